"""A last-line velocity filter against obstacles seen by the LiDAR (issue 11), with Nav2
collision_monitor's "stop" and "slowdown" semantics, as a pure class (no rclpy).

Every command (v, w) is checked before it reaches the base:

1. Stale or missing points (older than ``source_timeout``) -> **stop**, as Nav2 does when a
   source times out: the robot must not drive blind.
2. The unicycle motion at (v, w) is simulated over ``time_to_collision`` seconds in ``sim_dt``
   steps (poses k = 0 .. K, k = 0 the current one; exact arcs, so v < 0 simply drives backwards),
   and every scan point is moved into every future robot frame: a (K + 1, M) table of the
   points' clearance to the footprint polygon (0 inside it, exact point-in-polygon and
   point-to-edge distance; exact circle for circular robots).
3. If at least ``min_points`` points come within ``stop_margin`` of the footprint at some step
   -> **stop**: v = w = 0. Like Nav2, rotation in place is not let through even when it alone
   would be collision free: a point that close means the scan, the pose or the plan is wrong,
   and the planner, not the filter, should decide how to get out.
4. Else if at least ``min_points`` static points come within ``slowdown_margin`` at some step ->
   **slowdown**: v and w are scaled by ``slowdown_ratio`` (``slowdown_profile`` "step", Nav2's
   polygon), or by a ratio that grows linearly from ``slowdown_ratio`` at ``stop_margin`` to 1
   at ``slowdown_margin`` with the static points' least clearance over the horizon ("linear",
   ours: passing a box 0.25 m away is not crawling past it), and the slowed command is checked
   again (step 3; stop if it fails).
5. Else the command passes unchanged ("none").

The static map (beyond Nav2): given the map's overlap depths (``depths``), every command that
passes is also simulated over ``static_horizon`` (off by default in the config; the
local_refiner node's static guard calls :meth:`CollisionMonitor.keep_off_map` on every command
with its own horizon and the robot's real footprint, scans or none) and refused when it would
bring the footprint into the map (or deeper into it than now): the robot turns on the spot
instead if that is clear, else stops. The planners keep a clearance margin from walls, but a
tracker's arc cuts corners, and a local plan that doubles back swings the robot round in a
narrow corridor; the scan points the monitor sees are only the unmapped ones.

Moving obstacles (beyond Nav2). Given each point's velocity (:mod:`ecahd_core.tracking`), a
point is predicted at p + v t at step time t, its clearance shrunk by ``prediction_growth`` t
(the estimate's uncertainty, up to t = time_to_collision), so the monitor judges where a
crossing person or cart *will* be. A robot that stops in its way is hit all the same, so when
the command must stop and the stopped robot itself would be touched by a moving point within
``yield_horizon`` seconds, the monitor **yields**: it tries a small set of commands (v in {-1,
-1/2, 0, 1/2, 1} x max_v, w in {-1/2, 0, 1/2} x max_w of ``escape_limits``), each cut before
its first simulated pose that the caller's ``depths`` put into the static map (the robot would
wait there; the scan points here are only the unmapped ones), and sends the one
touched in the fewest steps, then latest, then the last yield's command again (no dithering),
then farthest from what comes at the horizon's end: often backing off out of the crossing,
sometimes clearing it ahead. Standing still wins ties. Only static points slow the robot down:
slowing near a moving one does not help (it may come from behind).

The step k of the first stop hit gives ``min_time_to_collision`` = k sim_dt [s] (``inf`` when
nothing is hit within the horizon). A point is never skipped between two steps as long as
|v| sim_dt is smaller than the footprint's width. Frames and units: map frame, metres, radians,
seconds; the footprint polygon is in the robot frame (x forward).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from ecahd_core.collision import DEFAULT_TOLERANCE
from ecahd_core.errors import EcahdError
from ecahd_core.footprint import Footprint
from ecahd_core.local_costmap import check_real

ACTIONS = ("none", "slowdown", "stop", "yield")
SLOWDOWN_PROFILES = ("linear", "step")
_ESCAPE_V = (-1.0, -0.5, 0.0, 0.5, 1.0)  # escape commands' v as fractions of max_v
_ESCAPE_W = (-0.5, 0.0, 0.5)  # ... and w as fractions of max_w
_OWNER = "collision monitor"
STATIC_STEP = 0.01  # [m] the static check samples a held command at most this far apart
_STRAIGHT_W = 1e-9  # [rad/s] below this |w| the motion is integrated as a straight line


def predicted_offsets(vel: np.ndarray, bounds: np.ndarray | None, t: np.ndarray) -> np.ndarray:
    """(T, M, 2) [m] where each point will have moved at times t (T,) [s]: v t, or for a
    point with finite bounds (M, 2) [m] (behind <= 0 <= ahead, along its motion) v t folded
    back and forth into [behind, ahead] (a triangle wave at |v|). vel: (M, 2) [m/s]."""
    disp = t[:, None, None] * vel[None, :, :]  # (T, M, 2)
    if bounds is None:
        return disp
    fold = np.isfinite(bounds).all(axis=1) & vel.any(axis=1)  # (M,)
    if not fold.any():
        return disp
    v = vel[fold]  # (m, 2)
    speed = np.hypot(v[:, 0], v[:, 1])  # (m,)
    lo, hi = np.minimum(bounds[fold, 0], 0.0), np.maximum(bounds[fold, 1], 0.0)  # (m,)
    length = hi - lo  # (m,) [m]
    x = speed[None, :] * t[:, None] - lo[None, :]  # (T, m) [m] from the rear end
    period = np.maximum(2.0 * length, 1e-9)[None, :]
    m = np.mod(x, period)
    s = lo[None, :] + np.where(m <= length[None, :], m, period - m)  # (T, m) offset along v
    s = np.where(length[None, :] > 0, s, 0.0)
    disp[:, fold, :] = s[..., None] * (v / speed[:, None])[None, :, :]
    return disp


@dataclass(frozen=True, kw_only=True)
class CollisionMonitorConfig:
    """Settings of the collision monitor (one place defines each default).

    Attributes:
        time_to_collision: [s] horizon over which the commanded motion is simulated.
        sim_dt: [s] simulation step (Nav2 ``simulation_time_step``).
        slowdown_ratio: factor in (0, 1] applied to v and w on a slowdown.
        slowdown_margin: [m] points within this distance of the footprint slow the robot.
        slowdown_profile: "linear" (default): the slowdown's ratio is ``slowdown_ratio`` for a
            least clearance c (the static points' nearest approach to the footprint over the
            horizon) at ``stop_margin`` and grows linearly to 1 at ``slowdown_margin``; "step":
            ``slowdown_ratio`` whatever c (Nav2's slowdown polygon). With "step" the robot
            crawled at 0.15 m/s beside every box it passed: 78% of the control ticks of a
            depot episode with 5 boxes (docs/RESULTS.md).
        stop_margin: [m] points within this distance of the footprint stop the robot
            (<= slowdown_margin).
        min_points: points needed to trigger an action (Nav2 ``min_points``).
        source_timeout: [s] points older than this count as no data and stop the robot
            (Nav2 ``source_timeout``); 0 disables the check.
        slowdown_limits: (max_v [m/s], max_w [rad/s]) or None. None: a slowdown multiplies
            the command by ``slowdown_ratio`` (Nav2). Given: a slowdown caps the command at
            ``slowdown_ratio`` times these limits instead. Use it when the controller ramps its
            next command from the one sent: scaling that again every tick decays the speed to
            a fixed point far below the ratio (ratio * accel * dt / (1 - ratio): 0.02 m/s for
            0.3, 1 m/s^2 and 20 Hz, measured in the closed loop), while the cap holds it at
            ratio * max_v.
        escape_limits: (max_v [m/s], max_w [rad/s]) of the commands tried when yielding to a
            moving obstacle; None: never yield (stop, as Nav2).
        yield_horizon: [s] how far ahead a moving point is predicted when judging whether the
            stopped robot would be hit, and the escape commands.
        prediction_growth: [m/s] a moving point predicted t seconds ahead counts as this
            times min(t, time_to_collision) closer (its velocity is an estimate: errors up to
            0.1 m/s measured, and a person may turn); 0 trusts the prediction. 0 by default:
            0.15 m/s made the robot yield so often that 13 of 20 moving-obstacle episodes
            reached their goals, against 17 of 20 without it.
        static_horizon: [s] how far ahead every command is checked against the static map
            (when the caller gives the map's depths): the tracker's arcs cut corners; 0: not
            checked. Off by default: in the closed loop (20 episodes) a robot whose pose lay
            within the clearance margin of a wall was stopped for the rest of the episode
            (1000-1500 ticks) in 2 episodes.
        beat_horizon: [s] a command that, held, meets a mover going back and forth (points
            given with finite ``bounds``) within this horizon is stopped: the robot does not
            start across its beat; 0: not checked. Off by default: with it (3 s) the robot
            waited for crossers, 10 of 20 moving-obstacle episodes reached against 14 without it.
    """

    time_to_collision: float = 1.0
    sim_dt: float = 0.1
    slowdown_ratio: float = 0.3
    slowdown_margin: float = 0.3
    slowdown_profile: str = "linear"
    stop_margin: float = 0.02
    min_points: int = 1
    source_timeout: float = 0.5  # five missed scans at 10 Hz (Nav2's default: 2.0)
    slowdown_limits: tuple[float, float] | None = None
    escape_limits: tuple[float, float] | None = None
    yield_horizon: float = 3.0
    prediction_growth: float = 0.0
    static_horizon: float = 0.0
    beat_horizon: float = 0.0

    def __post_init__(self) -> None:
        for field in ("slowdown_limits", "escape_limits"):
            limits = getattr(self, field)
            if limits is None:
                continue
            if len(limits) != 2:
                raise EcahdError(f"{field} must be (max_v, max_w) or None, got {limits!r}")
            for name, value in zip(("max_v", "max_w"), limits):
                check_real(_OWNER, f"{field} {name}", value, zero_ok=False)
        for name in ("time_to_collision", "sim_dt", "slowdown_ratio", "yield_horizon"):
            check_real(_OWNER, name, getattr(self, name), zero_ok=False)
        for name in ("slowdown_margin", "stop_margin", "source_timeout", "prediction_growth",
                     "static_horizon", "beat_horizon"):
            check_real(_OWNER, name, getattr(self, name), zero_ok=True)
        if self.slowdown_profile not in SLOWDOWN_PROFILES:
            raise EcahdError(f"slowdown_profile must be one of {list(SLOWDOWN_PROFILES)}, got "
                             f"{self.slowdown_profile!r}")
        if self.slowdown_ratio > 1:
            raise EcahdError(f"slowdown_ratio must be in (0, 1], got {self.slowdown_ratio!r}")
        if self.stop_margin > self.slowdown_margin:
            raise EcahdError(f"stop_margin ({self.stop_margin} m) must not exceed "
                             f"slowdown_margin ({self.slowdown_margin} m)")
        n = self.min_points
        if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 1:
            raise EcahdError(f"min_points must be an integer >= 1, got {n!r}")

    @property
    def steps(self) -> int:
        """K: simulated steps after the current pose (ceil(time_to_collision / sim_dt))."""
        return max(1, math.ceil(self.time_to_collision / self.sim_dt - 1e-9))

    @property
    def yield_steps(self) -> int:
        """Simulated steps of the yield check (ceil(yield_horizon / sim_dt))."""
        return max(1, math.ceil(self.yield_horizon / self.sim_dt - 1e-9))


@dataclass(frozen=True)
class MonitorResult:
    """What :meth:`CollisionMonitor.filter` lets through.

    Attributes:
        v: [m/s] the filtered linear velocity.
        w: [rad/s] the filtered angular velocity.
        action: "none", "slowdown", "stop" or "yield" (an escape from a moving obstacle).
        min_time_to_collision: [s] time of the first simulated step whose footprint (+
            stop_margin) holds min_points points, for the command as given; inf if none
            within the horizon, 0 when the data is stale.
        reason: one line for the log.
    """

    v: float
    w: float
    action: str
    min_time_to_collision: float
    reason: str


class CollisionMonitor:
    """Stop / slowdown filter of velocity commands (see the module docstring).

    Args:
        footprint: the robot footprint (its polygon, or its exact radius for a circle).
        config: the monitor settings (default CollisionMonitorConfig()).
    """

    def __init__(self, footprint: Footprint, config: CollisionMonitorConfig | None = None
                 ) -> None:
        self.footprint = footprint
        self.config = CollisionMonitorConfig() if config is None else config
        poly = np.asarray(footprint.polygon, dtype=np.float64)  # (V, 2) robot frame [m]
        self._a = poly  # (V, 2) edge starts
        self._ab = np.roll(poly, -1, axis=0) - poly  # (V, 2) edge vectors
        self._ab_len2 = np.maximum(np.sum(self._ab ** 2, axis=1), 1e-18)  # (V,)
        cfg = self.config
        # points farther than this from the robot now cannot trigger anything in the horizon
        self._reach_static = footprint.circumscribed_radius + cfg.slowdown_margin
        self._t = np.arange(cfg.steps + 1) * cfg.sim_dt  # (K+1,) [s]
        self._t_yield = np.arange(cfg.yield_steps + 1) * cfg.sim_dt  # (Ky+1,) [s]
        self._t_beat = np.arange(max(1, math.ceil(cfg.beat_horizon / cfg.sim_dt - 1e-9)) + 1
                                 ) * cfg.sim_dt  # (Kb+1,) [s]
        self._last_yield: tuple[float, float] | None = None  # its command (v, w)

    # ------------------------------------------------------------------------------ filter
    def filter(self, pose, v: float, w: float, points, points_stamp: float | None,
               now: float, *, velocities=None, bounds=None, depths=None) -> MonitorResult:
        """Filter one velocity command.

        Args:
            pose: (3,) robot x [m], y [m], yaw [rad] in the frame of ``points``.
            v: [m/s] commanded linear velocity (negative: reverse).
            w: [rad/s] commanded angular velocity.
            points: (M, 2) obstacle points (x, y) [m], e.g. the scan's endpoints or
                :meth:`LocalCostmap.points`; rows with NaN are ignored.
            points_stamp: [s] time the points were measured; None = no data yet.
            now: [s] the current time.
            bounds: (M, 2) [m] or None: where each moving point turns round, as offsets
                (behind <= 0 <= ahead) along its motion (:func:`~ecahd_core.sensing.
                shuttle_bounds`; +-inf: never). A point with finite bounds (a mover seen going
                back and forth) is predicted folded into that stretch; with ``beat_horizon``
                the command is also stopped if it meets it within that horizon, not only
                within time_to_collision: the robot does not start across a mover's beat that
                the mover will sweep again before the robot is through.
            velocities: (M, 2) [m/s] each point's velocity (:class:`MotionTracker`); None:
                every point is static.
            depths: callable (N, 3) poses -> (N,) overlap depth [m] of the footprint with the
                static map (<= 0: clear; e.g. :meth:`StaticClearance.depths` with the footprint
                grown by the clearance margin). Given, every command is also checked against
                the map over ``static_horizon`` (the scan points here are only the unmapped
                ones) and the robot may yield; None: neither.

        Returns:
            MonitorResult with the command to send.
        """
        result = self._filter_points(pose, v, w, points, points_stamp, now, velocities, bounds,
                                     depths)
        if depths is None or result.action in ("stop", "yield"):
            return result
        return self.keep_off_map(pose, result, depths)

    def keep_off_map(self, pose, result: MonitorResult, depths,
                     horizon: float | None = None) -> MonitorResult:
        """The static map's check alone (also where no scan points flow): ``result``'s command
        held over ``horizon`` [s] (default ``static_horizon``; 0: not checked) must not bring
        the footprint into the map, nor deeper into it than now; else the robot turns on the
        spot if that is clear (the tracker's arc straightens as the heading error shrinks), or
        stops. The held motion is sampled every STATIC_STEP metres of the footprint's travel,
        so a door's jamb is not passed between two samples. ``depths`` as for :meth:`filter`.

        Args:
            pose: (3,) x [m], y [m], yaw [rad].
            result: the command so far (e.g. ``MonitorResult(v, w, "none", inf, "")``).

        Returns:
            ``result`` unchanged, or a "stop" (v = 0, w = 0 or the turn on the spot).
        """
        horizon = self.config.static_horizon if horizon is None else horizon
        if horizon == 0 or (result.v == 0.0 and result.w == 0.0):
            return result
        v, w = float(result.v), float(result.w)
        t = self._static_times(horizon, v, w)
        if self._static_ok(pose, v, w, depths, t):
            return result
        turn = w if w != 0.0 and v != 0.0 and self._static_ok(pose, 0.0, w, depths, t) else 0.0
        return MonitorResult(0.0, turn, "stop", result.min_time_to_collision,
                             f"v={v:.2f} m/s, w={w:.2f} rad/s would touch the static map "
                             f"within {horizon:g} s" + (": turning on the spot" if turn else ""))

    def _static_times(self, horizon: float, v: float, w: float) -> np.ndarray:
        """(T,) [s] sample times of a held command over ``horizon``: sim_dt apart, closer
        where |v| + |w| r (r: circumscribed radius) moves the footprint more than STATIC_STEP
        in sim_dt."""
        speed = abs(v) + abs(w) * self.footprint.circumscribed_radius  # [m/s]
        dt = min(self.config.sim_dt, STATIC_STEP / speed) if speed > 0 else self.config.sim_dt
        n = max(1, math.ceil(horizon / dt - 1e-9))
        return np.linspace(0.0, n * dt, n + 1)

    def _static_ok(self, pose, v: float, w: float, depths, t: np.ndarray) -> bool:
        """The motion at (v, w) over the times ``t`` (T,) [s] never goes deeper into the
        static map than the robot is now, nor into it when it is clear now."""
        d = np.asarray(depths(self.simulate(pose, v, w, t)), dtype=np.float64)
        return bool(np.all(d[1:] <= max(float(d[0]), DEFAULT_TOLERANCE)))

    def _filter_points(self, pose, v: float, w: float, points, points_stamp, now: float,
                       velocities, bounds, depths) -> MonitorResult:
        """The stop / slowdown / yield rules against the scan points (module docstring)."""
        cfg = self.config
        pose = np.asarray(pose, dtype=np.float64).reshape(-1)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise EcahdError(f"pose must be 3 finite numbers (x, y, yaw), got {pose.tolist()}")
        if not (math.isfinite(v) and math.isfinite(w)):
            raise EcahdError(f"velocity command must be finite, got v={v!r}, w={w!r}")
        if points_stamp is None:
            return MonitorResult(0.0, 0.0, "stop", 0.0, "no obstacle data received yet")
        age = now - points_stamp
        if cfg.source_timeout > 0 and age > cfg.source_timeout:
            return MonitorResult(0.0, 0.0, "stop", 0.0,
                                 f"obstacle data is {age:.2f} s old (> source_timeout "
                                 f"{cfg.source_timeout} s)")
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)  # (M, 2)
        vel = np.zeros_like(pts) if velocities is None else \
            np.asarray(velocities, dtype=np.float64).reshape(-1, 2)  # (M, 2) [m/s]
        if vel.shape != pts.shape:
            raise EcahdError(f"velocities must be (M, 2) like the points {pts.shape}, got "
                             f"{vel.shape}")
        ok = np.isfinite(pts).all(axis=1)
        if bounds is not None:
            bounds = np.asarray(bounds, dtype=np.float64).reshape(-1, 2)
            if bounds.shape != pts.shape:
                raise EcahdError(f"bounds must be (M, 2) like the points {pts.shape}, got "
                                 f"{bounds.shape}")
            bounds = np.where(np.isnan(bounds[ok]), [-np.inf, np.inf], bounds[ok])
        pts, vel = pts[ok], np.where(np.isfinite(vel[ok]), vel[ok], 0.0)
        speed = np.hypot(vel[:, 0], vel[:, 1])  # (M,)
        # keep only the points that can reach the footprint within the horizons
        horizon = max(cfg.time_to_collision, cfg.yield_horizon if speed.any() else 0.0)
        reach = self._reach_static + (abs(v) + speed) * horizon  # (M,)
        near = np.sum((pts - pose[:2]) ** 2, axis=1) <= reach * reach
        pts, vel = pts[near], vel[near]  # (M', 2)
        if bounds is not None:
            bounds = bounds[near]
            if not np.isfinite(bounds).all(axis=1).any():
                bounds = None
        if len(pts) < cfg.min_points:
            return MonitorResult(float(v), float(w), "none", math.inf, "no obstacle in reach")
        moving = bool(np.any(vel))

        clearance = self._clearance(pose, v, w, pts, vel, bounds)  # (K+1, M') [m]
        stop_step = self._first_step(clearance, cfg.stop_margin)
        beat = None if bounds is None or cfg.beat_horizon == 0 or stop_step is not None \
            or (v == 0.0 and w == 0.0) else self._beat_step(pose, v, w, pts, vel, bounds)
        if stop_step is not None or beat is not None:
            if stop_step is not None:
                ttc = float(self._t[stop_step])
                reason = (f"{self._count(clearance[stop_step], cfg.stop_margin)} point(s) "
                          f"within {cfg.stop_margin} m of the footprint in {ttc:.2f} s")
            else:
                ttc = float(self._t_beat[beat])
                reason = (f"a mover going back and forth comes within {cfg.stop_margin} m of "
                          f"the footprint in {ttc:.2f} s: not starting across its beat")
            if moving:
                escape = self._yield(pose, pts, vel, bounds, depths)
                if escape is not None:
                    return MonitorResult(escape[0], escape[1], "yield", ttc,
                                         f"{reason}; a moving obstacle would hit the stopped "
                                         f"robot: {escape[2]}")
            return MonitorResult(0.0, 0.0, "stop", ttc, reason)
        if moving and v == 0.0 and w == 0.0:  # a stopped robot: is something coming at it?
            escape = self._yield(pose, pts, vel, bounds, depths)
            if escape is not None:
                return MonitorResult(escape[0], escape[1], "yield", math.inf,
                                     f"a moving obstacle would hit the stopped robot: "
                                     f"{escape[2]}")
        # slowing down near something that moves does not help (it may be coming from behind,
        # and is judged by its prediction above): only static points slow the robot
        still = ~vel.any(axis=1)  # (M',)
        slow_step = self._first_step(clearance[:, still], cfg.slowdown_margin)
        if slow_step is None:
            return MonitorResult(float(v), float(w), "none", math.inf, "clear")
        # slowdown, then check the slowed command again. Its poses lie on the same arc between
        # the simulated ones, where no footprint point is farther than
        # (|v| + |w| R_circumscribed) sim_dt from a simulated pose's: only points within that
        # much of the stop margin at some step can stop the slowed command.
        ratio = self.slowdown_ratio_at(float(clearance[:, still].min()))
        if cfg.slowdown_limits is None:
            v_slow, w_slow = v * ratio, w * ratio
        else:  # a cap: |v_slow| <= |v| and |w_slow| <= |w| as for the ratio
            cap_v, cap_w = (ratio * float(m) for m in cfg.slowdown_limits)
            v_slow, w_slow = float(np.clip(v, -cap_v, cap_v)), float(np.clip(w, -cap_w, cap_w))
        step = (abs(v) + abs(w) * self.footprint.circumscribed_radius) * cfg.sim_dt  # [m]
        # (a moving point is where it is at a time, not on the arc: every one is re-checked)
        candidates = (clearance.min(axis=0) <= cfg.stop_margin + step) | ~still  # (M',)
        slowed = self._clearance(pose, v_slow, w_slow, pts[candidates], vel[candidates],
                                 None if bounds is None else bounds[candidates])
        restop = self._first_step(slowed, cfg.stop_margin)
        if restop is not None:
            reason = (f"the slowed command still comes within {cfg.stop_margin} m in "
                      f"{float(self._t[restop]):.2f} s")
            if moving:
                escape = self._yield(pose, pts, vel, bounds, depths)
                if escape is not None:
                    return MonitorResult(escape[0], escape[1], "yield", math.inf,
                                         f"{reason}; a moving obstacle would hit the stopped "
                                         f"robot: {escape[2]}")
            return MonitorResult(0.0, 0.0, "stop", math.inf, reason)
        return MonitorResult(float(v_slow), float(w_slow), "slowdown", math.inf,
                             f"point(s) within {cfg.slowdown_margin} m of the footprint in "
                             f"{float(self._t[slow_step]):.2f} s: speed x "
                             f"{ratio:.2f}"
                             + ("" if cfg.slowdown_limits is None else " of the limits"))

    def slowdown_ratio_at(self, clearance: float) -> float:
        """The slowdown's speed ratio for the static points' least clearance [m] to the
        footprint over the horizon (``slowdown_profile``)."""
        cfg = self.config
        if cfg.slowdown_profile == "step":
            return cfg.slowdown_ratio
        span = cfg.slowdown_margin - cfg.stop_margin
        frac = 1.0 if span <= 0 else min(max((clearance - cfg.stop_margin) / span, 0.0), 1.0)
        return cfg.slowdown_ratio + (1.0 - cfg.slowdown_ratio) * frac

    # ------------------------------------------------------------------------------- yield
    def _beat_step(self, pose: np.ndarray, v: float, w: float, pts: np.ndarray,
                   vel: np.ndarray, bounds: np.ndarray) -> int | None:
        """First step (of beat_horizon's) at which the command, held, meets a point that goes
        back and forth (finite bounds), or None."""
        shuttling = np.isfinite(bounds).all(axis=1) & vel.any(axis=1)  # (M,)
        t = self._t_beat
        clearance = self._clearance_at(self.simulate(pose, v, w, t), pts[shuttling],
                                       vel[shuttling], t, bounds=bounds[shuttling])
        return self._first_step(clearance, self.config.stop_margin)

    def _yield(self, pose: np.ndarray, pts: np.ndarray, vel: np.ndarray, bounds, depths
               ) -> tuple[float, float, str] | None:
        """An escape command (v, w, why) when the stopped robot would be hit by a moving point
        within yield_horizon and a command does better; None: stopping is as good.
        pts, vel: (M, 2) points [m] and velocities [m/s]; bounds: (M, 2) [m] or None (see
        :meth:`filter`).

        Each escape command drives until just before its first pose that goes into the
        static map (``depths``; deeper than now when the robot already touches it) and waits
        there (the monitor re-judges every tick, so it never drives into the map); one that
        cannot move a single step is dropped. Commands are ranked by, in order: fewer steps
        within stop_margin of a point, the first such step later, more clearance at the
        horizon's end (away from what comes); it must beat standing still."""
        cfg = self.config
        if cfg.escape_limits is None or depths is None:
            return None
        t = self._t_yield  # (Ky+1,)
        # only touching matters here (and the clearance left at the end, a tie-breaker): a
        # point farther than a stop margin + 0.1 m from the circumscribed circle is "far"
        reach = self.footprint.circumscribed_radius + cfg.stop_margin + 0.1  # [m]
        standing = self._clearance_at(np.tile(pose, (len(t), 1)), pts, vel, t,
                                      reach=reach, bounds=bounds)  # (Ky+1, M)
        stand_hit = self._first_step(standing, cfg.stop_margin)
        if stand_hit is None:
            return None
        max_v, max_w = (float(m) for m in cfg.escape_limits)
        commands = [(fv * max_v, fw * max_w) for fv in _ESCAPE_V for fw in _ESCAPE_W
                    if (fv, fw) != (0.0, 0.0)]
        poses = np.stack([self.simulate(pose, cv, cw, t) for cv, cw in commands])  # (C, Ky+1, 3)
        d = np.asarray(depths(np.concatenate([pose[None], poses.reshape(-1, 3)])),
                       dtype=np.float64)
        clear = (d[1:] <= max(float(d[0]), DEFAULT_TOLERANCE)).reshape(len(commands), -1)
        moving = vel.any(axis=1)  # (M,)
        ahead = (pts + predicted_offsets(vel, bounds, t[-1:])[0])[moving]  # (m, 2) [m] where
        #   the moving points will be

        def away(xy: np.ndarray) -> float:  # [m] from the nearest of them at the horizon
            return float(np.min(np.hypot(*(ahead - xy).T), initial=math.inf))

        best, best_key = None, self._escape_key(standing, False, away(pose[:2]))
        # each command drives until its first refused step and waits there
        blocked = ~clear  # (C, Ky+1)
        stop_at = np.where(blocked.any(axis=1), np.argmax(blocked, axis=1), len(t))  # (C,)
        movable = np.flatnonzero(stop_at >= 2)
        if len(movable) == 0:
            self._last_yield = None
            return None
        steps = np.minimum(np.arange(len(t))[None, :], stop_at[movable, None] - 1)
        driven = poses[movable[:, None], steps]  # (C', Ky+1, 3)
        clearance = self._clearance_at(driven.reshape(-1, 3), pts, vel, np.tile(t, len(movable)),
                                       reach=reach, bounds=bounds
                                       ).reshape(len(movable), len(t), -1)
        for j, i in enumerate(movable):  # (C', Ky+1, M) ranked one by one
            key = self._escape_key(clearance[j], commands[i] == self._last_yield,
                                   away(driven[j, -1, :2]))
            if key > best_key:
                best, best_key = i, key
        if best is None:
            self._last_yield = None
            return None
        cv, cw = commands[best]
        self._last_yield = (cv, cw)
        touched = -best_key[0]
        return cv, cw, (f"escape v={cv:.2f} m/s, w={cw:.2f} rad/s (touched in {touched} of "
                        f"{len(t)} steps; standing: from {float(t[stand_hit]):.2f} s)")

    def _escape_key(self, clearance: np.ndarray, previous: bool, away: float
                    ) -> tuple[int, int, bool, float]:
        """Rank of an escape's (Ky+1, M) clearance: (-touched steps, first touched step (Ky+1
        if none), ``previous`` (the command of the last yield: kept on a tie, so the robot
        does not dither between two escapes as the obstacle moves), ``away`` [m] (how far
        its last pose is from the moving points' predicted positions then)); larger is
        better."""
        touched = np.count_nonzero(clearance <= self.config.stop_margin, axis=1) \
            >= self.config.min_points  # (Ky+1,)
        first = int(np.argmax(touched)) if touched.any() else len(touched)
        return -int(touched.sum()), first, previous, away

    # ---------------------------------------------------------------------------- geometry
    def simulate(self, pose, v: float, w: float, t: np.ndarray | None = None) -> np.ndarray:
        """(K+1, 3) poses x [m], y [m], yaw [rad] of the unicycle at (v, w) at times t (K+1,)
        [s] (default 0, sim_dt, ..., K sim_dt; exact arcs; straight when |w| is tiny)."""
        x0, y0, yaw0 = (float(c) for c in pose)
        t = self._t if t is None else t  # (K+1,)
        yaw = yaw0 + w * t
        if abs(w) < _STRAIGHT_W:
            x = x0 + v * t * math.cos(yaw0)
            y = y0 + v * t * math.sin(yaw0)
        else:
            x = x0 + v / w * (np.sin(yaw) - math.sin(yaw0))
            y = y0 - v / w * (np.cos(yaw) - math.cos(yaw0))
        return np.stack([x, y, yaw], axis=-1)

    def _clearance(self, pose, v: float, w: float, pts: np.ndarray, vel: np.ndarray | None = None,
                   bounds: np.ndarray | None = None, t: np.ndarray | None = None) -> np.ndarray:
        """(K+1, M) distance [m] from each point to the footprint at each simulated pose, 0
        inside it. For a polygon, ``inf`` where the point is farther than slowdown_margin from
        the circumscribed circle (too far to matter, not computed). pts: (M, 2) world points,
        vel: (M, 2) [m/s] their velocities (None: static), bounds: (M, 2) [m] where they turn
        round (None: never), t: (K+1,) [s] step times."""
        t = self._t if t is None else t
        return self._clearance_at(self.simulate(pose, v, w, t), pts, vel, t, bounds=bounds)

    def _clearance_at(self, poses: np.ndarray, pts: np.ndarray, vel: np.ndarray | None,
                      t: np.ndarray, reach: float | None = None,
                      bounds: np.ndarray | None = None) -> np.ndarray:
        """:meth:`_clearance` for given poses (K+1, 3) at step times t (K+1,) [s]. A moving
        point's clearance shrinks by ``prediction_growth`` t: where it will be is uncertain.
        For a polygon, points farther than ``reach`` [m] (default circumscribed radius +
        slowdown_margin) from a pose's centre are not computed (inf)."""
        moving = None if vel is None or not np.any(vel) else vel.any(axis=1)  # (M,)
        clearance = self._clearance_of(poses, pts, vel if moving is not None else None, t,
                                       self._reach_static if reach is None else reach, bounds)
        if moving is not None and self.config.prediction_growth > 0:
            # (K+1, 1) [m]; capped at the stop horizon: beyond it the estimate only decides
            # whether to yield, and a growing margin there made the robot yield for minutes
            grow = self.config.prediction_growth * np.minimum(t, self.config.time_to_collision
                                                              )[:, None]
            clearance[:, moving] = np.maximum(clearance[:, moving] - grow, 0.0)
        return clearance

    def _clearance_of(self, poses: np.ndarray, pts: np.ndarray, vel: np.ndarray | None,
                      t: np.ndarray, reach: float, bounds: np.ndarray | None = None
                      ) -> np.ndarray:
        c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]  # (K+1, 1)
        dx = pts[None, :, 0] - poses[:, 0:1]  # (K+1, M)
        dy = pts[None, :, 1] - poses[:, 1:2]
        if vel is not None:  # a moving point is at p + v t at step time t (folded: bounds)
            disp = predicted_offsets(vel, bounds, t)  # (K+1, M, 2)
            dx = dx + disp[..., 0]
            dy = dy + disp[..., 1]
        if self.footprint.radius is not None:
            return np.maximum(np.hypot(dx, dy) - self.footprint.radius, 0.0)
        clearance = np.full(dx.shape, np.inf)
        near = dx * dx + dy * dy <= reach * reach  # (K+1, M)
        if not near.any():
            return clearance
        cs, sn = np.broadcast_to(c, near.shape)[near], np.broadcast_to(s, near.shape)[near]
        dxn, dyn = dx[near], dy[near]  # (S,) the (step, point) pairs that can matter
        lx, ly = cs * dxn + sn * dyn, cs * dyn - sn * dxn  # (S,) robot-frame coordinates
        clearance[near] = self._polygon_clearance(lx, ly)
        return clearance

    def _polygon_clearance(self, lx: np.ndarray, ly: np.ndarray) -> np.ndarray:
        """(S,) robot-frame points -> (S,) distance [m] to the footprint polygon, 0 inside
        (even-odd rule, exact distance to the nearest edge)."""
        ax, ay = self._a[:, 0], self._a[:, 1]  # (V,) edge starts
        ex, ey = self._ab[:, 0], self._ab[:, 1]  # (V,) edge vectors
        px, py = lx[:, None] - ax, ly[:, None] - ay  # (S, V) from each edge start
        u = np.clip((px * ex + py * ey) / self._ab_len2, 0.0, 1.0)
        dist = np.sqrt(np.min((px - u * ex) ** 2 + (py - u * ey) ** 2, axis=-1))  # (S,)
        # even-odd rule: edge v crosses the horizontal line through the point (ay > ly) !=
        # (by > ly), to the right of it (lx < ax + py ex / ey); multiplied out by ey (!= 0
        # where the edge crosses) so nothing is divided
        crosses = (py < 0) != (py < ey)  # (S, V)
        right = np.where(ey > 0, px * ey < py * ex, px * ey > py * ex)  # (S, V)
        inside = np.count_nonzero(crosses & right, axis=-1) % 2 == 1
        return np.where(inside, 0.0, dist)

    def _first_step(self, clearance: np.ndarray, margin: float) -> int | None:
        """First step k at which >= min_points points lie within ``margin`` [m], or None.
        clearance: (K+1, M)."""
        hits = np.count_nonzero(clearance <= margin, axis=1) >= self.config.min_points  # (K+1,)
        return int(np.argmax(hits)) if hits.any() else None

    @staticmethod
    def _count(clearance_row: np.ndarray, margin: float) -> int:
        return int(np.count_nonzero(clearance_row <= margin))

