"""Leave no TraCI move pending when an episode ends before SUMO stepped.

`person.moveToXY` (and `vehicle.moveToXY`) do not move anything at once: libsumo records the road user
in a table of remote-controlled ones, by id and by a raw pointer, and SUMO's next step carries the move
out and empties the table. Neither `simulation.load` nor `close` empties it. An episode that ends
between a move and SUMO's step leaves the entry behind; the next episode's road user has the same id,
so SUMO's first step of that episode follows the stale pointer into freed memory and the process dies
(a segmentation fault in `simulation.step`, in the same worker, even after a close and a new start).
The loop moves the pedestrian to its start and then asks the AD stack: a stack that fails, times out
or returns an invalid command at its first step ended its episode so.

The cure is the step the episode skipped: one `simulation.step()` when SUMO's clock has not moved since
the pedestrian's first move, or when the episode is failing (an exception between the step's moves and
SUMO's step). It changes nothing the episode recorded (its log is complete).
"""

from __future__ import annotations

import sys
from typing import Any


def step_if_moved_since(api: Any, moved_at_s: float) -> None:
    """Step SUMO once if its clock still reads `moved_at_s` (the time of the first moveToXY) or an
    exception is propagating (call it in a `finally`), so that a pending move is carried out now. A
    SUMO that refuses the step, or a sumo-gui that has gone, is left to the caller's cleanup: the
    episode's own exception, if any, is the one that propagates."""
    failing = sys.exc_info()[1] is not None
    try:
        if failing or api.simulation.getTime() == moved_at_s:
            api.simulation.step()
    except Exception:  # noqa: BLE001, S110 - best effort on the way out (docstring)
        pass
