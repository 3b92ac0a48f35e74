"""Replay a logged episode of a batch run in sumo-gui, render one moment of it, or export it as FCD.

    python -m pedsafe_sumo.replay DIR --episode N --condition sv
    python -m pedsafe_sumo.replay DIR --episode N --condition sv --screenshot case.png --at collision
    python -m pedsafe_sumo.replay DIR --episode N --condition v2i --export-fcd case.fcd.xml
    python -m pedsafe_sumo.replay DIR --episode N --condition sv --export-xosc case.xosc
    python -m pedsafe_sumo.replay DIR --episode N --condition sv --scenario crossing --approach E

The episode runs again with the seed, scenario, parameters and AD stack the run recorded in run.json
(never today's defaults), and every step is checked against the case log: a difference is reported
at the first step it shows and makes the exit status 1. Bad input ends in one line on stderr and exit
status 2.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

from pedsafe_sumo.cli import OneLineParser, check_range
from pedsafe_sumo.compiled_kernels import prepare_compiled_kernels
from pedsafe_sumo.io.outputs import check_output_file
from pedsafe_sumo.ncap.suite import NcapRunner
from pedsafe_sumo.network.sumo_inputs import SumoInputError, check_gui_site
from pedsafe_sumo.replay.check import CHECKED_OUTCOME, TrajectoryCheck, outcome_mismatches
from pedsafe_sumo.replay.fcd import FcdRecorder, write_fcd
from pedsafe_sumo.replay.moments import find_moment, moment_step  # noqa: F401 - moment_step: the CLI's API
from pedsafe_sumo.replay.rundir import LoggedEpisode, ReplayError, load_logged_episode
from pedsafe_sumo.replay.scene import (
    EGO_RGBA,
    KERB_LANE_VEHICLE_RGBA,
    PEDESTRIAN_RGBA,
    ReplayScene,
    ScreenshotRequest,
    ScreenshotTaken,
)
from pedsafe_sumo.replay.xosc import TrackRecorder, write_xosc
from pedsafe_sumo.scenarios.episode_setup import EpisodeSetup
from pedsafe_sumo.settings import UsageError
from pedsafe_sumo.sim.connection import SimulatorError
from pedsafe_sumo.sim.episode import EpisodeRunner

#: Playback: wall-clock milliseconds per simulation step; 50 plays the 0.05 s steps in real time.
DEFAULT_DELAY_MS = 50.0
DEFAULT_SCREENSHOT_SIZE = (1000, 800)
#: Playback slower than 10 s per step shows nothing a screenshot (--at) does not.
MAX_DELAY_MS = 10_000.0
#: Road shown across the view [m]; a screenshot widens it to keep the pedestrian in the picture.
DEFAULT_VIEW_WIDTH_M = 60.0
#: Wider than any study site (build_network clips at most 2 km around its centre).
MAX_VIEW_WIDTH_M = 4000.0
#: Space sumo-gui's menus, toolbars and status bar take around its canvas [px]: the window is made this
#: much larger than the requested picture so that the canvas holds it.
WINDOW_CHROME_PX = (60, 320)
#: Set when the replay restarted itself under xvfb-run, so that it does not try again.
UNDER_XVFB_ENV = "PEDSAFE_REPLAY_UNDER_XVFB"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = OneLineParser(prog="python -m pedsafe_sumo.replay", description=__doc__.splitlines()[0])
    parser.add_argument(
        "run_dir", type=Path, metavar="DIR", help="run directory written by pedsafe_sumo.batch"
    )
    parser.add_argument(
        "--episode",
        type=int,
        required=True,
        help="episode number (episodes.parquet 'episode'), one the run holds",
    )
    parser.add_argument("--condition", required=True, help="sv or v2i")
    parser.add_argument("--scenario", help="scenario of the episode (needed when the run has several)")
    parser.add_argument(
        "--approach",
        metavar="ARM",
        help="approach of the episode, N, E, S or W (needed when the run, made with batch --approach, has "
        "several)",
    )
    parser.add_argument(
        "--site", help="the run's site (name or folder) when it is not where run.json says [its site_path]"
    )
    parser.add_argument(
        "--algorithm",
        metavar="MODULE:CLASS",
        help="the AD stack to import (replaces the run's); needed for a stack run.json names that is not "
        "installed (docs/trust.md)",
    )
    parser.add_argument(
        "--delay",
        type=float,
        help=f"playback speed: milliseconds per simulation step, 0 to {MAX_DELAY_MS:g} "
        f"[{DEFAULT_DELAY_MS:g}: real time with 0.05 s steps; 0 with --screenshot]",
    )
    parser.add_argument("--screenshot", type=Path, metavar="FILE", help="render one moment to a PNG and exit")
    parser.add_argument(
        "--at",
        metavar="MOMENT",
        help="moment of --screenshot: collision, least-ttc, closest-approach, first-detection or a time in "
        "seconds [the collision, else the least TTC, else the closest approach]",
    )
    parser.add_argument(
        "--size",
        default=f"{DEFAULT_SCREENSHOT_SIZE[0]},{DEFAULT_SCREENSHOT_SIZE[1]}",
        metavar="W,H",
        help="screenshot size in pixels, 16 to 8000 each way [%(default)s]",
    )
    parser.add_argument(
        "--view-width",
        type=float,
        default=DEFAULT_VIEW_WIDTH_M,
        metavar="M",
        help=f"road shown across the view, metres, above 0 and at most {MAX_VIEW_WIDTH_M:g} "
        f"[{DEFAULT_VIEW_WIDTH_M:g}]",
    )
    parser.add_argument(
        "--scene-colours",
        action="store_true",
        help="keep the colours the sensors saw (car bodies, clothing) instead of role colours",
    )
    parser.add_argument(
        "--export-fcd",
        type=Path,
        metavar="FILE",
        help="write the episode as SUMO FCD XML (headless, no window)",
    )
    parser.add_argument(
        "--export-xosc",
        type=Path,
        metavar="FILE",
        help="write the episode as ASAM OpenSCENARIO XML, its road as OpenDRIVE beside it (headless)",
    )
    return parser.parse_args(argv)


def check_args(args: argparse.Namespace) -> tuple[int, int]:
    if args.at is not None and args.screenshot is None:
        raise UsageError("--at chooses the moment of --screenshot: give --screenshot FILE too")
    if args.screenshot is not None and args.export_fcd is not None:
        raise UsageError("--screenshot and --export-fcd are separate runs: give one of them")
    if args.export_xosc is not None and (args.screenshot is not None or args.export_fcd is not None):
        raise UsageError("--export-xosc is a run of its own: give it without --screenshot and --export-fcd")
    if args.export_xosc is not None and args.export_xosc.suffix.lower() != ".xosc":
        raise UsageError(
            f"--export-xosc writes OpenSCENARIO: give a file name ending in .xosc, got {args.export_xosc}"
        )
    if args.delay is not None:
        check_range(args.delay, "--delay", 0, MAX_DELAY_MS, unit=" ms per step")
    check_range(args.view_width, "--view-width", 0, MAX_VIEW_WIDTH_M, unit=" m", low_open=True)
    try:
        width_px, height_px = (int(v) for v in args.size.split(","))
    except ValueError:
        raise UsageError(f"--size must be WIDTH,HEIGHT in pixels, got '{args.size}'") from None
    if not (16 <= width_px <= 8000 and 16 <= height_px <= 8000):
        raise UsageError(f"--size must be between 16 and 8000 pixels each way, got {args.size}")
    if args.screenshot is not None and args.screenshot.suffix.lower() != ".png":
        raise UsageError(f"--screenshot writes a PNG: give a file name ending in .png, got {args.screenshot}")
    for option, path in (
        ("--export-fcd", args.export_fcd),
        ("--export-xosc", args.export_xosc),
        ("--screenshot", args.screenshot),
    ):
        if path is not None:
            check_output_file(path, option, UsageError, make_parents=True)
    return width_px, height_px


def runner_class(logged: LoggedEpisode) -> type[EpisodeRunner]:
    """The engine the run used: a Euro NCAP run (pedsafe_sumo.ncap) holds the ego's movement green."""
    if logged.run_info.get("kind") == "ncap":
        return NcapRunner
    return EpisodeRunner


