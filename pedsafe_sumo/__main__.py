"""`python -m pedsafe_sumo`: the command `pedsafe-sumo` (pedsafe_sumo.cli)."""

import sys

from pedsafe_sumo.cli import main

if __name__ == "__main__":
    sys.exit(main())
