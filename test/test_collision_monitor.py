"""Tests of the stop / slowdown velocity filter (ecahd_core.collision_monitor).

Common setup unless a test says otherwise: a 0.4 m x 0.4 m square robot (front edge at
x = +0.2 m, sides at y = +-0.2 m) at the origin facing +x, default settings: horizon 1.0 s in
0.1 s steps, stop within 0.02 m, slow down within 0.3 m (x 0.3 with the "step" profile; x 0.3 at
0.02 m rising to x 1 at 0.3 m with the default "linear" one), points fresh.
"""
import math

import numpy as np
import pytest

from ecahd_core.collision_monitor import (ACTIONS, CollisionMonitor, CollisionMonitorConfig,
                                         MonitorResult)
from ecahd_core.errors import EcahdError
from ecahd_core.footprint import make_footprint, polygon_footprint

SQUARE = polygon_footprint([[0.2, 0.2], [-0.2, 0.2], [-0.2, -0.2], [0.2, -0.2]])
ORIGIN = (0.0, 0.0, 0.0)


def box_face(x: float) -> np.ndarray:
    """(9, 2) points of a box face across the robot's path at x [m], y in [-0.2, 0.2]."""
    return np.stack([np.full(9, x), np.linspace(-0.2, 0.2, 9)], axis=1)


def wall_along_x(y: float) -> np.ndarray:
    """(31, 2) points of a wall parallel to the robot's path at y [m], x in [-1, 2]."""
    return np.stack([np.linspace(-1.0, 2.0, 31), np.full(31, y)], axis=1)


def run(points, v, w=0.0, *, pose=ORIGIN, footprint=SQUARE, stamp=0.0, now=0.0, **config):
    monitor = CollisionMonitor(footprint, CollisionMonitorConfig(**config))
    return monitor.filter(pose, v, w, points, stamp, now)


def test_stops_before_a_box_half_a_metre_ahead():
    # box face at x = 0.7: 0.5 m in front of the front edge. At 0.5 m/s the gap after t seconds
    # is 0.5 - 0.5 t: 0.05 m at t = 0.9 (> stop margin 0.02), 0 at t = 1.0 -> stop, ttc 1.0 s
    result = run(box_face(0.7), 0.5)
    assert (result.v, result.w, result.action) == (0.0, 0.0, "stop")
    assert result.min_time_to_collision == pytest.approx(1.0)


def test_slows_down_within_the_margin():
    # at 0.4 m/s the gap 0.5 - 0.4 t never falls under 0.02 m within 1 s (0.1 m at t = 1), but
    # it is <= 0.3 m from t = 0.5 s on -> slowdown to 0.3 x (0.4, 0.2) = (0.12, 0.06) (step)
    result = run(box_face(0.7), 0.4, 0.2, slowdown_profile="step")
    assert result.action == "slowdown"
    assert (result.v, result.w) == pytest.approx((0.12, 0.06))
    assert result.min_time_to_collision == math.inf


def test_linear_slowdown_grows_with_the_least_clearance():
    # the same box, driving straight: the least gap over the horizon is 0.1 m (t = 1), 0.08 /
    # 0.28 of the way from the stop margin to the slowdown margin -> ratio 0.3 + 0.7 * 0.08 /
    # 0.28 = 0.5
    result = run(box_face(0.7), 0.4)
    assert result.action == "slowdown"
    assert (result.v, result.w) == pytest.approx((0.2, 0.0))
    # beside a wall: 0.25 m from the side -> 0.3 + 0.7 * 0.23 / 0.28 = 0.875; 0.05 m -> 0.375;
    # the step profile gives 0.3 for both
    for y, ratio in ((0.45, 0.875), (0.25, 0.375)):
        assert run(wall_along_x(y), 0.4).v == pytest.approx(0.4 * ratio)
        assert run(wall_along_x(y), 0.4, slowdown_profile="step").v == pytest.approx(0.12)
    # a cap (slowdown_limits) follows the same ratio of the limits; the stop rule is unchanged
    monitor = CollisionMonitor(SQUARE, CollisionMonitorConfig(slowdown_limits=(0.5, 1.5)))
    assert monitor.filter(ORIGIN, 0.5, 0.0, wall_along_x(0.25), 0.0, 0.0).v == \
        pytest.approx(0.5 * 0.375)
    assert run(box_face(0.7), 0.5).action == "stop"
    assert monitor.slowdown_ratio_at(0.0) == pytest.approx(0.3)
    assert monitor.slowdown_ratio_at(1.0) == 1.0
    with pytest.raises(EcahdError, match="slowdown_profile"):
        CollisionMonitorConfig(slowdown_profile="smooth")


