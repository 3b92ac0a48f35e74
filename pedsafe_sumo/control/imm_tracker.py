"""The baseline stack's manoeuvre-aware tracker: an interacting multiple model (IMM) filter per pedestrian.

Two motion models share the state (x, y, vx, vy) [m, m/s]:

- walking: the constant-velocity model of control/kalman_tracker.py (continuous white-noise acceleration,
  q = ACCEL_PSD_M2PS3), a V2I position measuring x - latency * v;
- standing: the velocity held at 0 (F = diag(1, 1, 0, 0)), the position wandering by a tiny random walk
  (STANDING_POSITION_PSD_M2PS); a V2I position measures x, the person having been there `latency` ago too.

Each step (Blom and Bar-Shalom, "The interacting multiple model algorithm for systems with Markovian
switching coefficients", IEEE Trans. Automatic Control 33(8), 1988; Bar-Shalom, Li and Kirubarajan,
"Estimation with Applications to Tracking and Navigation", Wiley 2001, section 11.6):

1. mixing: each model starts from the estimates of both, weighted by the probability that the person was
   in the other one a step ago given they are in this one now (Markov switching, SWITCH per step below);
2. model-conditioned prediction and update (Joseph form), with each model's own measurement matrix;
3. model probabilities from the innovations' Gaussian likelihoods;
4. combined estimate: the probability-weighted mean and covariance (with the spread of the means).

The planner reads the combined estimate (Track) and the standing model's probability
(Track.standing_probability): a track is moving when the walking model is the more probable and the
combined velocity differs from zero at 99.9 % (Track.moving). Object permanence as the constant-velocity
tracker: a track not measured is predicted on for `memory_s`, then dropped. With a validation gate
(`gate_chi2`, kalman_tracker.GATE_CHI2), a position outside both models' gates (under `gate_precise_only`:
and more precise than the predicted position) starts the track afresh.
Docs: docs/baseline_stack.md.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from functools import lru_cache

import numpy as np

# The gufuncs np.linalg.solve, inv and slogdet call (see kalman_tracker.lapack_call).
from numpy.linalg import _umath_linalg

from pedsafe_sumo.control.agent import PerceivedPedestrian
from pedsafe_sumo.control.kalman_tracker import (
    ACCEL_PSD_M2PS3,
    EYE4,
    INITIAL_SPEED_SIGMA_MPS,
    ONBOARD_POSITION_SIGMA_M,
    TRACK_MEMORY_S,
    V2I_LATENCY_S,
    V2I_POSITION_SIGMA_M,
    V2I_SOURCE,
    Track,
    frozen,
    linalg_errors,
    transition,
)
from pedsafe_sumo.control.tracker_kernels import mixed_estimates

#: Mean time a pedestrian walks before stopping, and stands before walking on [s]. Assumption: walking
#: outdoors comes in bouts of tens of steps with rests between them of seconds to tens of seconds
#: (Orendurff et al. 2008, "How humans walk: bout duration, steps per bout, and rest duration",
#: J. Rehabil. Res. Dev. 45(7)); 10 s for each, a round value of that order, not fitted to any scenario.
#: The per-step switch probability is dt / mean sojourn (0.005 at 20 Hz), so the chain's stationary
#: probability of standing, the prior of a new track, is 0.5.
MEAN_WALK_S = 10.0
MEAN_STAND_S = 10.0
#: Position random walk of a standing person [m2/s]: 1e-4 lets the position drift by sqrt(1e-4 t),
#: 1 cm over 1 s, the order of quiet standing's postural sway (centre-of-pressure excursions of millimetres
#: to a centimetre or two: Prieto et al. 1996, IEEE Trans. Biomed. Eng. 43(9)). It keeps the standing
#: model's position from freezing once converged; the simulated pedestrians stand exactly still.
STANDING_POSITION_PSD_M2PS = 1e-4
_WALK, _STAND = 0, 1


@lru_cache(maxsize=64)
def _standing_transition(dt_s: float, psd_m2ps: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of the standing model over `dt_s` (read-only: kept per step length)."""
    f = np.diag([1.0, 1.0, 0.0, 0.0])
    q = np.diag([psd_m2ps * dt_s, psd_m2ps * dt_s, 0.0, 0.0])
    return frozen(f), frozen(q)


def _log_gaussians(mahalanobis: list[float], s: np.ndarray) -> np.ndarray:
    """Log densities of innovations whose squared Mahalanobis distances under the stacked covariances `s`
    are `mahalanobis`."""
    signs, logdets = _umath_linalg.slogdet(s, signature="d->dd")
    dims = s.shape[-1]
    return np.array(
        [
            -math.inf if sign <= 0 else -0.5 * (m + logdet + dims * math.log(2 * math.pi))
            for m, sign, logdet in zip(mahalanobis, signs.tolist(), logdets.tolist())
        ]
    )


def _transposed(stack: np.ndarray) -> np.ndarray:
    """Each matrix of a stack transposed (a view, as `.T` of one matrix)."""
    return stack.transpose(0, 2, 1)


