"""One navigation goal from acceptance to its end, as Nav2's NavigateToPose reports it: the
distance left along the plan, the time driven and the time still to drive, the re-plans, and
whether the goal is reached (position within ``xy_tolerance`` and, when the goal has one, its
heading within ``yaw_tolerance``). No rclpy: global_planner feeds it poses, plans and the time.

Poses are (x [m], y [m], yaw [rad]); plans are (P, 2) [m] in the global frame; ``now`` is a
clock reading in seconds.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ecahd_core.errors import EcahdError

SPEED_WINDOW = 3.0  # [s] of progress the time-remaining estimate averages the speed over
MIN_SPEED = 0.02  # [m/s] slower progress than this gives no time estimate (0)


def wrap_angle(angle: float) -> float:
    """``angle`` [rad] wrapped to [-pi, pi)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class MissionConfig:
    """When a goal counts as reached, and how long the robot may stand at its position without
    turning to its heading (``align_timeout``) before the goal fails."""

    xy_tolerance: float = 0.3  # [m]
    yaw_tolerance: float = 0.25  # [rad]
    align_timeout: float = 15.0  # [s]

    def __post_init__(self) -> None:
        for name in ("xy_tolerance", "yaw_tolerance", "align_timeout"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise EcahdError(f"{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class MissionProgress:
    """What one look at the mission says.

    Attributes:
        state: "driving", "aligning" (at the position, turning to the heading), "succeeded"
            or "failed".
        distance_remaining: [m] along the plan from the robot's projection onto it (straight
            to the goal without a plan).
        elapsed: [s] since the goal was accepted.
        time_remaining: [s] distance_remaining over the recent speed of progress (0: unknown).
        replans: plans after the first one for this goal.
        message: why it failed ("" otherwise).
    """

    state: str
    distance_remaining: float
    elapsed: float
    time_remaining: float
    replans: int
    message: str = ""


def distance_along(plan: np.ndarray, xy: np.ndarray) -> float:
    """[m] the length of ``plan`` (P, 2) from the point of it nearest ``xy`` (2,) to its end."""
    plan = np.asarray(plan, dtype=np.float64).reshape(-1, 2)
    if len(plan) < 2:
        return float(np.linalg.norm(plan[-1] - xy)) if len(plan) else 0.0
    a, b = plan[:-1], plan[1:]
    ab = b - a
    length = np.linalg.norm(ab, axis=1)
    t = np.clip(np.einsum("ij,ij->i", xy - a, ab) / np.maximum(length ** 2, 1e-12), 0.0, 1.0)
    nearest = a + t[:, None] * ab
    k = int(np.argmin(np.linalg.norm(nearest - xy, axis=1)))
    return float((1.0 - t[k]) * length[k] + length[k + 1:].sum())


class Mission:
    """One goal: ``goal`` (2,) [m], ``yaw`` [rad] or None (any heading), accepted at
    ``start_time`` [s]. Call :meth:`planned` for every plan made for it, :meth:`update` with the
    robot's pose."""

    def __init__(self, goal, yaw: float | None, start_time: float,
                 config: MissionConfig | None = None) -> None:
        self.goal = np.asarray(goal, dtype=np.float64).reshape(2)
        self.yaw = None if yaw is None else float(yaw)
        self.start_time = float(start_time)
        self.config = config or MissionConfig()
        self.plan: np.ndarray | None = None
        self.plans = 0
        self._at_position_since: float | None = None
        self._progress: deque[tuple[float, float]] = deque()  # (now, distance remaining)
        self.state = "driving"
        self.message = ""
        self.code = 0  # the caller's error code for a failure (0: none given)

    def planned(self, plan) -> None:
        """A plan (P, 2) [m] for this goal went out."""
        self.plan = np.asarray(plan, dtype=np.float64).reshape(-1, 2)
        self.plans += 1

    def fail(self, message: str, code: int = 0) -> None:
        """The goal cannot be reached (``code``: the caller's error code for it)."""
        self.state, self.message, self.code = "failed", message, code

    def update(self, pose, now: float) -> MissionProgress:
        """The robot is at ``pose`` (x, y, yaw) at ``now`` [s]: the mission's progress (a
        finished mission stays finished)."""
        x, y, yaw = (float(v) for v in pose)
        xy = np.array([x, y])
        c = self.config
        to_goal = float(np.linalg.norm(self.goal - xy))
        remaining = to_goal if self.plan is None else distance_along(self.plan, xy)
        if self.state in ("driving", "aligning"):
            if to_goal < c.xy_tolerance:
                heading_ok = self.yaw is None or abs(wrap_angle(yaw - self.yaw)) <= c.yaw_tolerance
                if heading_ok:
                    self.state = "succeeded"
                else:
                    if self._at_position_since is None:
                        self._at_position_since = now
                    self.state = "aligning"
                    if now - self._at_position_since > c.align_timeout:
                        self.fail(f"at the goal's position but not turned to its heading "
                                  f"({math.degrees(wrap_angle(yaw - self.yaw)):+.0f} deg off) "
                                  f"within {c.align_timeout:g} s: turning in place is blocked")
            else:
                self._at_position_since = None
                self.state = "driving"
        if self.state == "succeeded":
            remaining = 0.0
        return MissionProgress(self.state, remaining, max(now - self.start_time, 0.0),
                               self._time_remaining(remaining, now), max(self.plans - 1, 0),
                               self.message)

    def _time_remaining(self, remaining: float, now: float) -> float:
        """[s] ``remaining`` over the progress speed of the last SPEED_WINDOW s (0: unknown)."""
        samples = self._progress
        samples.append((now, remaining))
        while len(samples) > 2 and now - samples[0][0] > SPEED_WINDOW:
            samples.popleft()
        t0, d0 = samples[0]
        if now - t0 <= 0:
            return 0.0
        speed = (d0 - remaining) / (now - t0)
        return remaining / speed if speed > MIN_SPEED else 0.0