def test_slowdown_with_limits_caps_the_command_and_a_ramp_keeps_its_speed():
    cfg = CollisionMonitorConfig(slowdown_limits=(0.5, 1.5), slowdown_profile="step")
    # cap 0.15 m/s, 0.45 rad/s
    monitor = CollisionMonitor(SQUARE, cfg)
    result = monitor.filter(ORIGIN, 0.4, 0.2, box_face(0.7), 0.0, 0.0)
    assert result.action == "slowdown"
    assert (result.v, result.w) == pytest.approx((0.15, 0.2))
    # beside a wall 0.25 m from the side (slow down, never stop), a controller that ramps from
    # the command sent (+0.05 m/s per tick) settles at the cap; scaling by the ratio every
    # tick decays to 0.3 * 0.05 / 0.7 = 0.021 m/s
    for scaled in (False, True):
        m = CollisionMonitor(SQUARE, CollisionMonitorConfig(slowdown_profile="step")
                             if scaled else cfg)
        v = 0.4
        for _ in range(50):
            v = m.filter(ORIGIN, min(0.5, v + 0.05), 0.0, wall_along_x(0.45), 0.0, 0.0).v
        assert v == pytest.approx(0.3 * 0.05 / 0.7 if scaled else 0.15, abs=1e-3)
    with pytest.raises(EcahdError, match="slowdown_limits"):
        CollisionMonitorConfig(slowdown_limits=(0.5,))


def test_driving_away_and_parallel_pass():
    # reversing away from the box: the gap grows -> unchanged
    result = run(box_face(0.7), -0.5)
    assert (result.v, result.w, result.action) == (-0.5, 0.0, "none")
    # a wall 0.6 m beside the centre line is 0.6 - 0.2 = 0.4 m from the side edge, outside the
    # 0.3 m slowdown margin -> unchanged
    assert run(wall_along_x(0.6), 0.5).action == "none"
    # a wall 0.45 m from the centre line is 0.25 m from the side: slow down, never stop
    result = run(wall_along_x(-0.45), 0.5, slowdown_profile="step")
    assert result.action == "slowdown" and result.v == pytest.approx(0.15)


def test_reverse_motion_stops_before_a_box_behind():
    # box face at x = -0.7, 0.5 m behind the rear edge: reversing at 0.5 m/s closes the gap
    # exactly as driving forward does in the first test; driving forward is fine
    result = run(box_face(-0.7), -0.5)
    assert result.action == "stop" and result.min_time_to_collision == pytest.approx(1.0)
    assert run(box_face(-0.7), 0.5).action == "none"


def test_turning_follows_the_arc():
    # robot at (1, 1) facing +y, turning left at w = pi/2 rad/s with v = pi/4 m/s: a quarter
    # circle of radius v / w = 0.5 m around (0.5, 1), ending at (0.5, 1.5) facing -x after 1 s.
    # A box just beyond that end, at x = 0.5 - 0.2 (front edge), stops it late in the horizon;
    # straight ahead (+y) the same command clears a box at (1, 1.8).
    pose = (1.0, 1.0, math.pi / 2)
    monitor = CollisionMonitor(SQUARE)
    poses = monitor.simulate(pose, math.pi / 4, math.pi / 2)
    assert poses.shape == (11, 3)
    np.testing.assert_allclose(poses[-1], [0.5, 1.5, math.pi], atol=1e-12)
    on_arc = np.array([[0.5 - 0.21, 1.5]])
    result = monitor.filter(pose, math.pi / 4, math.pi / 2, on_arc, 0.0, 0.0)
    assert result.action == "stop" and 0.5 < result.min_time_to_collision <= 1.0
    straight_ahead = np.array([[1.0, 1.8]])
    assert monitor.filter(pose, math.pi / 4, math.pi / 2, straight_ahead, 0.0, 0.0).action != "stop"