def episode_setup(runner: EpisodeRunner, logged: LoggedEpisode, say) -> EpisodeSetup:
    """The episode's initial world drawn from its seed as the batch did; the recorded one when the case
    recorded a different one (then the drawing code changed since the run). A Euro NCAP cell
    (pedsafe_sumo.ncap) is staged, not drawn: its recorded world is the world."""
    if logged.run_info.get("kind") == "ncap" and logged.case_meta is not None:
        return logged.case_meta["setup"]
    drawn = runner.draw_setup(logged.spec, logged.seed)
    if logged.case_meta is None:
        return drawn
    recorded = logged.case_meta["setup"]
    if drawn != recorded:
        differing = [
            f.name
            for f in dataclasses.fields(recorded)
            if getattr(recorded, f.name) != getattr(drawn, f.name)
        ]
        say(
            f"  note: the world drawn from seed {logged.seed} today differs from the recorded one "
            f"({', '.join(differing)}): replaying the recorded world"
        )
        return recorded
    return drawn


def chain(*hooks):
    hooks = [h for h in hooks if h is not None]

    def on_step(api, row):
        for hook in hooks:
            hook(api, row)

    return on_step


def error(message: str, status: int = 2) -> int:
    print(f"error: {message}", file=sys.stderr)
    return status


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        size_px = check_args(args)
        logged = load_logged_episode(
            args.run_dir,
            args.episode,
            args.condition,
            args.scenario,
            args.site,
            args.approach,
            args.algorithm,
        )
        if args.export_fcd is None and args.export_xosc is None:  # sumo-gui loads the site's additionals
            check_gui_site(logged.site, view=None)
    except (UsageError, ReplayError, SumoInputError) as exc:
        return error(str(exc))
    prepare_compiled_kernels()
    if args.export_fcd is not None:
        say_header(logged, print)
        return export_fcd(logged, args.export_fcd, print)
    if args.export_xosc is not None:
        say_header(logged, print)
        return export_xosc(logged, args.export_xosc, print)

    has_display = bool(os.environ.get("DISPLAY"))
    can_start_xvfb = (
        args.screenshot is not None and shutil.which("xvfb-run") and not os.environ.get(UNDER_XVFB_ENV)
    )
    if not has_display and not can_start_xvfb:
        hint = (
            "use --screenshot (it starts Xvfb itself when xvfb-run is installed)"
            if args.screenshot is None
            else "install xvfb (apt-get install xvfb)"
        )
        return error(f"sumo-gui needs a display and there is none: {hint}")
    # Without a display the checks below run silently and the run under Xvfb tells the story.
    say = print if has_display else _silent
    say_header(logged, say)
    try:
        plan = plan_replay(logged, args, size_px, say)
    except ReplayError as exc:
        return error(str(exc))
    except SimulatorError as exc:
        return error(str(exc), 1)
    if not has_display:
        return rerun_under_xvfb(argv, size_px)
    return replay_in_gui(logged, args, plan, say)


