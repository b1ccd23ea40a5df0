"""Inputs whose stamps disagree with the node's clock, said out loud (issue 39, "time that does
not agree").

A node run without ``use_sim_time`` beside a simulator that stamps its messages with its own
``/clock`` (sim_bridge) reads every scan as decades old: the collision monitor then stops the
robot for good, and nothing said why. :class:`StampCheck` compares an input's stamp with the
node's clock and returns one line naming the problem, its likely cause and the fix, at most once
every ``period`` seconds per input, so a node can log it without flooding. No rclpy here: the
caller passes both times in seconds.
"""
from __future__ import annotations

import time

# [s] stamps this far from the node's clock come from another time base (a simulator's /clock
# against the wall clock: 1.8e9 s apart today), not from a late message
TIME_BASE_GAP = 1e5
WARN_PERIOD = 5.0  # [s, monotonic] at most one line per input this often


class StampCheck:
    """Checks inputs' stamps against the node's clock.

    Args:
        use_sim_time: whether the node runs on ``/clock`` (its ``use_sim_time`` parameter).
        period: [s] the least time between two lines about the same input.
        monotonic: () -> s, the rate limit's clock (a fake one in tests).
    """

    def __init__(self, use_sim_time: bool, *, period: float = WARN_PERIOD,
                 monotonic=time.monotonic) -> None:
        self.use_sim_time = bool(use_sim_time)
        self.period = float(period)
        self.monotonic = monotonic
        self._last: dict[str, float] = {}  # input -> when its last line was given
        self.mismatches = 0  # stamps found from another time base
        self.stale = 0  # stamps found older than their tolerance

    def check(self, what: str, stamp: float, now: float, tolerance: float) -> str | None:
        """One line about ``what`` (e.g. "scan") stamped ``stamp`` [s] when the node's clock
        reads ``now`` [s], or None: its stamp is within ``tolerance`` [s] of the clock, or a line
        about it was given less than ``period`` ago (the counts still grow)."""
        gap = now - stamp
        clock = "sim time, /clock" if self.use_sim_time else "wall time"
        if abs(gap) > TIME_BASE_GAP:
            self.mismatches += 1
            other = "the wall clock" if self.use_sim_time else "a simulator's /clock"
            fix = ("run every node on the same clock: all with `--ros-args -p use_sim_time:=true` "
                   "beside a simulator that publishes /clock (sim_bridge), none on a real robot")
            line = (f"{what} stamps are {abs(gap):.3g} s {'behind' if gap > 0 else 'ahead of'} "
                    f"this node's clock ({clock}): they come from another time base, most likely "
                    f"{other}; {fix}")
        elif abs(gap) > tolerance:
            self.stale += 1
            line = (f"{what} is {abs(gap):.2f} s {'old' if gap > 0 else 'in the future'} by this "
                    f"node's clock ({clock}), beyond its {tolerance:g} s tolerance: is its "
                    f"publisher running and keeping up, and are the computers' clocks synchronised "
                    f"(chrony or NTP)?")
        else:
            return None
        t = self.monotonic()
        if t - self._last.get(what, -float("inf")) < self.period:
            return None
        self._last[what] = t
        return line