def test_rotation_in_place_next_to_an_obstacle_stops():
    # a 0.65 m x 0.30 m robot (quadruped preset) with a point 0.3 m to its left: 0.15 m from the
    # side now, but turning sweeps the corners out to hypot(0.325, 0.15) = 0.358 m > 0.3 m, so
    # the point ends up inside -> stop (Nav2's semantics: rotation is not let through)
    quadruped = make_footprint("quadruped")
    result = run(np.array([[0.0, 0.3]]), 0.0, 1.0, footprint=quadruped)
    assert result.action == "stop" and result.w == 0.0


def test_circle_footprint_uses_its_exact_radius():
    # circle of radius 0.4 m, point 0.9 m ahead: gap 0.5 - 0.5 t -> stop at t = 1.0 s; at
    # 0.25 m/s the gap ends at 0.25 m: slow down
    circle = make_footprint("circle")
    result = run(np.array([[0.9, 0.0]]), 0.5, footprint=circle)
    assert result.action == "stop" and result.min_time_to_collision == pytest.approx(1.0)
    assert run(np.array([[0.9, 0.0]]), 0.25, footprint=circle).action == "slowdown"


def test_a_point_inside_the_footprint_stops_any_command():
    result = run(np.array([[0.1, 0.0]]), -0.5)
    assert result.action == "stop" and result.min_time_to_collision == 0.0


def test_stale_or_missing_data_stops():
    # points measured at t = 0, now t = 3 s > source_timeout 2 s -> stop, as Nav2 does
    result = run(box_face(5.0), 0.5, stamp=0.0, now=3.0)
    assert (result.action, result.v, result.min_time_to_collision) == ("stop", 0.0, 0.0)
    assert "old" in result.reason
    assert run(box_face(5.0), 0.5, stamp=None).action == "stop"
    # source_timeout = 0 disables the check
    assert run(box_face(5.0), 0.5, stamp=0.0, now=3.0, source_timeout=0.0).action == "none"


def test_nan_points_are_ignored_and_min_points_counts():
    pts = np.vstack([box_face(0.7), [[math.nan, 0.0], [0.3, math.nan]]])
    assert run(pts, 0.5).action == "stop"
    assert run(np.full((5, 2), math.nan), 0.5).action == "none"
    assert run(np.empty((0, 2)), 0.5).action == "none"
    # one point in the way is not enough when min_points = 2
    assert run(np.array([[0.7, 0.0]]), 0.5, min_points=2).action == "none"


def test_config_is_validated():
    with pytest.raises(EcahdError, match="slowdown_ratio"):
        CollisionMonitorConfig(slowdown_ratio=0.0)
    with pytest.raises(EcahdError, match="stop_margin"):
        CollisionMonitorConfig(stop_margin=0.5, slowdown_margin=0.3)
    with pytest.raises(EcahdError, match="min_points"):
        CollisionMonitorConfig(min_points=0)
    assert CollisionMonitorConfig(time_to_collision=1.0, sim_dt=0.1).steps == 10
    with pytest.raises(EcahdError, match="velocity"):
        run(box_face(0.7), math.nan)


