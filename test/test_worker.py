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



def _own_nice():
    import os

    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())


def test_worker_threads_run_at_a_lower_priority_than_the_caller():
    """nice: the worker's thread (and only it) yields the CPU to the node's timers."""
    import pytest

    from ecahd_core.errors import EcahdError
    from ecahd_core.planning.local import LocalRunner, LocalRunnerConfig
    from ecahd_core.threads import lower_priority

    before = _own_nice()
    seen = []
    worker = LatestWorker(lambda item: seen.append(_own_nice()), name="niced",
                          on_error=lambda exc: None, nice=3)
    worker.submit(1)
    assert worker.wait_idle(5.0)
    worker.close()
    runner = LocalRunner(LocalRunnerConfig(), worker_nice=2)
    job = runner._submit(_own_nice)
    assert seen == [min(19, before + 3)] and job.result(5.0) == min(19, before + 2)
    assert _own_nice() == before  # the calling thread keeps its priority

    result = []
    t = threading.Thread(target=lambda: result.append((lower_priority(4), _own_nice())))
    t.start()
    t.join()
    assert result == [(min(19, before + 4), min(19, before + 4))]
    assert lower_priority(0) is None and _own_nice() == before
    for bad in (-1, 20, 1.5, True):
        with pytest.raises(EcahdError, match="nice increment"):
            lower_priority(bad)
