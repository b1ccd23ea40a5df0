"""The nodes' health on ``/diagnostics`` (diagnostic_msgs/DiagnosticArray), as ROS tools read it
(``rqt_robot_monitor``, the diagnostic aggregator, Foxglove): one DiagnosticStatus per node,
named ``ecahd_ros: <node>``, with a level (OK, WARN, ERROR), a one-line message and key-values
(model, map age, latencies p50 / p99, rates, counts), published every DIAGNOSTICS_PERIOD s.

:class:`Latencies` keeps the last WINDOW samples of a latency and :class:`RateMeter` the times
of the last events (a control loop's rate); both are plain Python, testable without ROS."""
from __future__ import annotations

import math
import time
from collections import deque

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

DIAGNOSTICS_PERIOD = 1.0  # [s] between two /diagnostics messages of a node
WINDOW = 200  # latencies kept for the quantiles
LEVELS = {"ok": DiagnosticStatus.OK, "warn": DiagnosticStatus.WARN,
          "error": DiagnosticStatus.ERROR, "stale": DiagnosticStatus.STALE}


class Latencies:
    """The last ``window`` latencies [ms] and their p50 / p99."""

    def __init__(self, window: int = WINDOW) -> None:
        self._ms: deque[float] = deque(maxlen=window)

    def add(self, ms: float) -> None:
        self._ms.append(float(ms))

    def __len__(self) -> int:
        return len(self._ms)

    def quantile(self, q: float) -> float:
        """The ``q`` (0..1) quantile [ms] by the nearest rank; NaN with no sample."""
        if not self._ms:
            return math.nan
        ordered = sorted(self._ms)
        return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


class RateMeter:
    """Events per second over the last ``span`` seconds of ``clock`` (monotonic by default)."""

    def __init__(self, span: float = 2.0, clock=time.monotonic) -> None:
        self.span, self.clock = float(span), clock
        self._times: deque[float] = deque()

    def tick(self) -> None:
        self._times.append(self.clock())

    def rate(self) -> float:
        """[Hz] events in the last ``span`` s over the time they span (0 with fewer than 2)."""
        now = self.clock()
        while self._times and now - self._times[0] > self.span:
            self._times.popleft()
        if len(self._times) < 2:
            return 0.0
        return (len(self._times) - 1) / max(self._times[-1] - self._times[0], 1e-9)


def _text(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.4g}"
    return str(value)


def node_status(node: str, level: str, message: str, values: dict) -> DiagnosticStatus:
    """The DiagnosticStatus ``ecahd_ros: <node>`` (``level``: one of LEVELS) with ``values``
    as key-values (floats to 4 significant digits)."""
    status = DiagnosticStatus()
    status.level = LEVELS[level]
    status.name = f"ecahd_ros: {node}"
    status.message = message
    status.hardware_id = node
    status.values = [KeyValue(key=str(k), value=_text(v)) for k, v in values.items()]
    return status


def diagnostic_array(statuses: list[DiagnosticStatus], stamp) -> DiagnosticArray:
    """``statuses`` stamped ``stamp`` (builtin_interfaces/Time)."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = list(statuses)
    return msg