@pytest.mark.parametrize("robot", ["circle", "quadruped"])
def test_filter_speed_is_reported(robot):
    # ``ecahd bench monitor``'s figures for the filter (360 points on a ring 0.9 m away, all
    # within reach, 10 steps), on a small static map: each figure is there, finite and > 0, and
    # the derived ones are the quotients of the times they come from, in the result and in the
    # printed table; no bound on the times themselves (they depend on the machine)
    from ecahd_core.bench.monitor import (FILTER_BUDGET_MS, MonitorBenchSettings, format_table,
                                          run_monitor_benchmark)

    settings = MonitorBenchSettings(footprint=robot, map_cells=200, window=1.8, repeats=20,
                                    reference_repeats=1, warmup=2)
    result = run_monitor_benchmark(settings)
    t = result.filter
    assert t.calls == 20 and t.budget_ms == FILTER_BUDGET_MS
    for value in (t.p50_ms, t.p99_ms, t.reference_ms):
        assert math.isfinite(value) and value > 0
    assert t.p50_ms <= t.p99_ms
    assert t.budget_ratio == pytest.approx(t.p99_ms / FILTER_BUDGET_MS, rel=1e-12)
    assert t.speedup == pytest.approx(t.reference_ms / t.p50_ms, rel=1e-12)
    assert result.steps == 10 and result.footprint_vertices == len(make_footprint(robot).polygon)
    as_json = result.to_dict()["filter"]
    assert as_json["speedup"] == t.speedup and as_json["budget_ratio"] == t.budget_ratio
    # the table's filter row prints these very figures
    row = next(line for line in format_table(result).splitlines()
               if line.startswith("CollisionMonitor.filter"))
    p50, p99, budget, ratio, ref, speed = row.split()[1:]
    assert (float(p50), float(p99), float(budget)) == pytest.approx(
        (t.p50_ms, t.p99_ms, FILTER_BUDGET_MS), abs=6e-4)
    assert float(ratio) == pytest.approx(t.budget_ratio, abs=6e-3)
    assert float(ref) == pytest.approx(t.reference_ms, abs=6e-3)
    assert speed.endswith("x") and float(speed[:-1]) == pytest.approx(t.speedup, abs=0.06)
    # and the filter measured is one that acts on the ring (the ring is within reach)
    ring = 0.9 * np.stack([np.cos(np.linspace(-math.pi, math.pi, 360, endpoint=False)),
                           np.sin(np.linspace(-math.pi, math.pi, 360, endpoint=False))], axis=1)
    action = CollisionMonitor(make_footprint(robot)).filter(ORIGIN, 0.5, 0.3, ring, 0.0, 0.0)
    assert action.action in ACTIONS and action.action != "none"


def test_monitor_benchmark_small(tmp_path, capsys):
    # ``ecahd bench monitor`` on a 200 x 200 map with a 60-cell window: the JSON has every
    # timing, the table names the three measurements; no assertion on the times themselves
    import argparse
    import json

    from ecahd_core.commands import bench

    parser = argparse.ArgumentParser(prog="ecahd bench")
    bench.add_arguments(parser)
    out = tmp_path / "monitor.json"
    args = parser.parse_args(["monitor", "--map-cells", "200", "--window", "1.8", "--points", "90",
                              "--repeats", "5", "--reference-repeats", "1", "--json", str(out)])
    assert bench.run(args) == 0
    result = json.loads(out.read_text())
    assert (result["window_cells"], result["map_cells"], result["steps"]) == (60, 200, 10)
    for name in ("filter", "static", "yield_", "track", "update", "fused"):
        t = result[name]
        assert 0 < t["p50_ms"] <= t["p99_ms"]
        assert t["budget_ratio"] == pytest.approx(t["p99_ms"] / t["budget_ms"])
    assert result["filter"]["speedup"] > 0 and result["update"]["speedup"] is None
    printed = capsys.readouterr().out
    assert "CollisionMonitor.filter" in printed and "update + fused_costmap" in printed


# ------------------------------------------------------------------ moving obstacles, yielding
CIRCLE = make_footprint("circle")  # radius 0.4 m


def cylinder_arc(cx: float, cy: float, r: float = 0.2, n: int = 9) -> np.ndarray:
    """(n, 2) points on the half of a cylinder (centre cx, cy, radius r) facing the origin."""
    facing = math.atan2(-cy, -cx)
    a = facing + np.linspace(-math.pi / 2, math.pi / 2, n)
    return np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)


