"""V2I link: roadside detections travel to the ego with latency, packet loss and position noise.

Each frame the roadside unit sends one message (possibly empty) holding the pedestrians it detected,
as points in its own camera frame (P_I of the paper's eq. 5). On the way:

* the whole message is lost with probability ``packet_loss_probability`` (one draw per message);
* each pedestrian's ground position gets isotropic Gaussian noise of ``position_noise_sigma_m`` in
  world x and y before it is expressed in the roadside camera frame (two draws per pedestrian);
* it becomes available at ``sent_time_s + latency_s``: :meth:`V2ILink.receive` at time t returns the
  messages with ``deliver_time_s <= t + 1e-9``. With a simulation step dt, a message sent at step k
  is used at step ``k + ceil(latency_s / dt)`` (100 ms at 0.05 s: 2 steps later; 0 s: same step).

The ego turns a delivered message into its own camera frame with eq. 5 (P_V = R_V R_I^-1 P_I, both
4x4 world-to-camera transforms, R_V the ego camera's pose at reception) and into pixels with eq. 6.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .geometry import invert_transform, project_points, transform_points

_TIME_EPS_S = 1e-9
_NO_POINTS = np.zeros((0, 3))


@dataclass(frozen=True)
class V2ISpec:
    latency_s: float
    packet_loss_probability: float
    position_noise_sigma_m: float

    @classmethod
    def from_params(cls, p: dict) -> V2ISpec:
        return cls(
            float(p["latency_s"]), float(p["packet_loss_probability"]), float(p["position_noise_sigma_m"])
        )


@dataclass(frozen=True)
class V2IMessage:
    """One roadside frame: pedestrian ids and their ground points in the roadside camera frame (m)."""

    rsu_id: str
    sent_time_s: float
    deliver_time_s: float
    ped_ids: tuple
    points_roadside_m: np.ndarray  # (K, 3), OpenCV camera axes of the roadside camera
    world_to_roadside: np.ndarray  # 4x4, the paper's R_I


class V2ILink:
    """The per-episode message queue between roadside units and the ego (stateful, FIFO).

    ``rng``: an optional generator of the link's own (loss and noise draws). Give the link its own
    stream (e.g. ``SeedSequence(seed).spawn(...)``) and the generator passed to ``perceive`` is used
    for the onboard draws only, so they are identical whether or not the episode has a link (SV and
    V2I stay paired even with per-frame misses). Without one, ``perceive``'s generator is used.
    """

    def __init__(self, spec: V2ISpec, rng: np.random.Generator | None = None):
        self.spec = spec
        self.rng = rng
        self._queue: deque[V2IMessage] = deque()
        self.sent = 0
        self.lost = 0

    def send(
        self,
        time_s: float,
        rsu_id: str,
        world_to_roadside: np.ndarray,
        ped_ids,
        ground_xy_m: np.ndarray,
        rng: np.random.Generator,
    ) -> V2IMessage | None:
        """Queue one roadside frame (true world ground positions (K, 2)); returns it, or None if lost."""
        self.sent += 1
        if rng.random() < self.spec.packet_loss_probability:
            self.lost += 1
            return None
        xy = np.asarray(ground_xy_m, dtype=float).reshape(-1, 2)
        if xy.shape[0]:
            if self.spec.position_noise_sigma_m > 0:
                xy = xy + rng.normal(0.0, self.spec.position_noise_sigma_m, size=xy.shape)
            world_pts = np.zeros((xy.shape[0], 3))
            world_pts[:, :2] = xy
            points = world_pts @ world_to_roadside[:3, :3].T + world_to_roadside[:3, 3]  # transform_points
        else:
            points = _NO_POINTS  # an empty message (most frames): no arrays to build
        msg = V2IMessage(
            rsu_id=rsu_id,
            sent_time_s=float(time_s),
            deliver_time_s=float(time_s) + self.spec.latency_s,
            ped_ids=tuple(ped_ids),
            points_roadside_m=points,
            world_to_roadside=world_to_roadside,
        )
        self._queue.append(msg)
        return msg

    def receive(self, time_s: float) -> list[V2IMessage]:
        """Pop every message due by ``time_s`` (in sending order)."""
        out = []
        while self._queue and self._queue[0].deliver_time_s <= time_s + _TIME_EPS_S:
            out.append(self._queue.popleft())
        return out

    def __len__(self) -> int:
        return len(self._queue)


def message_to_vehicle(msg: V2IMessage, world_to_vehicle_camera: np.ndarray, intrinsics: np.ndarray):
    """Eqs. 5-6 for one message: (points in the ego camera frame (K, 3), pixels (K, 2), in_front (K,),
    world ground positions (K, 3)). Pixels are NaN behind the ego camera."""
    p_v = transform_points(
        world_to_vehicle_camera @ invert_transform(msg.world_to_roadside), msg.points_roadside_m
    )
    pixels, in_front = project_points(intrinsics, p_v)
    world = transform_points(invert_transform(world_to_vehicle_camera), p_v)
    return p_v, pixels, in_front, world
