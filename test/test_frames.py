"""TransformBuffer (ecahd_core.frames) against hand-computed chains: REP-105's map -> odom ->
base_link -> base_scan, interpolation, latest common time, extrapolation and tolerance, and the
errors that name unknown frames, loops and second parents."""
import math

import numpy as np
import pytest

from ecahd_core.frames import ExtrapolationError, FrameError, Transform, TransformBuffer


def robot_buffer():
    """map -> odom: (1, 2) turned 90 deg (a localisation correction), stamped 10 s and 12 s
    (the second moved 1 m along map x); odom -> base_link: (1, 0) at 10 s, (3, 0) at 12 s;
    base_link -> base_scan: static, 0.2 m ahead and 0.3 m up, turned 180 deg."""
    tf = TransformBuffer()
    tf.set_transform("map", "odom", 10.0, Transform.from_xy_yaw(1.0, 2.0, math.pi / 2))
    tf.set_transform("map", "odom", 12.0, Transform.from_xy_yaw(2.0, 2.0, math.pi / 2))
    tf.set_transform("odom", "base_link", 10.0, Transform.from_xy_yaw(1.0, 0.0, 0.0))
    tf.set_transform("odom", "base_link", 12.0, Transform.from_xy_yaw(3.0, 0.0, 0.0))
    tf.set_transform("base_link", "base_scan", 0.0,
                     Transform.from_xy_yaw(0.2, 0.0, math.pi, z=0.3), static=True)
    return tf


def test_the_robots_pose_in_map_composes_the_chain():
    tf = robot_buffer()
    # at 10 s: odom's x axis is map's y axis, so base_link at odom (1, 0) is map (1, 2 + 1)
    x, y, yaw = tf.lookup("map", "base_link", 10.0).xy_yaw()
    assert (x, y, yaw) == pytest.approx((1.0, 3.0, math.pi / 2))
    # at 11 s both links are halfway: map -> odom (1.5, 2), odom -> base_link (2, 0)
    assert tf.lookup("map", "base_link", 11.0).xy_yaw() == pytest.approx((1.5, 4.0, math.pi / 2))
    # the scan 0.2 m ahead of base_link (along map y) and 0.3 m up, facing backwards
    scan = tf.lookup("map", "base_scan", 10.0)
    assert scan.translation == pytest.approx([1.0, 3.2, 0.3])
    assert scan.yaw() == pytest.approx(-math.pi / 2)
    # a point 1 m ahead of the scanner lies 0.8 m behind base_link: map (1, 3 - 0.8)
    assert scan.apply(np.array([[1.0, 0.0]]))[0] == pytest.approx([1.0, 2.2])
    # the inverse lookup undoes it
    back = tf.lookup("base_scan", "map", 10.0)
    assert back.apply(scan.apply(np.array([[0.3, -0.7, 0.1]])))[0] == pytest.approx(
        [0.3, -0.7, 0.1])


def test_latest_common_time_and_lookups_between_branches():
    tf = robot_buffer()
    tf.set_transform("odom", "base_link", 13.0, Transform.from_xy_yaw(4.0, 0.0, 0.0))
    # map -> odom is known up to 12 s only: the chain's latest common time
    assert tf.latest_common_time("map", "base_link") == 12.0
    assert tf.lookup("map", "base_link").xy_yaw() == pytest.approx((2.0, 5.0, math.pi / 2))
    assert tf.latest_common_time("base_link", "base_scan") == math.inf  # static only
    # siblings under odom: odom -> base_link and odom -> wheel
    tf.set_transform("odom", "wheel", 12.0, Transform.from_xy_yaw(3.0, 1.0, 0.0))
    assert tf.lookup("base_link", "wheel", 12.0).xy_yaw() == pytest.approx((0.0, 1.0, 0.0))


def test_extrapolation_is_an_error_unless_within_the_tolerance():
    tf = robot_buffer()
    with pytest.raises(ExtrapolationError, match=r"-> base_link is known up to 12.000 s; 12.500 s"
                                                  r" is 0.500 s into the future"):
        tf.lookup("map", "base_link", 12.5)
    # Nav2's transform_tolerance: up to 0.6 s after the newest, the newest is used
    assert tf.lookup("map", "base_link", 12.5, tolerance=0.6).xy_yaw() == pytest.approx(
        (2.0, 5.0, math.pi / 2))
    with pytest.raises(ExtrapolationError, match="before it"):
        tf.lookup("map", "base_link", 9.0)


def test_old_transforms_leave_the_cache():
    tf = TransformBuffer(cache_time=2.0)
    for t in range(10):
        tf.set_transform("odom", "base_link", float(t), Transform.from_xy_yaw(t, 0.0, 0.0))
    assert tf.lookup("odom", "base_link", 7.5).xy_yaw()[0] == pytest.approx(7.5)
    with pytest.raises(ExtrapolationError):
        tf.lookup("odom", "base_link", 6.5)  # older than 2 s before the newest (9 s)


def test_unknown_frames_loops_and_second_parents_are_named():
    tf = robot_buffer()
    with pytest.raises(FrameError, match="source frame 'laser' is unknown"):
        tf.lookup("map", "laser", 10.0)
    tf.set_transform("world", "elsewhere", 10.0, Transform.identity())
    with pytest.raises(FrameError, match="not connected"):
        tf.lookup("map", "elsewhere", 10.0)
    with pytest.raises(FrameError, match="close a loop"):
        tf.set_transform("base_scan", "map", 10.0, Transform.identity())
    with pytest.raises(FrameError, match="two"):
        tf.set_transform("map", "base_link", 10.0, Transform.identity())
    with pytest.raises(FrameError, match="not valid"):
        tf.set_transform("/map", "x", 10.0, Transform.identity())
    with pytest.raises(FrameError, match="not a unit quaternion"):
        Transform.checked([0, 0, 0], [0, 0, 0, 2])
    with pytest.raises(FrameError, match="not finite"):
        Transform.checked([math.nan, 0, 0], [0, 0, 0, 1])


def test_slerp_takes_the_shorter_way_round():
    tf = TransformBuffer()
    tf.set_transform("odom", "base_link", 0.0, Transform.from_xy_yaw(0, 0, math.radians(170)))
    tf.set_transform("odom", "base_link", 1.0, Transform.from_xy_yaw(0, 0, math.radians(-170)))
    # halfway between 170 and -170 deg is 180 deg, not 0
    assert abs(tf.lookup("odom", "base_link", 0.5).yaw()) == pytest.approx(math.pi)


def test_a_pose_in_odom_is_placed_in_map():
    tf = robot_buffer()
    # odom's (1, 0) facing +x is map's (1, 2 + 1) facing +y at 10 s (map -> odom: (1, 2), 90 deg)
    assert tf.pose_in("map", "odom", 10.0, (1.0, 0.0, 0.0)) == pytest.approx(
        (1.0, 3.0, math.pi / 2))
    assert tf.pose_in("odom", "odom", None, (0.5, -0.5, 0.1)) == pytest.approx((0.5, -0.5, 0.1))
