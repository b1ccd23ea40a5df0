"""LatestWorker: long callbacks off the executor thread, the newest item wins."""
import threading
import time

from ecahd_core.worker import LatestWorker


def test_runs_items_in_order_and_drops_those_a_newer_one_replaced():
    seen, gate = [], threading.Event()

    def work(item):
        gate.wait(5.0)
        seen.append(item)

    w = LatestWorker(work, name="t", on_error=lambda exc: None)
    w.submit(1)  # starts at once and waits on the gate
    time.sleep(0.05)
    for k in (2, 3, 4):  # handed over while 1 blocks the worker: only the newest survives
        w.submit(k)
    assert not w.idle
    gate.set()
    assert w.wait_idle(5.0)
    assert seen == [1, 4] and w.dropped == 2 and w.done == 2
    w.close()


def test_an_error_is_reported_and_the_worker_goes_on():
    errors, seen = [], []

    def work(item):
        if item == "bad":
            raise ValueError("bad item")
        seen.append(item)

    w = LatestWorker(work, name="t", on_error=errors.append)
    w.submit("bad")
    assert w.wait_idle(5.0)
    w.submit("good")
    assert w.wait_idle(5.0)
    assert [str(e) for e in errors] == ["bad item"] and seen == ["good"]
    w.close()
    w.submit("after close")  # ignored
    time.sleep(0.05)
    assert seen == ["good"]

