"""The one place that talks to SUMO.

Headless runs use libsumo (SUMO inside this Python process: no socket, no second process); replay
uses traci with sumo-gui. Both expose the same TraCI API, so the episode loop calls
`session.api.vehicle.setSpeed(...)` and never knows which it has. Nothing else in the package
imports libsumo or traci: they receive the session (STYLE: "the connection is handed to every
component that needs it").

One SUMO instance serves a worker for all its episodes: the first episode starts it, later ones
reload it with `load` (about 7 ms on the Xueqing network, against about 10 ms for a start and much
more for a new sumo-gui process), which resets the simulation to time 0 with new options.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import ModuleType

from pedsafe_sumo.sumo_binaries import sumo_binary


class SimulatorError(RuntimeError):
    """SUMO refused the configuration or failed while running."""


class _NeverRaisedError(Exception):
    """Stands for an exception the API in use never raises."""


class SumoSession:
    """A SUMO instance for one worker: libsumo headless, or traci + sumo-gui when `gui` is set."""

    def __init__(self, gui: bool = False, label: str = "pedsafe") -> None:
        self.gui = gui
        self.label = label
        self._started = False
        self.api: ModuleType
        if gui:
            import traci

            self.api = traci
            self._exception = traci.TraCIException
            self._lost: type[Exception] = traci.FatalTraCIError
        else:
            import libsumo

            self.api = libsumo
            self._exception = libsumo.TraCIException
            self._lost = _NeverRaisedError

    @property
    def exception(self) -> type[Exception]:
        """The exception class SUMO raises for a refused command (libsumo's or traci's)."""
        return self._exception

    @property
    def connection_lost(self) -> type[Exception]:
        """The exception traci raises when sumo-gui has gone away (its window closed); libsumo has none."""
        return self._lost

    def run(self, args: Sequence[str]) -> None:
        """Start SUMO with `args` (options only, no binary) or reload the running instance with them."""
        try:
            if not self._started:
                try:
                    binary = sumo_binary("sumo-gui" if self.gui else "sumo")
                except FileNotFoundError as exc:
                    raise SimulatorError(str(exc)) from None
                if self.gui:
                    self.api.start([binary, *args], label=self.label)
                else:
                    self.api.start([binary, *args])
                self._started = True
            else:
                self.api.load(list(args))
        except self._exception as exc:
            self._started = False
            raise SimulatorError(f"SUMO refused the episode configuration: {exc}") from None
        except Exception as exc:  # traci raises FatalTraCIError when sumo-gui exits on a bad option
            self._started = False
            raise SimulatorError(f"SUMO could not start: {exc}") from None

    def close(self) -> None:
        if self._started:
            try:
                self.api.close()
            finally:
                self._started = False

    def __enter__(self) -> SumoSession:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
