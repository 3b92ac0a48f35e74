"""Is restoring a saved SUMO state cheaper than `load`, and does it give the same episodes?

    nice -n 10 .venv/bin/python benchmarks/bench_load_state.py --pairs 5
    nice -n 10 .venv/bin/python benchmarks/bench_load_state.py --pairs 5 --site PATH/zhixin

Every episode starts SUMO afresh with `load` (sim/connection.py) and its own `--seed`. The alternative
measured here: after the first `load`, save the freshly loaded simulation (`simulation.saveState`, with
`--save-state.rng` so the random number generators are in it), and start every later episode with
`simulation.loadState` of that file, its generators set to what the episode's `--seed` would give them.

Part 1 (timing, SUMO only, the real episode arguments captured from one pair per scenario): the cost of
one reset each way, alternating, per call:
- `load`: the engine's way;
- `restore`: `loadState` of the state saved right after the first load, unchanged (its generators in
  SUMO's count form: "0 draws", which SUMO applies as `discard(0)` on the generator as it is, so the
  previous episode's stream would go on);
- `restore reseeded`: the same file with every generator written in SUMO's full text form for the
  episode's seed ("count key[624] pos"; the global generators seeded with the seed, lane generator i
  with seed + i, as `--seed` does: checked below against SUMO's own saveState).
Part 2 (identity): the worker side of a batch (`batch.runner.run_chunk`, the scenarios' pairs) twice in
this process, once with `load`, once with `restore reseeded` wherever the arguments differ from the
first episode's only in `--seed` and name no additional file (`load` otherwise); counts the rows and
columns that differ.
Part 3 (the mechanism): the speed factors SUMO draws for vehicles added by TraCI (DEFAULT_VEHTYPE's
speedDev), after a `load` with seed 9 and a restore reseeded for seed 5, against a fresh seed 5 and 9.
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pedsafe_sumo.batch import runner as batch_runner  # noqa: E402
from pedsafe_sumo.batch.__main__ import parse_args  # noqa: E402
from pedsafe_sumo.batch.chunks import plan_chunks  # noqa: E402
from pedsafe_sumo.batch.plan import prepare  # noqa: E402
from pedsafe_sumo.io.episodes import EPISODE_COLUMNS  # noqa: E402
from pedsafe_sumo.sim import connection  # noqa: E402

SCENARIOS = "crossing,jaywalking,background_blending,right_turn"
GLOBAL_RNGS = ("default", "routeHandler", "insertionControl", "device", "device.btreceiver", "driverState",
               "device.toc")  # fmt: skip
STATE_DIR = Path(tempfile.mkdtemp(prefix="bench_load_state_"))


def mt_text(seed: int) -> str:
    """SUMO's full text form of a std::mt19937 seeded with `seed`: draw count, the 624 words, position.
    numpy's legacy seeding of an integer is the same init_genrand as std::mt19937::seed."""
    _, key, pos, *_ = np.random.RandomState(seed % 2**32).get_state()
    return "0 " + " ".join(map(str, key.tolist())) + f" {pos}"


def rng_element(seed: int, lanes: int) -> str:
    everyone = mt_text(seed)
    attrs = " ".join(f'{name}="{everyone}"' for name in GLOBAL_RNGS)
    rows = "".join(f'        <rngLane index="{i}" state="{mt_text(seed + i)}"/>\n' for i in range(lanes))
    return f"<rngState {attrs}>\n{rows}    </rngState>"


def seed_of(args: list[str]) -> int:
    return int(args[args.index("--seed") + 1])


def without_seed(args: list[str]) -> list[str]:
    at = args.index("--seed")
    return [*args[:at], *args[at + 2 :]]


