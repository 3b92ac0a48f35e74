"""Stopping a batch by a signal: Ctrl-C (SIGINT) or SIGTERM (a job scheduler, `kill PID`).

Either signal, delivered to the driver, is handed on to its local worker processes as SIGINT (they stop
their episode at once, instead of finishing their chunk) and raises KeyboardInterrupt in the driver,
whose handler keeps every chunk recorded so far and exits with code 130: `--resume` continues the run
(run.json stays "running", which is what --resume continues). Ctrl-C in a terminal reaches the workers
directly as well; the second SIGINT they get is harmless, they are stopping anyway. A second signal to
the driver while it stops ends it at once (the signal's default action): the run stays resumable, the
OS releases its lock.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
from collections.abc import Callable
from types import FrameType

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def stop_on_signals() -> Callable[[], None]:
    """Install the handler of STOP_SIGNALS in the driver; returns the function that puts the previous
    handlers back (the batch's main() may run inside another program, e.g. a test). Outside the main
    thread, where Python takes no signals, nothing is installed."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    previous = {signum: signal.signal(signum, _stop) for signum in STOP_SIGNALS}

    def restore() -> None:
        for signum, handler in previous.items():
            signal.signal(signum, handler)

    return restore


def _stop(signum: int, frame: FrameType | None) -> None:
    for signum_ in STOP_SIGNALS:  # a second signal ends the driver at once, should the stop hang
        signal.signal(signum_, signal.SIG_DFL)
    for child in multiprocessing.active_children():
        if child.pid is not None:
            try:
                os.kill(child.pid, signal.SIGINT)
            except OSError:  # ended meanwhile
                pass
    raise KeyboardInterrupt
