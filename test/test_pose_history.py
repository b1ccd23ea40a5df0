"""Odometry poses by stamp for placing scans (ecahd_core.sensing.PoseHistory)."""
import math

import pytest

from ecahd_core.sensing import PoseHistory


def test_poses_are_interpolated_by_stamp_and_yaw_the_short_way():
    h = PoseHistory(horizon=1.0)
    assert h.at(0.0) is None and not h.covers(0.0) and h.newest is None
    h.add(1.0, (0.0, 0.0, math.pi - 0.1))
    h.add(1.1, (1.0, 2.0, -math.pi + 0.1))  # turned 0.2 rad through +-pi
    assert h.covers(1.05) and not h.covers(1.2) and h.newest == 1.1
    x, y, yaw = h.at(1.05)
    assert (x, y) == pytest.approx((0.5, 1.0)) and abs(abs(yaw) - math.pi) < 1e-9
    assert h.at(0.5) == pytest.approx((0.0, 0.0, math.pi - 0.1))  # before: the oldest
    assert h.at(2.0) == pytest.approx((1.0, 2.0, -math.pi + 0.1))  # after: the newest


def test_old_poses_leave_and_a_clock_that_goes_back_resets():
    h = PoseHistory(horizon=0.5)
    for k in range(20):
        h.add(0.1 * k, (0.1 * k, 0.0, 0.0))
    assert h.at(0.0) == pytest.approx((1.4, 0.0, 0.0))  # only the last 0.5 s kept
    h.add(0.05, (5.0, 5.0, 0.0))  # a restarted sim clock
    assert h.newest == 0.05 and h.at(1.9) == pytest.approx((5.0, 5.0, 0.0))