class Restorer:
    """Stands in for SumoSession.run: the first call starts/loads and saves the state; later calls whose
    arguments differ only in --seed (and name no additional file) restore it, reseeded."""

    def __init__(self, mode: str = "reseed") -> None:
        #: "reseed": the generators written for the episode's seed; "plain": as saved; "load_first":
        #: a `load` with the episode's arguments, then the plain restore (a diagnosis, not a saving: the
        #: generators are the load's, everything else the restored state's); "load_first_other_seed":
        #: the same with the load's --seed one higher (generators of another seed, nothing else changed).
        #: "+clear": remove every vehicle and person and step once before the restore.
        self.clear = "+clear" in mode
        #: "+unsubscribe": drop every vehicle subscription before the restore (a load drops them all).
        self.unsubscribe = "+unsubscribe" in mode
        #: "+norng": no --save-state.rng (the state file without generators, as sim/connection.py saves it).
        self.norng = "+norng" in mode
        self.mode = mode.split("+")[0]
        self.report_stale = not self.unsubscribe
        self.stale: list[int] = []
        self.reset_s = 0.0
        self.base: list[str] | None = None
        self.template = ""
        self.lanes = 0
        self.restored = self.loaded = 0

    def run(self, session, args) -> None:
        started = time.perf_counter()
        try:
            self._run(session, args)
        finally:
            self.reset_s += time.perf_counter() - started

    def _run(self, session, args) -> None:
        if not self.norng:
            args = [*args, "--save-state.rng", "true"]
        if (
            self.base is not None
            and session._started
            and without_seed(args) == self.base
            and "-a" not in args
            and "--additional-files" not in args
        ):
            path = STATE_DIR / "episode.xml"
            if self.mode == "load_first":
                REAL_RUN(session, args)
            elif self.mode == "load_first_other_seed":
                other = list(args)
                other[other.index("--seed") + 1] = str((seed_of(args) + 1) % 2_147_483_647)
                REAL_RUN(session, other)
            element = rng_element(seed_of(args), self.lanes) if self.mode == "reseed" else self.plain
            path.write_text(self.template.replace("@RNG@", element), encoding="utf-8")
            if self.unsubscribe:
                stale = list(session.api.vehicle.getAllSubscriptionResults())
                self.stale.append(len(stale))
                for vehicle_id in stale:
                    session.api.vehicle.unsubscribe(vehicle_id)
            if self.clear:
                api = session.api
                for vehicle_id in api.vehicle.getIDList():
                    api.vehicle.remove(vehicle_id)
                for person_id in api.person.getIDList():
                    api.person.remove(person_id)
                api.simulation.step()
            session.api.simulation.loadState(str(path))
            if self.report_stale:
                self.stale.append(len(session.api.vehicle.getAllSubscriptionResults()))
            self.restored += 1
            return
        REAL_RUN(session, args)
        self.loaded += 1
        if "-a" in args or "--additional-files" in args:
            # loadState resets no infrastructure: this load's parking areas would stay in every later
            # restore (see parking_areas()), so the next episode loads afresh.
            self.base = None
            return
        base_file = STATE_DIR / "base.xml"
        session.api.simulation.saveState(str(base_file))
        text = base_file.read_text(encoding="utf-8")
        found = re.search(r"<rngState.*?</rngState>", text, flags=re.S)
        self.plain = found.group(0) if found else "<!-- no generators -->"
        if not found:
            text = text.replace("<snapshot ", self.plain + "\n<snapshot ", 1)
        self.lanes = len(re.findall(r"<rngLane ", text))
        self.template = text.replace(self.plain, "@RNG@")
        self.base = without_seed(args)


REAL_RUN = connection.SumoSession.run
MODES = ("plain", "reseed", "load_first", "load_first_other_seed")


def chunks_for(site: str | None, pairs: int, approach: str | None = None):
    # prepare() writes nothing: --out is only a name the parser requires.
    argv = ["--scenario", SCENARIOS, "--episodes", str(pairs), "--out", "never-written"]
    if site:
        argv += ["--site", site]
    if approach:
        argv += ["--approach", approach]
    plan = prepare(parse_args(argv))
    return plan, plan_chunks(plan.scenarios, plan.conditions, pairs, plan.arguments["seed"], 1)


def run_all(plan, chunks) -> pd.DataFrame:
    rows = []
    for chunk in chunks:
        rows += batch_runner.run_chunk(plan.config, chunk.key, chunk.tasks).rows
    batch_runner._close_runner()
    frame = pd.DataFrame(rows)
    return frame[[c for c in EPISODE_COLUMNS if c in frame.columns]]


