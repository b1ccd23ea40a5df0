"""Tests of the unmapped obstacles' velocity estimate (ecahd_core.tracking).

Scans are ray-cast by hand here (circles and axis-aligned boxes, analytically): 360 beams
around a sensor, 10 Hz.
"""
import numpy as np
import pytest

from ecahd_core.errors import EcahdError
from ecahd_core.tracking import MotionTracker, TrackerConfig, align, clusters
from conftest import ray_cast

ANGLES = np.linspace(-np.pi, np.pi, 360, endpoint=False)


def cast(sensor, circles=(), boxes=(), noise=0.0, rng=None) -> np.ndarray:
    """World points (M, 2) of the returns of rays from ``sensor`` (2,) against circles
    (cx, cy, r) and boxes (xmin, ymin, xmax, ymax), in beam order; ranges + N(0, noise)."""
    sensor = np.asarray(sensor, dtype=float)
    d = np.stack([np.cos(ANGLES), np.sin(ANGLES)], 1)  # (N, 2)
    r = ray_cast(sensor, ANGLES, circles, boxes)
    if noise:
        r = r + rng.normal(0.0, noise, r.shape)
    ok = np.isfinite(r)
    return sensor + r[ok, None] * d[ok]


def test_clusters_split_at_gaps_and_close_the_circle():
    pts = np.array([[0.0, 0.0], [0.1, 0.0], [1.0, 0.0], [1.1, 0.0], [0.05, 0.05]])
    # gaps: 0.1 | 0.9 (break) | 0.1 | 1.05 (break); last to first 0.07 < 0.3: the circle closes
    assert clusters(pts, 0.3).tolist() == [0, 0, 1, 1, 0]
    assert clusters(np.zeros((0, 2)), 0.3).tolist() == []


def test_align_recovers_a_shift_finer_than_the_points_and_keeps_a_static_corner():
    # an arc of a 0.2 m cylinder sampled every 5 cm, moved by (0.07, -0.03): point-to-segment
    # matching resolves the 2-3 cm that nearest points alone would round off
    a = np.linspace(-1.2, 1.2, 10)
    arc = np.stack([0.2 * np.cos(a), 0.2 * np.sin(a)], axis=1)  # (10, 2) in beam order
    t, rms = align(arc + [0.07, -0.03], arc, np.zeros(2), trim=0.7, iterations=8, gap=0.3)
    assert rms < 0.005
    assert t == pytest.approx([0.07, -0.03], abs=0.01)
    # a box corner seen first on one face, 0.3 s later also on 3 returns of the other (the
    # robot drove on): the centroid moves by ~0.06 m, the faces do not -> the shift aligned
    # from standing still is ~0 (the trimmed matches drop the new face's returns); from the
    # centroid guess it slides along the face (not observable there) with the same residual
    face = np.stack([np.full(9, 1.0), np.linspace(0.0, 0.4, 9)], axis=1)  # x = 1, y 0..0.4
    side = np.stack([np.linspace(1.05, 1.15, 3), np.full(3, 0.0)], axis=1)  # y = 0, x > 1
    later = np.concatenate([face, side])
    guess = later.mean(axis=0) - face.mean(axis=0)
    assert np.hypot(*guess) > 0.05
    still, still_rms = align(later, face, np.zeros(2), trim=0.7, iterations=4, gap=0.3)
    slid, slid_rms = align(later, face, guess, trim=0.7, iterations=4, gap=0.3)
    assert np.hypot(*still) < 0.01 and still_rms < 0.01
    assert slid_rms > still_rms - 0.003  # no better than still: MotionTracker keeps still


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_a_crossing_cylinder_moves_and_a_box_passed_by_stays(noise):
    # the robot drives +x at 0.5 m/s past a box 0.6 m to its left (the faces it sees change,
    # so the visible points' centroid moves); a cylinder 3 m ahead crosses +y at 0.4 m/s
    rng = np.random.default_rng(1)
    tracker = MotionTracker()
    box = (1.5, 0.6, 1.9, 1.2)
    for k in range(25):
        t = 0.1 * k
        cyl = (3.0, -1.5 + 0.4 * t, 0.2)
        pts = cast((0.5 * t, 0.0), [cyl], [box], noise, rng)
        vel = tracker.update(pts, t)
        if k < 3:  # no scan 0.3 s old yet: nothing is known to move
            assert not vel.any()
            continue
        on_cyl = np.hypot(pts[:, 0] - cyl[0], pts[:, 1] - cyl[1]) < 0.25
        assert vel[on_cyl].mean(axis=0) == pytest.approx([0.0, 0.4], abs=0.1), t
        assert np.abs(vel[~on_cyl]).max() == 0.0, t


def test_a_new_object_has_no_velocity_and_time_going_back_resets():
    tracker = MotionTracker()
    assert not tracker.update(cast((0, 0), [(2.0, 0.0, 0.2)]), 0.0).any()
    # 0.3 s later an object appears far from anything seen before: unknown, not moving
    assert not tracker.update(cast((0, 0), [(-2.0, 0.0, 0.2)]), 0.3).any()
    assert not tracker.update(cast((0, 0), [(-2.0, 0.5, 0.2)]), 0.1).any()  # clock went back


def test_config_is_checked():
    with pytest.raises(EcahdError, match="max_baseline"):
        TrackerConfig(baseline=0.5, max_baseline=0.2)
    with pytest.raises(EcahdError, match="trim"):
        TrackerConfig(trim=1.5)
    with pytest.raises(EcahdError, match="stamp"):
        MotionTracker().update(np.zeros((1, 2)), float("nan"))