def say_header(logged: LoggedEpisode, say) -> None:
    say(f"replaying {logged.describe()} of run {logged.run_dir}")
    say(
        f"  settings from run.json: scenario '{logged.spec.name}', algorithm {logged.algorithm}, "
        f"site {logged.site.name}"
    )
    for note in logged.notes:
        say(f"  note: {note}")


def _silent(*_args, **_kwargs) -> None:
    pass


def export_fcd(logged: LoggedEpisode, path: Path, say) -> int:
    runner = runner_class(logged)(
        logged.site, logged.params, logged.agent_class, step_length_s=logged.step_length_s
    )
    try:
        setup = episode_setup(runner, logged, say)
        check = _trajectory_check(logged, say)
        angle_path = setup.pedestrian.path_xy
        heading_rad = math.atan2(angle_path[1][1] - angle_path[0][1], angle_path[1][0] - angle_path[0][0])
        recorder = FcdRecorder(heading_rad)
        result = runner.run(
            logged.spec, logged.condition, logged.seed, setup=setup, on_step=chain(check, recorder)
        )
    except SimulatorError as exc:
        return error(str(exc), 1)
    finally:
        runner.close()
    write_fcd(
        path,
        recorder.timesteps,
        comment=f"pedsafe_sumo replay of {logged.describe()}, run {logged.run_dir}",
    )
    say(f"wrote {path}: {len(recorder.timesteps)} timesteps, ended ({result.end_reason.replace('_', ' ')})")
    return _verdict(logged, check, result, say)