def compare(reference: pd.DataFrame, restored: pd.DataFrame) -> None:
    if restored.shape != reference.shape:
        print(f"  shapes differ: {reference.shape} against {restored.shape}")
        return
    differ = ~((reference == restored) | (reference.isna() & restored.isna()))
    rows = differ.any(axis=1)
    print(f"  rows that differ: {int(rows.sum())} of {len(rows)}")
    counts = differ.sum()
    print("  columns that differ (rows): " + ", ".join(f"{c} {n}" for c, n in counts[counts > 0].items()))
    if rows.any():
        by = reference.loc[rows, ["scenario", "condition"]].value_counts()
        print("  by scenario and condition: " + ", ".join(f"{k} {v}" for k, v in by.items()))


def timing(captured: list[list[str]], calls: int) -> None:
    import libsumo

    restorer = Restorer()
    session = connection.SumoSession()
    restorer.run(session, captured[0])
    plain = restorer.template.replace("@RNG@", restorer.plain)
    plain_file = STATE_DIR / "plain.xml"
    plain_file.write_text(plain, encoding="utf-8")
    times: dict[str, list[float]] = {"load": [], "restore": [], "restore reseeded": []}
    clock = time.perf_counter
    for i in range(calls):
        args = [*captured[i % len(captured)], "--save-state.rng", "true"]
        seed = (seed_of(args) + i) % 2_147_483_647
        at = args.index("--seed") + 1
        args[at] = str(seed)
        started = clock()
        libsumo.load(args)
        times["load"].append(clock() - started)
        started = clock()
        libsumo.simulation.loadState(str(plain_file))
        times["restore"].append(clock() - started)
        started = clock()
        path = STATE_DIR / "episode.xml"
        path.write_text(restorer.template.replace("@RNG@", rng_element(seed, restorer.lanes)), "utf-8")
        libsumo.simulation.loadState(str(path))
        times["restore reseeded"].append(clock() - started)
    session.close()
    for name, values in times.items():
        print(f"  {name:17s} median {1e6 * statistics.median(values):9.0f} us per episode "
              f"(min {1e6 * min(values):.0f}, {len(values)} calls)")  # fmt: skip
    reseeded = len(restorer.template) + len(rng_element(1, restorer.lanes))
    print(f"  state file: {len(plain)} characters as saved, {reseeded} reseeded")


def mechanism(net: str) -> None:
    import libsumo

    base = ["-n", net, "--no-step-log", "true", "--no-warnings", "true", "--save-state.rng", "true"]

    def speed_factors() -> list[float]:
        edges = [e for e in libsumo.edge.getIDList() if not e.startswith(":")][:20]
        for i, edge in enumerate(edges):
            try:
                libsumo.route.add(f"r{i}", [edge])
                libsumo.vehicle.add(f"v{i}", f"r{i}")
            except libsumo.TraCIException:
                pass
        libsumo.simulation.step()
        return [libsumo.vehicle.getSpeedFactor(v) for v in sorted(libsumo.vehicle.getIDList())][:4]

    libsumo.start(["sumo", *base, "--seed", "5"])
    fresh5 = speed_factors()
    libsumo.load([*base, "--seed", "9"])
    fresh9 = speed_factors()
    libsumo.load([*base, "--seed", "9"])
    libsumo.simulation.saveState(str(STATE_DIR / "m.xml"))
    text = (STATE_DIR / "m.xml").read_text(encoding="utf-8")
    lanes = len(re.findall(r"<rngLane ", text))
    text = re.sub(r"<rngState.*?</rngState>", lambda _: rng_element(5, lanes), text, flags=re.S)
    (STATE_DIR / "m5.xml").write_text(text, encoding="utf-8")
    libsumo.simulation.loadState(str(STATE_DIR / "m5.xml"))
    restored = speed_factors()
    # What SUMO holds after the restore: its own saveState, generators forced into the full form.
    saved = STATE_DIR / "after.xml"
    (STATE_DIR / "c.xml").write_text(text.replace('default="0 ', 'default="1000000 '), encoding="utf-8")
    libsumo.simulation.loadState(str(STATE_DIR / "c.xml"))
    libsumo.simulation.saveState(str(saved))
    echoed = re.search(r'default="([^"]*)"', saved.read_text(encoding="utf-8")).group(1).split()
    libsumo.close()
    print(f"  speed factors, fresh --seed 5: {fresh5}")
    print(f"  speed factors, fresh --seed 9: {fresh9}")
    print(f"  load --seed 9, then loadState reseeded for 5: {restored}")
    print(f"  SUMO's saveState after that restore: default generator's first word {echoed[1]} "
          f"(init_genrand(5) gives 5), position {echoed[-1]}")  # fmt: skip


