"""Pieces of the replay command line with known answers: which step --at names, sumo-gui's delay."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import pandas as pd
import pytest

from pedsafe_sumo.replay.__main__ import gui_settings, moment_step
from pedsafe_sumo.replay.rundir import ReplayError

LOGGED = SimpleNamespace(describe=lambda: "jaywalking episode 0, condition sv, seed 1")


def _log() -> pd.DataFrame:
    # Steps at 0.05 .. 0.40 s; perceived from the 4th step; touching (clearance <= 0) at the last.
    return pd.DataFrame(
        {
            "time_s": [0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.35, 0.40],
            "perceived": [False, False, False, True, True, False, True, True],
            "clearance_m": [9.0, 8.0, 6.5, 5.0, 3.0, 1.5, 0.2, -0.1],
        }
    )


def test_collision_is_the_first_touching_step():
    assert moment_step(_log(), "collision", LOGGED) == (7, "the collision")


def test_first_detection_is_the_first_perceived_step():
    assert moment_step(_log(), "first-detection", LOGGED) == (3, "the first detection")


@pytest.mark.parametrize(("moment", "index"), [("0", 0), ("0.05", 0), ("0.12", 2), ("0.3", 5), ("0.4", 7)])
def test_a_time_names_the_first_step_at_or_after_it(moment, index):
    assert moment_step(_log(), moment, LOGGED)[0] == index


@pytest.mark.parametrize("moment", ["0.41", "-0.1", "nan", "later"])
def test_a_time_outside_the_episode_is_refused(moment):
    with pytest.raises(ReplayError):
        moment_step(_log(), moment, LOGGED)


def test_moments_that_never_happened_are_refused():
    quiet = _log().assign(perceived=False, clearance_m=1.0)
    with pytest.raises(ReplayError, match="no collision"):
        moment_step(quiet, "collision", LOGGED)
    with pytest.raises(ReplayError, match="never perceived"):
        moment_step(quiet, "first-detection", LOGGED)


@pytest.mark.parametrize(
    ("per_step_ms", "step_s", "gui_delay"), [(50, 0.05, 1000), (200, 0.05, 4000), (0, 0.05, 0)]
)
def test_delay_per_step_becomes_sumo_gui_delay_per_simulated_second(per_step_ms, step_s, gui_delay):
    settings = gui_settings(per_step_ms, step_s)
    assert re.search(r'<delay value="([0-9.]+)"/>', settings).group(1) == f"{gui_delay:g}"
    assert '<scheme name="real world">' in settings


def test_replay_view_draws_the_signal_heads_states():
    """sumo-gui draws each controlled link's state (red, yellow, green bar at the stop line and on the
    crosswalks) when the view's <edges showLinkRules> is on; the replay's view turns it on, inside the
    scheme it uses (SUMO's GUISettingsHandler reads <edges> there)."""
    root = ET.fromstring(gui_settings(50.0, 0.05))
    edges = root.find("scheme/edges")
    assert edges is not None and edges.get("showLinkRules") == "1"