def export_xosc(logged: LoggedEpisode, path: Path, say) -> int:
    """The episode as OpenSCENARIO + OpenDRIVE (pedsafe_sumo/replay/xosc.py), checked like --export-fcd."""
    runner = runner_class(logged)(
        logged.site, logged.params, logged.agent_class, step_length_s=logged.step_length_s
    )
    try:
        setup = episode_setup(runner, logged, say)
        check = _trajectory_check(logged, say)
        ped = setup.pedestrian
        heading_rad = math.atan2(ped.path_xy[1][1] - ped.path_xy[0][1], ped.path_xy[1][0] - ped.path_xy[0][0])
        colours = {v.vehicle_id: v.colour_rgb for v in (setup.ego, *setup.parked)}
        colours.update({v.vehicle_id: v.colour_rgb for v in setup.background})
        recorder = TrackRecorder(ped.radius_m, ped.height_m, ped.clothing_rgb, heading_rad, colours)
        result = runner.run(
            logged.spec, logged.condition, logged.seed, setup=setup, on_step=chain(check, recorder)
        )
    except SimulatorError as exc:
        return error(str(exc), 1)
    finally:
        runner.close()
    try:
        xosc_path, xodr_path = write_xosc(
            recorder,
            logged.site.file("net.xml"),
            path,
            f"pedsafe_sumo replay of {logged.describe()}, run {logged.run_dir}",
            logged.step_length_s,
        )
    except (RuntimeError, OSError) as exc:
        return error(str(exc), 1)
    entered = recorder.entered_later()
    say(
        f"wrote {xosc_path} and {xodr_path}: {len(recorder.times_s)} steps, "
        f"{len(recorder.exported_vehicles())} vehicles, the pedestrian and "
        f"{len(recorder.persons)} background pedestrians ({len(entered)} road users added when they appear), "
        f"{len(recorder.signal_changes)} traffic light states"
    )
    return _verdict(logged, check, result, say)


@dataclasses.dataclass(frozen=True)
class ReplayPlan:
    setup: EpisodeSetup
    #: The episode's course known in advance (markers, framing): the case log, else a headless run.
    reference: pd.DataFrame
    screenshot: ScreenshotRequest | None


def plan_replay(logged: LoggedEpisode, args: argparse.Namespace, size_px: tuple[int, int], say) -> ReplayPlan:
    """The world to replay, the episode's course, and the screenshot's step (ReplayError when the
    requested moment never happened)."""
    headless = runner_class(logged)(
        logged.site, logged.params, logged.agent_class, step_length_s=logged.step_length_s
    )
    try:
        setup = episode_setup(headless, logged, say)
        reference = logged.case_log
        if reference is None:
            # Markers and framing need the episode's course in advance: a headless run gives it (~0.5 s).
            say(
                "  no case log for this episode (no collision or conflict in its pair): nothing recorded to "
                "check the trajectory against; the outcome is checked against episodes.parquet"
            )
            reference = headless.run(logged.spec, logged.condition, logged.seed, setup=setup).log
    finally:
        headless.close()
    screenshot = None
    if args.screenshot is not None:
        moment = find_moment(reference, args.at, logged.describe())
        step_index = moment.step_index
        if step_index == 0:
            step_index = 1
            say(
                f"  note: the first step (t={reference['time_s'].iloc[0]:.2f} s) is never drawn; "
                "rendering the next one"
            )
        time_s = float(reference["time_s"].iloc[step_index])
        stamp = (f"t = {time_s:.2f} s  {moment.phrase}", moment.detail, logged.describe())
        screenshot = ScreenshotRequest(args.screenshot.resolve(), step_index, *size_px, stamp_lines=stamp)
        say(moment.line())
    return ReplayPlan(setup, reference, screenshot)


def replay_in_gui(logged: LoggedEpisode, args: argparse.Namespace, plan: ReplayPlan, say) -> int:
    setup, reference, screenshot = plan.setup, plan.reference, plan.screenshot
    if screenshot is not None:
        screenshot.path.parent.mkdir(parents=True, exist_ok=True)
    delay_ms_per_step = args.delay if args.delay is not None else (0.0 if screenshot else DEFAULT_DELAY_MS)
    if screenshot is None:
        say("  colours: " + _legend(args.scene_colours))

    with tempfile.TemporaryDirectory(prefix="pedsafe-replay-") as tmp:
        settings = Path(tmp) / "replay.view.xml"
        settings.write_text(gui_settings(delay_ms_per_step, logged.step_length_s), encoding="utf-8")
        options = []
        if screenshot is not None:
            options = [
                "--window-size",
                f"{screenshot.width_px + WINDOW_CHROME_PX[0]},{screenshot.height_px + WINDOW_CHROME_PX[1]}",
            ]
        runner = runner_class(logged)(
            logged.site,
            logged.params,
            logged.agent_class,
            gui=True,
            step_length_s=logged.step_length_s,
            gui_settings_file=settings,
            gui_options=options,
        )
        check = _trajectory_check(logged, say, reference)
        scene = ReplayScene(
            setup,
            runner.sensors_for(logged.spec),
            reference,
            logged.condition,
            view_width_m=args.view_width,
            scene_colours=args.scene_colours,
            screenshot=screenshot,
            say=say,
        )
        result = None
        try:
            result = runner.run(
                logged.spec, logged.condition, logged.seed, setup=setup, on_step=chain(check, scene)
            )
        except ScreenshotTaken as taken:
            say(f"wrote {taken}")
        except SimulatorError as exc:
            _close_quietly(runner)
            return error(str(exc), 1)
        except runner.session.connection_lost:
            # No check (no case log, no reference run): nothing counted the steps, nothing can fail.
            steps = f" after {check.steps_checked} steps" if check is not None else ""
            say(f"sumo-gui was closed{steps}, before the episode ended")
            return 0 if check is None or check.ok else 1
        except TimeoutError as exc:
            _close_quietly(runner)
            return error(str(exc), 1)
        if screenshot is not None and result is not None:
            _close_quietly(runner)
            return error(
                f"the replay ended ({result.end_reason.replace('_', ' ')}) "
                f"at t={result.log['time_s'].iloc[-1]:.2f} s, "
                "before the requested moment: it differs from the log",
                1,
            )
        if result is not None and screenshot is None and sys.stdin.isatty():
            try:
                input("episode over: press Enter to close sumo-gui ")
            except EOFError:
                pass
        _close_quietly(runner)
    return _verdict(logged, check, result, say)


def _trajectory_check(
    logged: LoggedEpisode, say, reference: pd.DataFrame | None = None
) -> TrajectoryCheck | None:
    def report(line: str) -> None:
        print(line, file=sys.stderr)

    if logged.case_log is not None:
        say(f"  checking every step against the case log {logged.case_path} ({len(logged.case_log)} steps)")
        return TrajectoryCheck(logged.case_log, report)
    if reference is not None:
        say("  checking every step against a headless run of the same episode")
        return TrajectoryCheck(reference, report, reference_name="the headless run")
    say(
        "  no case log for this episode (no collision or conflict in its pair): nothing recorded to check "
        "the trajectory against; the outcome is checked against episodes.parquet"
    )
    return None


