"""The site commands: build a study site (network/) and say what it hosts (scenarios/hosting.py).

`python -m pedsafe_sumo.site --site NAME_OR_PATH` rebuilds a site and summarises it;
`tools/build_network.py` (site.build_command) builds a new one. They sit above both `network` and
`scenarios`, so neither of those imports the other's command line.
"""