class _ImmTrack:
    """One pedestrian's two model-conditioned estimates and the models' probabilities.

    The models are stacked (row 0 walking, row 1 standing): numpy's matmul and numpy.linalg's gufuncs
    work matrix by matrix through a stack, making for each the BLAS or LAPACK call one matrix alone
    makes, so a stacked step gives the bits of one model at a time (tests/control/test_imm_tracker.py)."""

    def __init__(self, x_m: float, y_m: float, sigma_m: float, time_s: float, walk_prior: float) -> None:
        #: (2, 4): each model's state.
        self.states = np.array([[x_m, y_m, 0.0, 0.0], [x_m, y_m, 0.0, 0.0]])
        #: (2, 4, 4): each model's covariance.
        self.covs = np.array(
            [
                np.diag([sigma_m**2, sigma_m**2, INITIAL_SPEED_SIGMA_MPS**2, INITIAL_SPEED_SIGMA_MPS**2]),
                np.diag([sigma_m**2, sigma_m**2, 0.0, 0.0]),
            ]
        )
        self.probs = np.array([walk_prior, 1.0 - walk_prior])
        self.time_s = time_s
        self.seen_s = time_s

    def combined(self) -> tuple[np.ndarray, np.ndarray]:
        """The probability-weighted mean and covariance (with the spread of the means) of the models."""
        x, p = mixed_estimates(self.probs[:, None], self.states, self.covs)
        return x[0], p[0]


