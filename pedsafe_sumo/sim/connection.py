"""The one place that talks to SUMO.

Headless runs use libsumo (SUMO inside this Python process: no socket, no second process); replay
uses traci with sumo-gui. Both expose the same TraCI API, so the episode loop calls
`session.api.vehicle.setSpeed(...)` and never knows which it has. Nothing else in the package
imports libsumo or traci: they receive the session (STYLE: "the connection is handed to every
component that needs it").

One SUMO instance serves a worker for all its episodes: the first episode starts it, later ones
reload it with `load` (about 7 ms on the Xueqing network, against about 10 ms for a start and much
more for a new sumo-gui process), which resets the simulation to time 0 with new options.

Every episode loads (`restore_state=False`, the default). A session made with
`restore_state=True` restores instead, headless, an episode whose options differ from the last load's
only in `--seed` and that loads no additional file, from the state saved right after that load
(`simulation.loadState`, about 1.5 ms against about 10 ms; docs/engine.md "Restoring a saved state
instead of load"). It is off because its rows can depend on the episodes run before it in the process:
SUMO's generators continue across a restore, and the staged vehicles (copies of DEFAULT_VEHTYPE, speedDev
0.1) get their speed factors from them. On the dual-ring site, right_turn on the W approach (seed
1641411168) ran after the same episode's SV run gave the leader a speed factor of 0.9932 instead of the
0.9602 that every load with that seed gives, and its V2I run failed ("SUMO did not insert vehicle
'leader_0'"), while it runs when loaded (tests/sim/test_episode_history.py). On Xueqing 80 of 80 rows
came out equal with and without the restore (benchmarks/bench_load_state.py, tools/compare_runs_exact.py):
the effect is rare, not absent (docs/decisions/2026-11-27-state-restore-off.md). What the restore does,
and its other limits:
- the state is saved without SUMO's random number generators (no --save-state.rng): with them in the
  file, restored episodes differ from loaded ones from the second on (measured, mechanism not found);
- a restore keeps SUMO's generators where the last episode left them (generator states written into a
  state file did not reach SUMO 1.28's draws, and TraCI has no call to reseed): the episode's `--seed`
  is not applied.
  The staging is built to draw nothing from SUMO that reaches a row (episodes loaded with another
  `--seed` gave the same 80 rows on Xueqing); the staged vehicles' speed factors do reach rows elsewhere
  (above), which is why the restore is off by default;
- a state holds no traffic light programs (only which one runs, and its phase): a program that TraCI
  replaced (setProgramLogic; the staging does not) would stay replaced, so the programs after a restore
  are checked against those read after the load, and the episode loads when they differ;
- libsumo is one simulation per process: a session restores only if no other session loaded since;
- vehicle subscriptions are dropped before `loadState` (their last results stay readable after it until
  the next step; no test saw them act on a later episode, but a load drops them too);
- a state holds no infrastructure: an episode with an additional file (the kerb parking areas of a
  one-lane site, sim/kerb.py) loads, and the next one loads too (a restore would keep those parking areas).
"""

from __future__ import annotations

import os
import tempfile
import weakref
from collections.abc import Sequence
from types import ModuleType

from pedsafe_sumo.sumo_binaries import sumo_binary

#: The session that last loaded, started or restored libsumo: libsumo is one simulation per process, so
#: two sessions in one process (two runners, as in tests) take turns in it, and a session may restore its
#: saved state only when nobody loaded anything since (another network, other options).
_libsumo_user: list[object | None] = [None]


class SimulatorError(RuntimeError):
    """SUMO refused the configuration or failed while running."""


class _NeverRaisedError(Exception):
    """Stands for an exception the API in use never raises."""


class SumoSession:
    """A SUMO instance for one worker: libsumo headless, or traci + sumo-gui when `gui` is set."""

    def __init__(self, gui: bool = False, label: str = "pedsafe", restore_state: bool = False) -> None:
        self.gui = gui
        self.label = label
        self._started = False
        #: Restore the state saved after the last load instead of loading again (module docstring: off by
        #: default, its rows can depend on the episodes before); libsumo only.
        self.restore_state = restore_state and not gui
        #: The last load's options without its --seed, when its state is saved in _state_file.
        self._base_args: list[str] | None = None
        self._state_file: str | None = None
        #: Every traffic light's programs right after that load (a restore must give them back).
        self._signal_programs: tuple = ()
        self._token = object()  # this session, in _libsumo_user (no reference to the session itself)
        self.api: ModuleType
        if gui:
            # Imported here: a session loads only the API it uses (traci ~0.3 s to import; libsumo ~0.6 s
            # and ~160 MiB of RSS, which a sumo-gui replay does not need).
            import traci

            self.api = traci
            self._exception = traci.TraCIException
            self._lost: type[Exception] = traci.FatalTraCIError
        else:
            import libsumo  # here, not at the top: see traci above

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
        """Start SUMO with `args` (options only, no binary) or reload the running instance with them (or
        restore the state saved after the last load, where that is the same: module docstring)."""
        args = list(args)
        if (
            self._started
            and self._base_args is not None
            and _without_seed(args) == self._base_args
            and _libsumo_user[0] is self._token
        ):
            try:
                if self._restore():
                    return
            except self._exception:
                pass  # load instead, below
        self._base_args = None
        self._load(args)
        if not self.gui:
            _libsumo_user[0] = self._token
        if self.restore_state and "--seed" in args and not _loads_additional_files(args):
            if self._state_file is None:
                handle, self._state_file = tempfile.mkstemp(prefix="pedsafe_state_", suffix=".xml")
                os.close(handle)
                weakref.finalize(self, _remove, self._state_file)
            self.api.simulation.saveState(self._state_file)
            self._signal_programs = self._programs()
            self._base_args = _without_seed(args)

    def _restore(self) -> bool:
        """Restore the saved state; False when it does not give the loaded simulation back (a load is due)."""
        api = self.api
        for vehicle_id in list(api.vehicle.getAllSubscriptionResults()):
            api.vehicle.unsubscribe(vehicle_id)
        api.simulation.loadState(self._state_file)
        # A state holds which program each traffic light runs and where in it, not the programs: one that
        # TraCI replaced stays replaced.
        return self._programs() == self._signal_programs

    def _programs(self) -> tuple:
        tl = self.api.trafficlight

        def phases(logic) -> tuple:
            return tuple((p.duration, p.state, p.minDur, p.maxDur, p.next, p.name) for p in logic.phases)

        return tuple(
            (
                tls,
                tl.getProgram(tls),
                tuple(
                    (
                        logic.programID,
                        logic.type,
                        logic.currentPhaseIndex,
                        phases(logic),
                        tuple(sorted(logic.subParameter.items())),
                    )
                    for logic in tl.getAllProgramLogics(tls)
                ),
            )
            for tls in tl.getIDList()
        )

    def _load(self, args: list[str]) -> None:
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
        self._base_args = None
        if _libsumo_user[0] is self._token:
            _libsumo_user[0] = None
        if self._started:
            try:
                self.api.close()
            finally:
                self._started = False

    def __enter__(self) -> SumoSession:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def _without_seed(args: list[str]) -> list[str]:
    if "--seed" not in args:
        return args
    at = args.index("--seed")
    return [*args[:at], *args[at + 2 :]]


def _loads_additional_files(args: list[str]) -> bool:
    return any(a in ("-a", "--additional-files") or a.startswith("--additional-files=") for a in args)


def _remove(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass
