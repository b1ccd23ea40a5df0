"""A worker thread for a node's long callbacks (no rclpy).

A ROS 2 node here spins one executor thread (ecahd_ros.spin: rclpy's MultiThreadedExecutor
busy-waits and starves the control timer), so a callback that takes long (a map of 2000 x 2000
cells: cost map, clearance, model; a scan fused into the cost map of such a map: ~75 ms) delays
every timer behind it. :class:`LatestWorker` moves such work to its own thread: the callback
only hands the message over and returns; the worker runs the work on the newest message,
dropping older ones that waited (a newer map or scan makes them moot). numpy and torch release
the GIL while they compute, so the executor's timers keep their rate.
"""
from __future__ import annotations

import threading
from typing import Any, Callable


class LatestWorker:
    """Runs ``fn(item)`` on a daemon thread for the latest item handed to :meth:`submit`.

    Args:
        fn: the work; called on the worker thread, one item at a time.
        name: the thread's name.
        on_error: called with any exception ``fn`` raises (the worker goes on).
        nice: the worker thread's nice value is raised by this much (``threads.lower_priority``)
            so that its work yields the CPU to the node's timers; 0 leaves it.
    Attributes:
        dropped: items replaced by a newer one before their turn.
        done: items ``fn`` finished (raised or not).
    """

    _STOP = object()

    def __init__(self, fn: Callable[[Any], None], *, name: str,
                 on_error: Callable[[BaseException], None], nice: int = 0) -> None:
        self.fn, self.on_error, self.nice = fn, on_error, nice
        self.dropped = self.done = 0
        self._cond = threading.Condition()
        self._item: Any = None
        self._has_item = self._busy = False
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, item: Any) -> None:
        """Hand ``item`` over (replacing one still waiting); never blocks on the work."""
        with self._cond:
            if self._closed:
                return
            if self._has_item:
                self.dropped += 1
            self._item, self._has_item = item, True
            self._cond.notify_all()

    @property
    def idle(self) -> bool:
        """Nothing waiting and nothing running."""
        with self._cond:
            return not (self._has_item or self._busy)

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Block until :attr:`idle` (True) or ``timeout`` s passed (False)."""
        with self._cond:
            return self._cond.wait_for(lambda: not (self._has_item or self._busy), timeout)

    def close(self, timeout: float = 5.0) -> None:
        """Stop after the running item (a waiting one is dropped); join the thread."""
        with self._cond:
            self._closed = True
            self._item, self._has_item = None, False
            self._cond.notify_all()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def _run(self) -> None:
        from ecahd_core.threads import lower_priority

        lower_priority(self.nice)
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._has_item or self._closed)
                if self._closed:
                    return
                item, self._item, self._has_item = self._item, None, False
                self._busy = True
            try:
                self.fn(item)
            except BaseException as exc:  # noqa: BLE001 - reported, the worker goes on
                try:
                    self.on_error(exc)
                except BaseException:  # noqa: BLE001 - a failing reporter must not kill it
                    pass
            finally:
                with self._cond:
                    self._busy = False
                    self.done += 1
                    self._cond.notify_all()