def parking_areas(site: str, pairs: int, approach: str | None) -> None:
    """What a restore keeps of a one-lane episode's additional file (its kerb parking areas)."""
    import libsumo

    plan, chunks = chunks_for(site, pairs, approach)
    seen: list[tuple[str, int, int]] = []

    def watch(self, sumo_args):
        REAL_RUN(self, sumo_args)
        if "-a" in sumo_args and not seen:
            loaded = len(libsumo.parkingarea.getIDList())
            self.api.simulation.saveState(str(STATE_DIR / "kerb.xml"))
            self.api.simulation.loadState(str(STATE_DIR / "kerb.xml"))
            seen.append((sumo_args[sumo_args.index("-a") + 1], loaded, len(libsumo.parkingarea.getIDList())))

    connection.SumoSession.run = watch
    try:
        for chunk in chunks:
            batch_runner.run_chunk(plan.config, chunk.key, chunk.tasks)
            if seen:
                break
        batch_runner._close_runner()
    finally:
        connection.SumoSession.run = REAL_RUN
    for path, loaded, after in seen:
        print(f"  {Path(path).name}: {loaded} parking areas after its load, {after} after a loadState")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=5, help="pairs per scenario for the identity check")
    parser.add_argument("--calls", type=int, default=40, help="resets timed per way")
    parser.add_argument("--site", help="a site folder (default: the batch's default site)")
    parser.add_argument("--modes", default=",".join(MODES), help="restore modes to check (Restorer)")
    parser.add_argument("--approach", help="the batch's --approach (N, S: zhixin's one-lane arms)")
    args = parser.parse_args()
    plan, chunks = chunks_for(args.site, args.pairs, args.approach)

    captured: list[list[str]] = []

    load_s = [0.0]

    def capture(self, sumo_args):
        captured.append(list(sumo_args))
        started = time.perf_counter()
        try:
            return REAL_RUN(self, sumo_args)
        finally:
            load_s[0] += time.perf_counter() - started

    connection.SumoSession.run = capture
    try:
        reference = run_all(plan, chunks)
    finally:
        connection.SumoSession.run = REAL_RUN
    print(f"load: {1e6 * load_s[0] / len(captured):.0f} us per episode's reset")
    with_files = sum("-a" in a for a in captured)
    print(f"{len(reference)} rows with load; {with_files} of {len(captured)} name an additional file")

    for mode in args.modes.split(","):
        restorer = Restorer(mode)
        connection.SumoSession.run = lambda self, a, r=restorer: r.run(self, a)
        try:
            restored = run_all(plan, chunks)
        finally:
            connection.SumoSession.run = REAL_RUN
        print(
            f"restore ({mode}): {restorer.restored} episodes restored, {restorer.loaded} loaded, "
            f"{1e6 * restorer.reset_s / (restorer.restored + restorer.loaded):.0f} us per episode's reset"
        )
        if restorer.stale:
            what = "unsubscribed before" if restorer.unsubscribe else "still subscribed after"
            print(f"  vehicle subscriptions {what} each restore: max {max(restorer.stale)}, "
                  f"total {sum(restorer.stale)}")  # fmt: skip
        compare(reference, restored)

    if with_files:
        print("parking areas of the kerb (one-lane site):")
        parking_areas(args.site, args.pairs, args.approach)
    plain_args = [a for a in captured if "-a" not in a] or captured
    print("timing per reset (this machine, niced; see uptime):")
    timing(plain_args, args.calls)
    print("mechanism:")
    mechanism(plain_args[0][plain_args[0].index("-n") + 1])


if __name__ == "__main__":
    main()