def open_floor(poses: np.ndarray) -> np.ndarray:
    """Static-map depths (N,) of poses (N, 3): nothing anywhere."""
    return np.full(len(poses), -np.inf)


def yielding(**config) -> CollisionMonitor:
    """Trusting the predictions (prediction_growth 0) unless a test says otherwise."""
    config = {"prediction_growth": 0.0, **config}
    return CollisionMonitor(CIRCLE, CollisionMonitorConfig(escape_limits=(0.5, 1.5), **config))


def test_a_cylinder_coming_at_a_stopped_robot_makes_it_back_off_where_the_map_allows():
    # cylinder (r 0.2) centred 1.0 m left of the robot, coming at it at 0.4 m/s: the stopped
    # robot (r 0.4) is touched when the gap 1.0 - 0.6 - 0.4 t reaches 0.02 m, at t ~ 0.95 s
    pts = cylinder_arc(0.0, 1.0)
    vel = np.tile([0.0, -0.4], (len(pts), 1))
    result = yielding().filter(ORIGIN, 0.0, 0.0, pts, 0.0, 0.0, velocities=vel,
                               depths=open_floor)
    assert result.action == "yield" and abs(result.v) > 0
    assert "standing: from 1.00 s" in result.reason  # first 0.1 s step with gap <= 0.02 m
    # a wall behind (x < 0 is in the static map, as deep as it is negative): forward
    no_reverse = lambda poses: np.where(poses[:, 0] >= 0, -np.inf, -poses[:, 0])  # noqa: E731
    forward = yielding().filter(ORIGIN, 0.0, 0.0, pts, 0.0, 0.0, velocities=vel,
                                depths=no_reverse)
    assert forward.action == "yield" and forward.v > 0
    # boxed in (every move refused): stop, as without yielding
    boxed = lambda poses: np.hypot(poses[:, 0], poses[:, 1])  # noqa: E731
    stuck = yielding().filter(ORIGIN, 0.0, 0.0, pts, 0.0, 0.0, velocities=vel, depths=boxed)
    assert (stuck.v, stuck.w) == (0.0, 0.0)


def test_no_yield_without_limits_or_map_check_or_for_static_points():
    pts = cylinder_arc(0.0, 1.0)
    vel = np.tile([0.0, -0.4], (len(pts), 1))
    plain = CollisionMonitor(CIRCLE)  # escape_limits None: Nav2's stop
    assert plain.filter(ORIGIN, 0.0, 0.0, pts, 0.0, 0.0, velocities=vel,
                        depths=open_floor).action != "yield"
    assert yielding().filter(ORIGIN, 0.0, 0.0, pts, 0.0, 0.0, velocities=vel).action != "yield"
    # the same points standing still: nothing comes at the robot
    still = yielding().filter(ORIGIN, 0.0, 0.0, pts, 0.0, 0.0, depths=open_floor)
    assert still.action == "none"


def test_a_crossing_cylinder_stops_a_robot_whose_path_it_will_cross():
    # the robot drives +x at 0.5 m/s; a cylinder (r 0.2) at (0.8, -0.8) crosses towards +y at
    # 0.5 m/s. Static, it never comes closer than 0.25 m within 1 s (robot at (0.5, 0): 0.854 -
    # 0.6): a slowdown at most. Predicted, the centres are sqrt(2) (0.8 - 0.5 t) apart, within
    # 0.6 + 0.02 m from t = 0.72 s: stop
    pts = cylinder_arc(0.8, -0.8)
    vel = np.tile([0.0, 0.5], (len(pts), 1))
    monitor = CollisionMonitor(CIRCLE, CollisionMonitorConfig(prediction_growth=0.0))
    assert monitor.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0).action != "stop"
    predicted = monitor.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel)
    assert predicted.action == "stop"
    assert predicted.min_time_to_collision == pytest.approx(0.8)  # first 0.1 s step >= 0.72
    # with the prediction's uncertainty (0.15 m/s: the clearance at t shrinks by 0.15 t) the
    # gap sqrt(2) (0.8 - 0.5 t) - 0.6 - 0.15 t reaches 0.02 m earlier: at t = 0.511 / 0.857 =
    # 0.596 s, the step at 0.6 s
    uncertain = CollisionMonitor(CIRCLE, CollisionMonitorConfig(prediction_growth=0.15))
    early = uncertain.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel)
    assert early.min_time_to_collision == pytest.approx(0.6)


