"""Leave no TraCI move pending when an episode ends before SUMO stepped.

`person.moveToXY` (and `vehicle.moveToXY`) do not move anything at once: libsumo records the person in
a table of remote-controlled road users, by id and by a raw pointer, and SUMO's next step carries the
move out and empties the table. Neither `simulation.load` nor `close` empties it. An episode that ends
between the pedestrian's move and SUMO's step (the loop moves the pedestrian to its start, then asks
the AD stack: a stack that fails, times out or returns an invalid command on its first step) leaves
the entry behind; the next episode's person has the same id, so SUMO's first step of that episode
follows the stale pointer into freed memory and the process dies (a segmentation fault in
`simulation.step`, in the same worker, even after a close and a new start).

The cure is the step the episode skipped: one `simulation.step()` when SUMO's clock has not moved
since the pedestrian's move. It changes nothing the episode recorded (its log is complete).
"""

from __future__ import annotations

from typing import Any


def step_if_moved_since(api: Any, moved_at_s: float, sumo_error: type[Exception]) -> None:
    """Step SUMO once if its clock still reads `moved_at_s` (the time of the last moveToXY), so that
    the pending move is carried out now; a SUMO that refuses the step is left to the caller's cleanup."""
    try:
        if api.simulation.getTime() == moved_at_s:
            api.simulation.step()
    except sumo_error:
        pass
