"""The Euro NCAP pedestrian AEB tests on a real junction, SV against V2I (docs/ncap.md).

protocol.toml/protocol.py: the grids and rules with their sources; scoring.py: colours, cell scores,
points as the official calculator computes them; staging.py: a cell as the engine's EpisodeSetup on the
site's geometry; suite.py: running and scoring cells; figure.py: the result-sheet figure; __main__.py:
the command line.
"""
