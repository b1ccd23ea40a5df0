"""How many waypoints each re-plan of Algorithm 1 keeps (paper Sec. III-A, lines 2-11: the
global plan t^g_p shrinks by one waypoint per iteration, P^g - p), and our replan spacing that
keeps a waypoint per few metres left to the goal on building maps. Shared by the offline
planner (:mod:`ecahd_core.planning.hierarchical`) and the online runner
(:mod:`ecahd_core.planning.online`)."""
from __future__ import annotations

import math

import numpy as np

from ecahd_core.errors import EcahdError

REPLAN_POLICIES = ("every_waypoint", "once")
REPLAN_SPACING = 3.0  # [m] the least replan spacing chosen on a big map (auto_replan_spacing)
# every_waypoint with SparseConfig.max_spacing or a replan spacing: iterations beyond P^g - 1
# before the last SD plan is followed to the goal whole (rules.SparseStage)
MAX_EXTRA_ITERATIONS = 30
SNAP_DISTANCE = 0.2  # [m] a goal in collision moves at most this far (< waypoint_tolerance)


def auto_replan_spacing(grid, expert_spacing: float | None = None, *,
                        general: bool = False) -> float | None:
    """[m] the replan spacing (:func:`replan_horizon`) chosen by the map and the SD model: on
    maps over ``astar.COARSE_ABOVE_CELLS`` cells (buildings), and on any map for the
    map-conditioned generalist (``general``), the model's ``expert_spacing``
    (``SparseDiffusion.expert_spacing``, the median spacing of the waypoints it learnt), at
    least REPLAN_SPACING; None (Algorithm 1's P^g - p) on smaller maps with a per-map model,
    so maze2d-large's own models keep the paper's rule. (The generalist on maze2d-large, 12
    problems: 50 / 50 / 58.3% alone with the paper's rule and no placement, 100% with both
    rules, docs/rules.md.)

    Measured (docs/RESULTS.md): 3 m fits the warehouses (expert spacing 2.6-2.7 m); on the
    60 x 60 m office (6.5 m) 3 m asked for twice the waypoints SD learnt and 6.5 m beat it on
    ECAHD alone, fallbacks and time."""
    from ecahd_core.astar import COARSE_ABOVE_CELLS

    if grid.width * grid.height <= COARSE_ABOVE_CELLS and not general:
        return None
    return max(REPLAN_SPACING, expert_spacing or 0.0)


def replan_spacing_for(grid, value: float | None,
                       expert_spacing: float | None = None, *,
                       general: bool = False) -> float | None:
    """A replan-spacing setting [m] as the commands take it: None by the map and the model
    (:func:`auto_replan_spacing`), 0 off, else ``value``."""
    if value is None:
        return auto_replan_spacing(grid, expert_spacing, general=general)
    if not (math.isfinite(value) and value >= 0):
        raise EcahdError(f"replan spacing must be >= 0 m (0: off), got {value}")
    return value or None


def check_replan_spacing(spacing: float | None) -> float | None:
    """``spacing`` [m] if it is None (off) or a finite number > 0, else EcahdError."""
    if spacing is not None and not (math.isfinite(spacing) and spacing > 0):
        raise EcahdError(f"replan_spacing must be None (off) or a finite number > 0 m, "
                         f"got {spacing}")
    return spacing


def replan_horizon(horizon: int, iteration: int, start, goal,
                   spacing: float | None = None) -> int:
    """The horizon of Algorithm 1's p-th SD plan: P^g - p, at least 2 (line 2).

    With ``spacing`` [m] (ours, for big maps; None: the paper's rule) at least
    ceil(D / spacing) + 1 and at most P^g, for the straight distance D [m] from ``start`` (2,)
    to ``goal`` (2,): the horizon shrinks with the distance left, not with the count of
    waypoints reached. Algorithm 1 as written ends with a plan of horizon 2, the straight line
    to the goal, after P^g - 2 re-plans wherever the robot then is; on a building SD's first
    waypoints often lie close together, and that last straight leg crossed shelf rows for
    8-35 m (every colliding circle-robot plan on a generated warehouse, docs/RESULTS.md)."""
    h = max(2, horizon - iteration)
    if spacing is not None:
        h = max(h, distance_horizon(horizon, start, goal, spacing))
    return h


def distance_horizon(horizon: int, start, goal, spacing: float) -> int:
    """A plan's horizon by distance alone: ceil(D / ``spacing``) + 1 waypoints, at most
    ``horizon``, for the straight distance D [m] from ``start`` (2,) to ``goal`` (2,)."""
    d = float(np.linalg.norm(np.asarray(goal, dtype=np.float64)
                             - np.asarray(start, dtype=np.float64)))
    return min(horizon, int(math.ceil(d / spacing - 1e-9)) + 1)