def test_velocities_must_match_the_points():
    with pytest.raises(EcahdError, match="velocities"):
        yielding().filter(ORIGIN, 0.0, 0.0, cylinder_arc(0.0, 1.0), 0.0, 0.0,
                          velocities=np.zeros((2, 2)))


def test_a_cylinder_keeping_pace_beside_the_robot_does_not_slow_it_down():
    # a cylinder 0.85 m to the left (0.25 m from the footprint, inside the 0.3 m slowdown
    # margin) moving +x with the robot at 0.5 m/s: static, it slows the robot; moving, slowing
    # would only let it drift ahead, and it never comes closer: the command passes
    pts = cylinder_arc(0.0, 0.85)
    monitor = CollisionMonitor(CIRCLE)
    assert monitor.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0).action == "slowdown"
    vel = np.tile([0.5, 0.0], (len(pts), 1))
    assert monitor.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel).action == "none"


def test_a_command_into_the_static_map_turns_the_robot_on_the_spot_instead():
    # a wall across the path at x = 0.5 (depth: how far the circle's front, x + 0.4, passes
    # it). At 0.5 m/s with w = 0.3 the front reaches the wall within 0.5 s (0.25 m covered,
    # 0.1 m of space): refused; turning on the spot keeps x and passes; no scan points at all
    wall = lambda poses: np.where(poses[:, 0] + 0.4 > 0.5, poses[:, 0] - 0.1, -np.inf)  # noqa
    off = CollisionMonitor(CIRCLE)  # static_horizon 0 by default: not checked
    assert off.filter(ORIGIN, 0.5, 0.3, np.zeros((0, 2)), 0.0, 0.0, depths=wall).action == \
        "none"
    monitor = CollisionMonitor(CIRCLE, CollisionMonitorConfig(static_horizon=0.5))
    result = monitor.filter(ORIGIN, 0.5, 0.3, np.zeros((0, 2)), 0.0, 0.0, depths=wall)
    assert (result.v, result.w, result.action) == (0.0, 0.3, "stop")
    assert "static map" in result.reason
    # slower, it stays clear within the horizon (0.1 m/s: 0.05 m in 0.5 s): passes
    slow = monitor.filter(ORIGIN, 0.1, 0.3, np.zeros((0, 2)), 0.0, 0.0, depths=wall)
    assert (slow.v, slow.w, slow.action) == (0.1, 0.3, "none")
    # already 0.05 m into the map (a pose within the clearance margin): backing out passes,
    # going deeper does not
    inside = (0.15, 0.0, 0.0)
    assert monitor.filter(inside, -0.2, 0.0, np.zeros((0, 2)), 0.0, 0.0,
                          depths=wall).action == "none"
    deeper = monitor.filter(inside, 0.2, 0.0, np.zeros((0, 2)), 0.0, 0.0, depths=wall)
    assert (deeper.v, deeper.w) == (0.0, 0.0)


