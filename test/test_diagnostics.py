"""The pieces of the nodes' /diagnostics: latency quantiles, a loop's rate, the status message
(ecahd_ros.diagnostics)."""
import math

from diagnostic_msgs.msg import DiagnosticStatus

from ecahd_ros.diagnostics import Latencies, RateMeter, node_status


def test_latency_quantiles_by_nearest_rank_over_the_window():
    lat = Latencies(window=100)
    assert math.isnan(lat.quantile(0.5)) and len(lat) == 0
    for ms in range(1, 201):  # 1..200 ms; the window keeps 101..200
        lat.add(ms)
    assert len(lat) == 100
    assert lat.quantile(0.5) == 150  # the 50th of 101..200
    assert lat.quantile(0.99) == 199 and lat.quantile(1.0) == 200


def test_rate_meter_counts_the_last_span():
    t = [0.0]
    meter = RateMeter(span=2.0, clock=lambda: t[0])
    assert meter.rate() == 0.0
    for _ in range(41):  # 20 Hz for 2 s
        meter.tick()
        t[0] += 0.05
    assert math.isclose(meter.rate(), 20.0, rel_tol=1e-6)
    t[0] += 10.0  # the loop stopped: nothing in the last span
    assert meter.rate() == 0.0


def test_node_status_names_the_node_and_formats_its_values():
    status = node_status("local_refiner", "warn", "waiting for a map",
                         {"map_age_s": math.nan, "control_ms_p99": 4.56789, "scans": 3})
    assert status.level == DiagnosticStatus.WARN and status.name == "ecahd_ros: local_refiner"
    assert status.hardware_id == "local_refiner" and status.message == "waiting for a map"
    assert {kv.key: kv.value for kv in status.values} == {
        "map_age_s": "nan", "control_ms_p99": "4.568", "scans": "3"}
