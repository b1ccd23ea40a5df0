"""``ecahd bench control``: a local_refiner process on the wall clock is timed tick by tick
(structure only; no timing assertions)."""
import math

import pytest

pytest.importorskip("rclpy")


@pytest.mark.slow
def test_a_short_run_times_every_tick(ros_domain_id):
    from ecahd_ros.bench_control import run_once

    r = run_once(dd_enabled=False, seconds=2.0, rate=20.0, domain=ros_domain_id)
    assert r.ticks >= 10 and r.dd_runs == 0  # ~40 ticks at 20 Hz
    for value in (r.interval_p50, r.interval_p99, r.jitter_p99, r.tick_p99):
        assert math.isfinite(value) and value >= 0
    assert r.interval_p50 <= r.interval_p99 <= r.interval_max
    assert r.distance > 0  # the fake robot followed the commands


def test_bench_control_is_an_ecahd_bench():
    from ecahd_ros.cli import build_parser

    args = build_parser().parse_args(["bench", "control", "--seconds", "3", "--rate", "10"])
    assert (args.seconds, args.rate) == (3.0, 10.0)
