"""Replay of logged episodes: in sumo-gui with the run's own settings, checked step by step against the
case log, rendered to PNG, or exported as SUMO FCD. The command line is `python -m pedsafe_sumo.replay`;
docs/replay.md explains it."""
