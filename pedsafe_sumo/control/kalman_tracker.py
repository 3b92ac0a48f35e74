"""The baseline stack's constant-velocity tracker: one Kalman filter per pedestrian, with memory.

The stack runs it under `[algorithm] tracker_motion_model = "cv"`; its motion model is also the walking
model of the IMM tracker (control/imm_tracker.py), the default.

State per track: world position and velocity (x, y, vx, vy) [m, m/s] and its 4 x 4 covariance. Motion
model: the continuous white-noise acceleration model (Bar-Shalom, Li and Kirubarajan, "Estimation with
Applications to Tracking and Navigation", Wiley 2001, section 6.2.2), per axis

    F = [[1, T], [0, 1]],   Q = q [[T^3/3, T^2/2], [T^2/2, T]],

q being the acceleration's power spectral density. Measurements: positions, one per pedestrian a step
(the observation reports each pedestrian once, by its first reporter: onboard camera, onboard LiDAR,
V2I), with the noise of the source that reported it. A V2I position is the roadside position sent
`latency_s` earlier; under the constant-velocity model it measures x - latency * v, and the filter uses
that measurement matrix rather than taking the stale position for the current one.

A track not measured this step is predicted on (its covariance grows) for `track_memory_s`, then
dropped. Docs: docs/baseline_stack.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Any

import numpy as np
from numpy.linalg import _umath_linalg  # the gufuncs np.linalg.solve, inv and slogdet call: see lapack_call

from pedsafe_sumo.control.agent import PerceivedPedestrian

#: Standard deviation of a V2I position per world axis [m]: the link's stated noise,
#: [perception.v2i] position_noise_sigma_m of the parameter file.
V2I_POSITION_SIGMA_M = 0.2
#: Age of a V2I position when it arrives [s]: [perception.v2i] latency_s (SPaT and detections alike).
V2I_LATENCY_S = 0.1
#: Standard deviation of an onboard camera or LiDAR position [m]. The simulator's onboard detectors
#: report the pedestrian's true centre (perception/pipeline.py: no position noise); 0.01 m is a floor
#: that keeps the filter's covariance well conditioned. With it two detections 0.05 s apart give the
#: velocity to 0.3 m/s, as the exact difference would: a new track is told moving from its second
#: detection.
ONBOARD_POSITION_SIGMA_M = 0.01
#: Acceleration power spectral density q of the motion model [m2/s3]. Bar-Shalom et al. (2001, section
#: 6.2.2): over an interval tau the velocity changes by about sqrt(q tau). Assumption: q = 0.01 lets a
#: steady walker's velocity wander by about 0.1 m/s over 1 s, a few per cent of 1.4 m/s, the order of
#: healthy adults' stride-to-stride variability (Hausdorff 2005, J. NeuroEng. Rehabil. 2:19). Under the
#: 0.2 m V2I noise at 20 Hz it leaves a standing person's speed estimate at about 0.1 m/s per axis (steady
#: state), four times q gives 0.15. A start or a stop is a manoeuvre the model does not describe: the gain
#: takes it up within about a second on V2I positions alone, half that on onboard ones
#: (docs/baseline_stack.md).
ACCEL_PSD_M2PS3 = 0.01
#: Prior standard deviation of a new track's velocity per axis [m/s]: covers a brisk walk (1.4 m/s) at
#: one standard deviation and a run (2.5 m/s) within two.
INITIAL_SPEED_SIGMA_MPS = 1.5
#: How long a track no longer measured is predicted on before it is dropped [s]. 2 s: about the longest
#: the roadside camera loses a jaywalker behind a queue on the study junctions (median 0.9 s, 90 % 1.7 s;
#: examples/tracking_stack.py), the hold that removed V2I's jaywalking collisions there.
TRACK_MEMORY_S = 2.0
#: Chi-square quantile, 2 degrees of freedom, 99.9 %: a velocity whose Mahalanobis distance from zero
#: is below it is not told apart from standing. The test is repeated every step, 20 times a second: at
#: 95 % a person standing at the kerb, seen over V2I alone, was told moving in the first second of their
#: track often enough to start the brakes (paper-v7's scenarios, 50 pairs: docs/baseline_stack.md). A
#: walker's second exact onboard position passes it (1.4 m/s against a standard deviation of about 0.3).
MOVING_CHI2 = 13.816
#: Validation gate of a track [chi-square, 2 degrees of freedom]: a position whose normalised innovation
#: squared (z - H x)^T S^-1 (z - H x) exceeds it under every motion model cannot have come from the track's
#: estimate at the gate probability, 99.9 % (the quantile above): the estimate has lost the person, who is
#: taken up afresh from this position as a new track (the validation region of Bar-Shalom, Li and
#: Kirubarajan, "Estimation with Applications to Tracking and Navigation", Wiley 2001, and track
#: initiation from an unassociated measurement). Without it, a track built on V2I positions (0.2 m noise,
#: 0.1 s old) that lags a pedestrian who has just stepped off took the first onboard position (0.01 m),
#: a metre or more ahead, as no motion, and held the walker as standing while they crossed
#: (docs/decisions/2026-11-27-tracker-validation-gate.md).
GATE_CHI2 = MOVING_CHI2
#: `tracker_gate` of [algorithm]: "precise" starts a track afresh from a position outside GATE_CHI2 that is
#: also more precise than the track's predicted position (its noise variance below the predicted
#: position variance, per axis on average); "reinitialise" from any position outside GATE_CHI2; "none"
#: folds every position in. A V2I position (0.2 m) outside the gate of a track that lags a start carries
#: little of its own: restarting from it discarded the history, and a start seen over V2I alone took
#: longer to be told (median 1.15 s, max 2.10 s, against 0.95 and 1.10 s: 200 synthetic starts); an
#: onboard position (0.01 m) outside it is the person, and the next one gives the velocity.
TRACKER_GATES = ("precise", "reinitialise", "none")

#: A track whose standing model (control/imm_tracker.py) is the more probable is not moving: the
#: maximum a posteriori model.
STANDING_PROBABILITY_THRESHOLD = 0.5

V2I_SOURCE = "v2i"


@dataclass(frozen=True)
class Track:
    """One pedestrian's estimate at the current step."""

    ped_id: str
    x_m: float
    y_m: float
    vx_mps: float
    vy_mps: float
    #: Covariance of (x, y, vx, vy) [m2, m2/s, m2/s2].
    covariance: np.ndarray
    #: Seconds since its last measurement (0 when measured this step).
    unseen_s: float
    #: Probability that the person stands still (the IMM tracker's standing model, control/imm_tracker.py);
    #: 0 from the constant-velocity tracker, which has no such model.
    standing_probability: float = 0.0

    @cached_property
    def moving(self) -> bool:
        """Whether the velocity differs from zero at 99.9 % (Mahalanobis distance under its covariance),
        the standing model, where there is one, being the less probable. Worked out once per track
        and step: the planner asks it at every predicted position."""
        if self.standing_probability > STANDING_PROBABILITY_THRESHOLD:
            return False
        v = np.array([self.vx_mps, self.vy_mps])
        cov = self.covariance[2:, 2:]
        try:
            return float(v @ lapack_call(_umath_linalg.solve1, cov, v)) > MOVING_CHI2
        except np.linalg.LinAlgError:
            return bool(np.any(v != 0.0))

    def position_sigma_m(self, direction: tuple[float, float], after_s: float) -> float:
        """Standard deviation of the position predicted `after_s` ahead, along the unit `direction`."""
        ux, uy = direction
        h = np.array([ux, uy, ux * after_s, uy * after_s])
        return math.sqrt(max(float(h @ self.covariance @ h), 0.0))

    def position_sigmas_m(self, directions: Any, after_s: Any) -> list[float]:
        """position_sigmas_array as a list."""
        return self.position_sigmas_array(directions, after_s).tolist()

    def position_sigmas_array(self, directions: Any, after_s: Any) -> np.ndarray:
        """position_sigma_m for several (direction, time) pairs at once, bit for bit: h C h' as a stack
        of 1 x 4 rows, so that numpy makes for each row the calls (vector-matrix, then dot) it makes for
        one (a 4 x 4 matrix product per row is rounded otherwise; tests/control pin the equality).
        `directions`: unit vectors, as (x, y) pairs or the rows of an n x 2 array; `after_s`: the times,
        a list or an array."""
        d = np.asarray(directions, dtype=float).reshape(-1, 2)
        t = np.asarray(after_s, dtype=float)
        h = np.empty((len(t), 1, 4))
        h[:, 0, 0], h[:, 0, 1] = d[:, 0], d[:, 1]
        h[:, 0, 2], h[:, 0, 3] = d[:, 0] * t, d[:, 1] * t
        return self.position_sigmas_of_rows(h)

    def position_sigmas_of_rows(self, h: np.ndarray) -> np.ndarray:
        """The standard deviations sqrt(h C h') of the rows h = (ux, uy, ux t, uy t), (n, 1, 4)."""
        variances = np.matmul(np.matmul(h, self.covariance), np.ascontiguousarray(h.transpose(0, 2, 1)))
        # np.sqrt and math.sqrt both round correctly (IEEE square root): the same floats.
        return np.sqrt(np.maximum(variances[:, 0, 0], 0.0))


