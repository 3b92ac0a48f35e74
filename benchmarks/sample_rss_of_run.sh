#!/bin/bash
# Samples the RSS of a batch that is already running (bench_rss.py starts its own batch; this one
# attaches to a long run, e.g. a whole protocol): every 20 s, each worker of the batch whose command
# line contains PATTERN, with the episodes done read from the batch's progress bar in LOG.
#   benchmarks/sample_rss_of_run.sh PATTERN LOG OUT.csv     (e.g. paper-v5.toml run.log rss.csv)
set -euo pipefail
pattern=${1:?PATTERN (a string of the batch's command line)} log=${2:?LOG (the batch's stderr)} out=${3:?OUT.csv}
echo "utc,pid,rss_kib,episodes_done" > "$out"
while pgrep -f -- "$pattern" >/dev/null; do
  done_episodes=$(tail -c 200 "$log" | grep -ao '[0-9]*/[0-9]*' | tail -1 | cut -d/ -f1 || true)
  for pid in $(pgrep -f "multiprocessing.spawn" || true); do
    parent=$(ps -o ppid= -p "$pid" | tr -d ' ' || true)
    if [ -n "$parent" ] && ps -o args= -p "$parent" | grep -q -- "$pattern"; then
      echo "$(date -u +%H:%M:%S),$pid,$(ps -o rss= -p "$pid" | tr -d ' '),$done_episodes" >> "$out"
    fi
  done
  sleep 20
done
