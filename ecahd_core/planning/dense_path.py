"""A whole dense path from a start to a goal, collision-checked: ECAHD's Algorithm 1 offline (SD
re-planned at every waypoint, DD guided by J per segment, the exact rule) and then the safety
net (``ecahd_core.safety``: a plan the exact checker finds in collision is repaired or replaced,
and never returned as safe). What Nav2's ComputePathToPose asks of a planner plugin, and what
``ecahd plan --method ecahd`` draws.

Paths are (M, 2) [m] in the map's frame.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ecahd_core.errors import PlanningError


@dataclass(frozen=True)
class DensePath:
    """Result of :meth:`DensePathPlanner.plan`.

    Attributes:
        path: (M, 2) [m] start to goal (as the exact checker judged it).
        safe: the exact checker finds ``path`` collision-free (False: do not follow it).
        rule: the safety net's last rule ("none" when Algorithm 1's plan was already free).
        reason: why the path is unsafe ("" otherwise).
        ms: wall time of the whole call.
    """

    path: np.ndarray
    safe: bool
    rule: str
    reason: str
    ms: float


class DensePathPlanner:
    """Algorithm 1 (``HierarchicalPlanner``) plus the safety net on one map.

    Args:
        hd: a HierarchicalPlanner (``HierarchicalPlanner.for_map``).
        net: a SafetyNet on the same map and footprint.
    """

    def __init__(self, hd, net) -> None:
        self.hd, self.net = hd, net

    @classmethod
    def for_map(cls, grid, footprint, sd, *, dd_model: str | None = None,
                padding: float = 0.0, learnt=None) -> "DensePathPlanner":
        """On ``grid`` for ``footprint`` over ``sd`` (a SparseDiffusion for the map, its cost J
        set): the map's DD model (``dd_model``: a path; None: the shipped one; CheckpointError
        when there is none; ``learnt``: the site's map the model learnt when ``grid`` is an
        update of it) and the net with A*'s ``padding`` [m]."""
        from ecahd_core.planning.hierarchical import HierarchicalPlanner
        from ecahd_core.safety import SafetyNet, SafetyNetConfig

        if sd.cost is None:
            raise PlanningError("a dense path needs SD with its collision cost J")
        hd = HierarchicalPlanner.for_map(grid, footprint, sd, model=dd_model, learnt=learnt)
        return cls(hd, SafetyNet(grid, footprint, SafetyNetConfig(padding=padding), planner=hd))

    @property
    def grid(self):
        return self.net.grid

    def plan(self, start, goal, *, generator=None) -> DensePath:
        """``start``, ``goal`` (2,) [m] on the map and free (PlanningError otherwise) -> a
        DensePath."""
        t0 = time.perf_counter()
        start = self.grid.validate_point(start, "start")
        goal = self.grid.validate_point(goal, "goal")
        plan = self.hd.plan(start, goal, generator=generator)
        safe = self.net.apply(plan.trajectory, segments=plan.segments, generator=generator)
        path = np.asarray(safe.path, dtype=np.float64)  # judged as it is: ends not moved
        return DensePath(path=path, safe=safe.safe, rule=safe.rule, reason=safe.reason,
                         ms=(time.perf_counter() - t0) * 1e3)