class ImmTracker:
    """Walking/standing IMM filters by pedestrian id, kept `memory_s` after their last measurement."""

    def __init__(
        self,
        memory_s: float = TRACK_MEMORY_S,
        accel_psd_m2ps3: float = ACCEL_PSD_M2PS3,
        standing_psd_m2ps: float = STANDING_POSITION_PSD_M2PS,
        mean_walk_s: float = MEAN_WALK_S,
        mean_stand_s: float = MEAN_STAND_S,
        v2i_sigma_m: float = V2I_POSITION_SIGMA_M,
        onboard_sigma_m: float = ONBOARD_POSITION_SIGMA_M,
        v2i_latency_s: float = V2I_LATENCY_S,
        gate_chi2: float | None = None,
        gate_precise_only: bool = False,
    ) -> None:
        self.memory_s = memory_s
        #: The validation gate (kalman_tracker.GATE_CHI2), or None: every position is folded in.
        self.gate_chi2 = gate_chi2
        #: Restart only from a position more precise than the predicted one (`tracker_gate` "precise").
        self.gate_precise_only = gate_precise_only
        self.accel_psd = accel_psd_m2ps3
        self.standing_psd = standing_psd_m2ps
        self.mean_walk_s = mean_walk_s
        self.mean_stand_s = mean_stand_s
        self.v2i_sigma_m = v2i_sigma_m
        self.onboard_sigma_m = onboard_sigma_m
        self.v2i_latency_s = v2i_latency_s
        self._tracks: dict[str, _ImmTrack] = {}
        # Kept between steps (read-only): Markov matrices and the models' stacked F, F^T and scaled Q by
        # step length; stacked measurement matrices (and their transposes) by whether the position is
        # V2I's, noise covariances likewise.
        self._switching: dict[float, np.ndarray] = {}
        self._motion: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._h: dict[bool, tuple[np.ndarray, np.ndarray]] = {}
        self._r: dict[bool, np.ndarray] = {}

    def switching(self, dt_s: float) -> np.ndarray:
        """Markov matrix [from, to] over `dt_s`: leave walking with dt / mean walk, standing with dt /
        mean stand (capped at 1)."""
        walk_to_stand = min(dt_s / self.mean_walk_s, 1.0)
        stand_to_walk = min(dt_s / self.mean_stand_s, 1.0)
        return np.array([[1.0 - walk_to_stand, walk_to_stand], [stand_to_walk, 1.0 - stand_to_walk]])

    def _switching_kept(self, dt_s: float) -> np.ndarray:
        switch = self._switching.get(dt_s)
        if switch is None:
            if len(self._switching) >= 64:
                self._switching.clear()
            switch = self._switching[dt_s] = frozen(self.switching(dt_s))
        return switch

    def _motion_kept(self, dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The models' F stacked, its transposes, and their process noises (the walking model's Q scaled
        by the acceleration PSD, the standing model's as it is)."""
        motion = self._motion.get(dt_s)
        if motion is None:
            if len(self._motion) >= 64:
                self._motion.clear()
            (f_walk, q_walk), (f_stand, q_stand) = (
                transition(dt_s),
                _standing_transition(dt_s, self.standing_psd),
            )
            f = frozen(np.array([f_walk, f_stand]))
            q = frozen(np.array([self.accel_psd * q_walk, 1.0 * q_stand]))
            motion = self._motion[dt_s] = (f, _transposed(f), q)
        return motion

    def _measurements(self, v2i: bool) -> tuple[np.ndarray, np.ndarray]:
        """H of both models stacked (a V2I position measures the walking model's x - latency * v), and
        the stack transposed."""
        kept = self._h.get(v2i)
        if kept is None:
            h = np.zeros((2, 2, 4))
            h[:, 0, 0] = h[:, 1, 1] = 1.0
            if v2i:
                h[_WALK, 0, 2] = h[_WALK, 1, 3] = -self.v2i_latency_s
            h = frozen(h)
            kept = self._h[v2i] = (h, _transposed(h))
        return kept

    def _predict(self, track: _ImmTrack, dt_s: float) -> None:
        switch = self._switching_kept(dt_s)
        f, f_t, q = self._motion_kept(dt_s)
        probs, states = track.probs, track.states
        predicted = switch.T @ probs  # c_j = sum_i p_ij mu_i
        # weights[i, j] = p_ij mu_i / c_j: model j starts from model i's estimate with this weight; a model
        # with c_j = 0 starts from the probabilities as they are.
        reachable = predicted > 0
        weights = np.where(
            reachable, switch * probs[:, None] / np.where(reachable, predicted, 1.0), probs[:, None]
        )
        x0s, p0s = mixed_estimates(weights, states, track.covs)  # both models' mixed starts
        track.states = np.matmul(f, x0s[:, :, None])[:, :, 0]
        track.covs = f @ p0s @ f_t + q
        track.probs = predicted

    def _noise(self, v2i: bool) -> np.ndarray:
        r = self._r.get(v2i)
        if r is None:
            sigma = self.v2i_sigma_m if v2i else self.onboard_sigma_m
            r = self._r[v2i] = frozen(sigma * sigma * np.eye(2))
        return r

    def _update(self, track: _ImmTrack, z: np.ndarray, source: str) -> bool:
        """Fold `z` into the track; False (the track untouched) when `z` lies outside the validation gate
        of both models' predictions (and, with `gate_precise_only`, is more precise than the combined
        predicted position): the estimate has lost the person."""
        v2i = source == V2I_SOURCE
        r = self._noise(v2i)
        h, h_t = self._measurements(v2i)
        x, p = track.states, track.covs
        s = h @ p @ h_t + r
        innovations = z - np.matmul(h, x[:, :, None])[:, :, 0]
        with linalg_errors():  # as np.linalg.solve and inv, in one context for both calls
            solved = _umath_linalg.solve1(s, innovations, signature="dd->d")
            s_inv = _umath_linalg.inv(s, signature="d->d")
        # Each innovation @ its solution, a vector-vector dot as for one model alone.
        mahalanobis = np.matmul(innovations[:, None, :], solved[:, :, None])[:, 0, 0].tolist()
        if self.gate_chi2 is not None and all(m > self.gate_chi2 for m in mahalanobis):
            if not self.gate_precise_only:
                return False
            _, p_combined = track.combined()
            if float(r[0, 0]) < (p_combined[0, 0] + p_combined[1, 1]) / 2:
                return False
        gain = p @ h_t @ s_inv
        i_kh = EYE4 - gain @ h
        track.states = x + np.matmul(gain, innovations[:, :, None])[:, :, 0]
        track.covs = i_kh @ p @ _transposed(i_kh) + gain @ r @ _transposed(gain)
        weighted = _log_gaussians(mahalanobis, s) + np.log(np.maximum(track.probs, 1e-300))
        weighted -= weighted.max()
        probs = np.exp(weighted)
        track.probs = probs / probs.sum()
        return True

    def update(self, pedestrians: Iterable[PerceivedPedestrian], time_s: float) -> list[Track]:
        """Mix and predict every track to `time_s`, fold in this step's positions, drop tracks unseen for
        longer than the memory; the combined tracks, in order of first sighting."""
        for kept in self._tracks.values():
            dt = time_s - kept.time_s
            if dt > 0:
                self._predict(kept, dt)
                kept.time_s = time_s
        walk_prior = self.mean_walk_s / (self.mean_walk_s + self.mean_stand_s)
        for ped in pedestrians:
            track = self._tracks.get(ped.ped_id)
            if track is not None and self._update(track, np.array([ped.x_m, ped.y_m]), ped.source):
                track.seen_s = time_s
                continue
            # A new pedestrian, or a position outside the gate: the track starts (afresh) from it.
            sigma = self.v2i_sigma_m if ped.source == V2I_SOURCE else self.onboard_sigma_m
            self._tracks[ped.ped_id] = _ImmTrack(ped.x_m, ped.y_m, sigma, time_s, walk_prior)
        for ped_id in [k for k, t in self._tracks.items() if time_s - t.seen_s > self.memory_s + 1e-9]:
            del self._tracks[ped_id]
        out = []
        for ped_id, t in self._tracks.items():
            x, p = t.combined()
            out.append(
                Track(
                    ped_id,
                    float(x[0]),
                    float(x[1]),
                    float(x[2]),
                    float(x[3]),
                    p,
                    time_s - t.seen_s,
                    standing_probability=float(t.probs[_STAND]),
                )
            )
        return out