def _verdict(logged: LoggedEpisode, check: TrajectoryCheck | None, result, say) -> int:
    """Summary lines; 1 when the replay differs from what the run recorded."""
    differs = False
    if check is not None:
        if result is not None:
            check.finish(len(result.log), result.end_reason, complete=True)
        say(check.summary())
        differs = not check.ok
    if result is not None:
        mismatches = outcome_mismatches(logged.outcome, result.outcome)
        for mismatch in mismatches:
            print(mismatch.line(), file=sys.stderr)
        if not mismatches:
            say("outcome matches episodes.parquet (" + ", ".join(CHECKED_OUTCOME) + ")")
        differs = differs or bool(mismatches)
    return 1 if differs else 0


def _legend(scene_colours: bool) -> str:
    if scene_colours:
        return "as the sensors saw them; the pedestrian ringed in white"

    def rgb(rgba):
        return ",".join(str(c) for c in rgba[:3])

    return (
        f"ego magenta ({rgb(EGO_RGBA)}), pedestrian orange ({rgb(PEDESTRIAN_RGBA)}) in a white ring, "
        f"kerb-lane vehicles (occluder, queue) cyan ({rgb(KERB_LANE_VEHICLE_RGBA)}), roadside camera pole "
        "blue square; fields of view: onboard camera magenta wedge, LiDAR range magenta circle, roadside "
        "camera blue wedge; first detections: yellow (onboard) and light-blue (roadside) dots with "
        "sight lines"
    )


def gui_settings(delay_ms_per_step: float, step_length_s: float) -> str:
    """sumo-gui view settings of the replay: the site's real-world colours, POI labels, the signal heads'
    states (link rules: a red, yellow or green bar at the end of each controlled lane and crosswalk,
    drawn from the traffic light's state at every step), the delay.

    sumo-gui 1.28 counts its delay in milliseconds per simulated second (it scales the value by the
    step length, whatever its help text says): 1000 plays in real time. --delay is per step.
    """
    gui_delay = delay_ms_per_step / step_length_s
    return (
        "<viewsettings>\n"
        '    <scheme name="real world">\n'
        '        <pois poiType_show="1" poiType_size="50" poiType_color="255,255,255"\n'
        '              poiType_constantSize="1"/>\n'
        '        <edges showLinkRules="1" showLinkDecals="1"/>\n'
        "    </scheme>\n"
        f'    <delay value="{gui_delay:g}"/>\n'
        "</viewsettings>\n"
    )


def _close_quietly(runner: EpisodeRunner) -> None:
    try:
        runner.close()
    except runner.session.connection_lost:
        pass  # the window was closed already


def rerun_under_xvfb(argv: list[str] | None, size_px: tuple[int, int]) -> int:
    """Run this same command again inside a virtual X server (no display here, xvfb-run installed)."""
    width, height = size_px[0] + WINDOW_CHROME_PX[0] + 200, size_px[1] + WINDOW_CHROME_PX[1] + 200
    command = [
        "xvfb-run",
        "-a",
        "-s",
        f"-screen 0 {width}x{height}x24",
        sys.executable,
        "-m",
        "pedsafe_sumo.replay",
        *(sys.argv[1:] if argv is None else argv),
    ]
    # The same pedsafe_sumo package for the child, whatever else is installed.
    package_root = str(Path(__file__).resolve().parents[2])
    python_path = os.pathsep.join(p for p in (package_root, os.environ.get("PYTHONPATH", "")) if p)
    env = {**os.environ, UNDER_XVFB_ENV: "1", "LIBGL_ALWAYS_SOFTWARE": "1", "PYTHONPATH": python_path}
    return subprocess.run(command, env=env, check=False).returncode


if __name__ == "__main__":
    sys.exit(main())
