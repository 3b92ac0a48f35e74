#!/bin/bash
# Samples the RSS of a batch that is already running (bench_rss.py starts its own batch; this one
# attaches to a long run, e.g. a whole protocol): every 20 s (SAMPLE_EVERY_S), each worker of the batch
# whose command line contains PATTERN, with the episodes done read from the batch's progress bar in LOG.
#   benchmarks/sample_rss_of_run.sh PATTERN LOG OUT.csv     (e.g. paper-v7.toml run.log rss.csv)
set -euo pipefail
pattern=${1:?PATTERN (a string of the batch command line)} log=${2:?LOG (the batch stderr)} out=${3:?OUT.csv}
echo "utc,pid,rss_kib,episodes_done" > "$out"
# The batch's driver: the first python process with the pattern in its command line (this script, a
# shell or `timeout` around it hold the pattern too, so they cannot be what the loop waits for).
driver=""
for pid in $(pgrep -f -- "$pattern" || true); do
  case "$(ps -o comm= -p "$pid" || true)" in python*) driver=$pid; break ;; esac
done
[ -n "$driver" ] || { echo "error: no python process has '$pattern' in its command line" >&2; exit 2; }
while kill -0 "$driver" 2>/dev/null; do
  # At least one digit each side: "episode/s" of the same bar would otherwise match as "/".
  done_episodes=$(tail -c 200 "$log" | grep -ao '[0-9]\+/[0-9]\+' | tail -1 | cut -d/ -f1 || true)
  for pid in $(pgrep -f "multiprocessing.spawn" || true); do
    parent=$(ps -o ppid= -p "$pid" | tr -d ' ' || true)
    if [ "$parent" = "$driver" ]; then
      echo "$(date -u +%H:%M:%S),$pid,$(ps -o rss= -p "$pid" | tr -d ' '),$done_episodes" >> "$out"
    fi
  done
  sleep "${SAMPLE_EVERY_S:-20}"
done