def test_the_static_check_does_not_pass_a_thin_obstacle_between_two_samples():
    # a post the footprint touches only while x lies in (0.215, 0.235): at 0.5 m/s held for
    # 0.5 s, samples sim_dt (0.1 s) apart land at x = 0, 0.05, ..., 0.25 and miss it; the
    # static check samples every STATIC_STEP (1 cm) of travel and refuses the command
    from ecahd_core.collision_monitor import STATIC_STEP

    assert STATIC_STEP <= 0.01
    post = lambda poses: np.where(np.abs(poses[:, 0] - 0.225) < 0.01, 0.002, -np.inf)  # noqa
    monitor = CollisionMonitor(CIRCLE)
    result = monitor.keep_off_map(ORIGIN, MonitorResult(0.5, 0.0, "none", math.inf, ""), post,
                                  horizon=0.5)
    assert (result.v, result.w, result.action) == (0.0, 0.0, "stop")
    # beyond the horizon's reach (0.25 m) it does not matter
    far = lambda poses: np.where(np.abs(poses[:, 0] - 0.3) < 0.01, 0.002, -np.inf)  # noqa
    assert monitor.keep_off_map(ORIGIN, MonitorResult(0.5, 0.0, "none", math.inf, ""), far,
                                horizon=0.5).action == "none"


def test_predicted_offsets_fold_a_shuttling_point_back_and_forth():
    from ecahd_core.collision_monitor import predicted_offsets

    vel = np.array([[0.5, 0.0], [0.0, -0.5], [0.5, 0.0]])
    # point 0 turns 0.5 m ahead and 0.25 m behind; point 1 has no known turn; point 2 none
    bounds = np.array([[-0.25, 0.5], [-np.inf, np.inf], [-np.inf, np.inf]])
    t = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0])
    disp = predicted_offsets(vel, bounds, t)  # (T, 3, 2)
    # 0 -> 0.25 -> 0.5 (turns) -> 0.25 -> 0 -> -0.25 (turns) -> 0: period 2 * 0.75 / 0.5 = 3 s
    assert disp[:, 0, 0] == pytest.approx([0.0, 0.25, 0.5, 0.25, 0.0, -0.25, 0.0])
    assert np.all(disp[:, 0, 1] == 0.0)
    assert disp[:, 1, 1] == pytest.approx(-0.5 * t)  # straight on
    assert disp[:, 2, 0] == pytest.approx(0.5 * t)
    assert np.array_equal(predicted_offsets(vel, None, t), t[:, None, None] * vel[None])


def test_a_robot_does_not_start_across_the_beat_of_a_cylinder_going_back_and_forth():
    # a cylinder (r 0.2) shuttles across the robot's way 1.2 m ahead, between y = -0.9 and
    # y = 0.9, at 0.5 m/s; now it is at y = 0.6 going away (+y). Straight on, it would never
    # come back: the robot (r 0.4, +x at 0.5 m/s) goes. Known to turn round 0.3 m ahead, it is
    # back in the robot's way in about 1.5 s, before the robot (in the way from ~1.2 s to
    # ~3.2 s) is through: the robot waits. Standing, the robot is never touched: no yield.
    pts = cylinder_arc(1.2, 0.6)
    vel = np.tile([0.0, 0.5], (len(pts), 1))
    monitor = yielding()
    straight = monitor.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel,
                              depths=open_floor)
    assert straight.action == "none"
    # along +y: the centre (0.6) turns at 0.9 (0.3 m ahead) and at -0.9 (1.5 m behind)
    bounds = np.tile([-1.5, 0.3], (len(pts), 1))
    # without the beat rule (the default) the folded prediction alone lets it go: within the
    # 1 s stop horizon the cylinder does not come back
    assert monitor.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel, bounds=bounds,
                          depths=open_floor).action == "none"
    monitor = yielding(beat_horizon=3.0)
    beat = monitor.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel, bounds=bounds,
                          depths=open_floor)
    assert beat.action == "stop" and "back and forth" in beat.reason
    assert 1.0 < beat.min_time_to_collision < 3.0
    # standing still is allowed (nothing reaches the robot where it is)
    assert monitor.filter(ORIGIN, 0.0, 0.0, pts, 0.0, 0.0, velocities=vel, bounds=bounds,
                          depths=open_floor).action == "none"
    with pytest.raises(EcahdError, match="bounds"):
        monitor.filter(ORIGIN, 0.5, 0.0, pts, 0.0, 0.0, velocities=vel, bounds=bounds[:2])
