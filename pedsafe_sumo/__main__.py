"""`python -m pedsafe_sumo`: the command `pedsafe-sumo` (pedsafe_sumo.command)."""

import sys

from pedsafe_sumo.command import main

if __name__ == "__main__":
    sys.exit(main())