def _raise_singular(err: str, flag: int) -> None:
    raise np.linalg.LinAlgError("Singular matrix")


def lapack_call(gufunc, *arrays: np.ndarray):
    """numpy.linalg's LAPACK gufunc of np.linalg.solve (`solve1`, a vector right-hand side) or inv on
    float64 stacks, as those functions call it (the same LAPACK routine per matrix, so the same bits, and
    LinAlgError on a singular matrix), without their per-call checks and conversions: the trackers call
    them every track and step."""
    with linalg_errors():
        return gufunc(*arrays, signature="dd->d" if len(arrays) == 2 else "d->d")


def linalg_errors() -> np.errstate:
    """The floating-point error handling numpy.linalg's solve and inv set around their LAPACK call: a
    singular matrix raises LinAlgError."""
    return np.errstate(call=_raise_singular, invalid="call", over="ignore", divide="ignore", under="ignore")


def frozen(array: np.ndarray) -> np.ndarray:
    """`array`, read-only: a matrix kept and shared between the steps and tracks."""
    array.setflags(write=False)
    return array


#: The identity of the state space, shared (read-only).
EYE4 = frozen(np.eye(4))


@lru_cache(maxsize=64)
def transition(dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q / q over `dt_s` (read-only: kept per step length, which repeats every step)."""
    f, q = _transition(dt_s)
    return frozen(f), frozen(q)


def _transition(dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt_s
    q = np.zeros((4, 4))
    a, b, c = dt_s**3 / 3, dt_s**2 / 2, dt_s
    for i in (0, 1):
        q[i, i], q[i, i + 2], q[i + 2, i], q[i + 2, i + 2] = a, b, b, c
    return f, q


class KalmanTracker:
    """Constant-velocity Kalman filters by pedestrian id, kept `memory_s` after their last measurement."""

    def __init__(
        self,
        memory_s: float = TRACK_MEMORY_S,
        accel_psd_m2ps3: float = ACCEL_PSD_M2PS3,
        v2i_sigma_m: float = V2I_POSITION_SIGMA_M,
        onboard_sigma_m: float = ONBOARD_POSITION_SIGMA_M,
        v2i_latency_s: float = V2I_LATENCY_S,
        gate_chi2: float | None = None,
        gate_precise_only: bool = False,
    ) -> None:
        self.memory_s = memory_s
        self.accel_psd = accel_psd_m2ps3
        #: The validation gate (GATE_CHI2), or None: every position is folded into its track.
        self.gate_chi2 = gate_chi2
        #: Restart only from a position more precise than the predicted one (`tracker_gate` "precise").
        self.gate_precise_only = gate_precise_only
        self.v2i_sigma_m = v2i_sigma_m
        self.onboard_sigma_m = onboard_sigma_m
        self.v2i_latency_s = v2i_latency_s
        # ped id -> [state (4,), covariance (4, 4), time of the state, time of the last measurement]
        self._tracks: dict[str, list] = {}
        self._h: dict[bool, np.ndarray] = {}  # measurement matrix by whether the position is V2I's
        self._r: dict[float, np.ndarray] = {}  # measurement noise covariance by standard deviation

    def _measurement(self, source: str) -> tuple[np.ndarray, float]:
        v2i = source == V2I_SOURCE
        if v2i not in self._h:
            h = np.zeros((2, 4))
            h[0, 0] = h[1, 1] = 1.0
            if v2i:
                h[0, 2] = h[1, 3] = -self.v2i_latency_s
            self._h[v2i] = frozen(h)
        return self._h[v2i], self.v2i_sigma_m if v2i else self.onboard_sigma_m

    def update(self, pedestrians: Iterable[PerceivedPedestrian], time_s: float) -> list[Track]:
        """Predict every track to `time_s`, fold in this step's positions, drop tracks unseen for longer
        than the memory; the tracks, in order of first sighting."""
        for kept in self._tracks.values():
            dt = time_s - kept[2]
            if dt > 0:
                f, q = transition(dt)
                kept[0] = f @ kept[0]
                kept[1] = f @ kept[1] @ f.T + self.accel_psd * q
                kept[2] = time_s
        for ped in pedestrians:
            z = np.array([ped.x_m, ped.y_m])
            h, sigma = self._measurement(ped.source)
            r = self._r.get(sigma)
            if r is None:
                r = self._r[sigma] = frozen(sigma * sigma * np.eye(2))
            track = self._tracks.get(ped.ped_id)
            if track is not None:
                x, p = track[0], track[1]
                s = h @ p @ h.T + r
                s_inv = lapack_call(_umath_linalg.inv, s)
                innovation = z - h @ x
                if (
                    self.gate_chi2 is not None
                    and float(innovation @ s_inv @ innovation) > self.gate_chi2
                    and (not self.gate_precise_only or sigma * sigma < (p[0, 0] + p[1, 1]) / 2)
                ):
                    track = None  # outside the validation gate: taken up afresh below
            if track is None:
                state = np.array([ped.x_m, ped.y_m, 0.0, 0.0])
                cov = np.diag([sigma**2, sigma**2, INITIAL_SPEED_SIGMA_MPS**2, INITIAL_SPEED_SIGMA_MPS**2])
                self._tracks[ped.ped_id] = [state, cov, time_s, time_s]
                continue
            gain = p @ h.T @ s_inv
            x = x + gain @ innovation
            i_kh = EYE4 - gain @ h
            p = i_kh @ p @ i_kh.T + gain @ r @ gain.T  # Joseph form: stays symmetric and positive
            track[0], track[1], track[3] = x, p, time_s
        for ped_id in [k for k, t in self._tracks.items() if time_s - t[3] > self.memory_s + 1e-9]:
            del self._tracks[ped_id]
        return [
            Track(ped_id, float(t[0][0]), float(t[0][1]), float(t[0][2]), float(t[0][3]), t[1], time_s - t[3])
            for ped_id, t in self._tracks.items()
        ]
