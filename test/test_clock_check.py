"""Inputs stamped by another clock, or late, are said in one line naming the cause and the fix,
at most once per period per input (ecahd_ros.clock_check; no rclpy)."""
from ecahd_ros.clock_check import TIME_BASE_GAP, StampCheck


class FakeMonotonic:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def test_sim_stamps_on_a_wall_clock_node_name_use_sim_time():
    clock = FakeMonotonic()
    check = StampCheck(use_sim_time=False, period=5.0, monotonic=clock)
    wall = 1.8e9  # a wall clock reading [s]
    line = check.check("scan", 42.0, wall, 0.5)  # a simulator's stamp
    assert line is not None and line.startswith("scan stamps are")
    assert "behind" in line and "another time base" in line and "use_sim_time:=true" in line
    assert "a simulator's /clock" in line
    assert check.check("scan", 42.1, wall, 0.5) is None  # said once per period
    assert check.check("odometry", 42.1, wall, 0.5) is not None  # another input: said too
    clock.t = 5.0
    assert check.check("scan", 43.0, wall, 0.5) is not None  # the period is over
    assert check.mismatches == 4 and check.stale == 0


def test_wall_stamps_on_a_sim_time_node_and_late_or_fine_ones():
    check = StampCheck(use_sim_time=True, monotonic=FakeMonotonic())
    line = check.check("odometry", 1.8e9, 12.0, 0.5)
    assert "ahead of" in line and "the wall clock" in line and "sim time" in line
    assert check.check("scan", 10.0, 10.3, 0.5) is None  # within the tolerance
    late = check.check("scan", 10.0, 11.2, 0.5)
    assert late.startswith("scan is 1.20 s old") and "0.5 s tolerance" in late
    assert check.check("map", 10.0, 10.0 - 0.9 * TIME_BASE_GAP, 0.5).startswith(
        "map is")  # far in the future, but within one time base: late, not another clock
    assert check.stale == 2 and check.mismatches == 1
