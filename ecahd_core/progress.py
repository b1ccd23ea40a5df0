"""The goal's cost-to-go over the free space a footprint fits, and the re-plan loop's subgoal
rule that uses it (ours, beyond the paper; :class:`SubgoalRule`, used by
:class:`~ecahd_core.planning.hierarchical.HierarchicalPlanner` and the ``global_planner`` node).

A re-plan loop (Algorithm 1 with a replan spacing) that has used its P^g - 1 iterations and is
not at the goal is usually circling a wall with the goal behind it: SD's candidates all aim at
the goal through the wall, placement puts their first waypoints back beside the wall, and the
robot dithers there until the iterations run out and the last plan crosses the wall
(docs/RESULTS.md, the session of 2026-12-04 13:58). The goal's cost-to-go (one Dijkstra over
the coarse A* graph per goal, :class:`~ecahd_core.astar.CoarseAStarPlanner`) says which way the
route round the wall goes; the subgoal rule then lets SD plan toward a point along that route.
SD still draws every waypoint and DD every local plan.
"""
from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from ecahd_core.astar import (COARSE_BLOCK_SIZE, AStarPlanner, CoarseAStarPlanner,
                              clearance_for_footprint)
from ecahd_core.planning.horizon import distance_horizon

# [m] how far round a point without the clearance (a waypoint beside a wall) its cost-to-go
# looks for cells that have it
SNAP_REACH = 0.5
# the subgoal rule (SubgoalRule): a re-plan beyond Algorithm 1's P^g - 1 iterations whose first
# leg is not free or brings the robot less than SUBGOAL_TRIGGER [m] nearer the goal by its
# cost-to-go plans toward the farthest point of the shortest route within SUBGOAL_REACH x the
# replan spacing that a straight leg reaches (route_sight), kept if its first leg is free and gains
# SUBGOAL_GAIN [m] on the other's
SUBGOAL_TRIGGER = 0.5
# ... and acts from a goal's first plan where its route is ROUNDABOUT x the straight line,
# which is not free (SubgoalRule.roundabout)
ROUNDABOUT = 1.5
SUBGOAL_REACH = 1.0
SUBGOAL_GAIN = 0.1


class GoalField:
    """Cost-to-go [m] to goals on one map for one footprint.

    The coarse A* graph of the footprint's clearance (blocks of ``COARSE_BLOCK_SIZE``; built on
    the first goal, about 0.9 s on a 60 x 60 m map at 0.03 m/cell) gives every node its cost to
    the goal's node by one Dijkstra (50-80 ms on that map, 28 000 nodes); a point's cost-to-go
    is the least, over its own cell's node or else the nodes within SNAP_REACH, of the node's
    cost plus the straight distance to the node's representative cell.

    Args:
        grid: the GridMap.
        footprint: the robot's Footprint (clearance as :func:`clearance_for_footprint`).
    """

    def __init__(self, grid, footprint) -> None:
        self.grid = grid
        self.clearance = clearance_for_footprint(footprint)
        self._graph: CoarseAStarPlanner | None = None

    @property
    def graph(self) -> CoarseAStarPlanner:
        """The coarse A* graph (built on first use)."""
        if self._graph is None:
            self._graph = CoarseAStarPlanner.for_resolution(
                AStarPlanner(self.grid, self.clearance), COARSE_BLOCK_SIZE, landmarks=0)
        return self._graph

    def to(self, goal) -> "CostToGo | None":
        """The cost-to-go to ``goal`` (2,) [m], or None where no node lies within SNAP_REACH of
        it (no free space the footprint fits there)."""
        graph = self.graph
        node = self.lookup(np.asarray(goal, dtype=np.float64).reshape(1, 2),
                           np.zeros(graph.num_nodes))[0][0]
        if node < 0:
            return None
        return CostToGo(self, graph._dijkstra(int(node)) * self.grid.resolution)

    def lookup(self, xy: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (K, 2) [m] and per-node costs (N,) [m] -> ((K,) node, (K,) cost [m]) of each
        point's least-cost node (see the class docstring); node -1 and cost inf for none."""
        graph, labels = self.graph, self.graph.labels
        H, W = labels.shape
        rows, cols = self.grid.world_to_cell(xy)
        nodes = np.full(len(xy), -1, dtype=np.int64)
        cost = np.full(len(xy), math.inf)
        reach = int(math.ceil(SNAP_REACH / self.grid.resolution))
        for i, (r, c) in enumerate(zip(rows.tolist(), cols.tolist())):
            if 0 <= r < H and 0 <= c < W and labels[r, c] >= 0:
                near = labels[r, c:c + 1]
            else:
                win = labels[max(0, r - reach):max(0, r + reach + 1),
                             max(0, c - reach):max(0, c + reach + 1)]
                near = np.unique(win[win >= 0])
                if len(near) == 0:
                    continue
            total = dist[near] + np.linalg.norm(graph.rep_xy[near] - xy[i], axis=1)
            j = int(np.argmin(total))
            if math.isfinite(total[j]):
                nodes[i], cost[i] = near[j], total[j]
        return nodes, cost


class CostToGo:
    """Cost-to-go [m] to one goal (:meth:`GoalField.to`).

    Call with points (K, 2) [m] -> (K,) [m], inf where a point has no node within SNAP_REACH or
    its node cannot reach the goal."""

    def __init__(self, field: GoalField, dist: np.ndarray) -> None:
        self.field, self.dist = field, dist

    def __call__(self, xy) -> np.ndarray:
        return self.field.lookup(np.asarray(xy, dtype=np.float64).reshape(-1, 2), self.dist)[1]

    def route(self, xy, reach: float) -> np.ndarray | None:
        """The shortest route from ``xy`` (2,) [m] toward the goal over the coarse graph, as
        its nodes' representatives (K, 2) [m], K >= 1, from ``xy``'s node until ``reach`` [m]
        of route or the goal's node; None where ``xy`` has no node that reaches the goal."""
        graph, res, dist = self.field.graph, self.field.grid.resolution, self.dist
        xy = np.asarray(xy, dtype=np.float64).reshape(2)
        node = int(self.field.lookup(xy[None], dist)[0][0])
        if node < 0:
            return None
        indptr, dst, cost = graph._indptr, graph._dst, graph._cost
        walked = float(np.linalg.norm(graph.rep_xy[node] - xy))
        route = [node]
        while walked < reach and dist[node] > 0 and indptr[node] < indptr[node + 1]:
            # the neighbour the shortest route goes through (least cost to the goal via it)
            j = min(range(indptr[node], indptr[node + 1]),
                    key=lambda e: dist[dst[e]] + cost[e] * res)
            if not dist[dst[j]] < dist[node]:
                break
            node, walked = dst[j], walked + cost[j] * res
            route.append(node)
        return graph.rep_xy[route].copy()


def route_sight(placer, start, route) -> np.ndarray:
    """Which points of ``route`` (K, 2) [m], a shortest route from ``start`` (2,) [m], a
    straight leg from ``start`` reaches -> (K,) bool: the leg crosses no more wall by the
    placer's leg test (``WaypointPlacer.wall_length``) than the route itself does from
    ``start`` to that point. The route's points are coarse nodes the footprint fits by A*'s
    clearance, which the leg test (conservative by up to half a cell diagonal) may find a few
    centimetres near a door's jamb: a straight leg that grazes no more than the route is as
    good as it (a robot standing in a door sees through it); one that cuts a corner is not.
    The leg test samples a leg once per cell, so the two may differ by a sample: a cell's
    width is the tolerance."""
    pts = np.concatenate([np.asarray(start, dtype=np.float64).reshape(1, 2), route])
    own = np.cumsum(placer.leg_walls(pts))  # (K,) [m] the route's own legs up to each point
    return placer.wall_length(pts[0], route) <= own + placer.grid.resolution


class SubgoalRule:
    """The subgoal rule (ours) on one map for one footprint.

    A re-plan beyond Algorithm 1's P^g - 1 iterations (a loop circling a wall with the goal
    behind it) whose first leg is not free or brings the robot less than SUBGOAL_TRIGGER nearer
    the goal by the goal's cost-to-go (:class:`GoalField`, one coarse Dijkstra per goal, kept
    for the last goal) is drawn again by SD toward a subgoal: of the shortest route's points
    within SUBGOAL_REACH x ``spacing``, the farthest a straight leg reaches (:func:`route_sight`:
    no more wall by the leg test than the route's own legs); that plan, followed by the goal,
    is kept if its first leg is free and gains SUBGOAL_GAIN on the other's. SD still draws the
    waypoints.

    Args:
        grid: the GridMap the cost-to-go is computed on (the static map).
        footprint: the robot's Footprint.
        spacing: [m] the re-plan loop's replan spacing.
    """

    def __init__(self, grid, footprint, spacing: float) -> None:
        self.field = GoalField(grid, footprint)
        self.spacing = float(spacing)
        self._to_go: tuple | None = None  # (goal, CostToGo) of the last goal

    def cost_to_go(self, goal, times: dict | None = None) -> "CostToGo | None":
        """The cost-to-go to ``goal`` (2,) [m] (None: no free space round it); its time [ms]
        is added to ``times["goal_field"]`` when it had to be computed."""
        key = tuple(np.asarray(goal, dtype=np.float64).tolist())
        if self._to_go is None or self._to_go[0] != key:
            t0 = time.perf_counter()
            self._to_go = (key, self.field.to(goal))
            if times is not None:
                times["goal_field"] = (times.get("goal_field", 0.0)
                                       + (time.perf_counter() - t0) * 1e3)
        return self._to_go[1]

    def roundabout(self, sd, start, goal, times: dict | None = None) -> bool:
        """Whether ``goal`` (2,) [m] lies behind walls from ``start`` (2,) [m]: the straight
        leg between them is not free by the placer's leg test and the goal's cost-to-go from
        ``start`` is more than ROUNDABOUT times their distance. SD reads the map but aims
        through it there (a 9 m problem whose route is 42 m spent 9 re-plans in a dead end
        before the rule acted, docs/rules.md)."""
        S = np.asarray(start, dtype=np.float64).reshape(2)
        G = np.asarray(goal, dtype=np.float64).reshape(2)
        straight = float(np.linalg.norm(G - S))
        if straight < 1e-9 or not sd.leg_blocked(np.stack([S, G])):
            return False
        to_go = self.cost_to_go(G, times)
        return to_go is not None and float(to_go(S[None])[0]) > ROUNDABOUT * straight

    def apply(self, sd, start, goal, sparse, iteration: int, *, generator=None,
              times: dict | None = None):
        """The rule on ``sparse`` (a SparsePlan), the SD plan of re-plan ``iteration`` (p) from
        ``start`` (2,) [m] toward ``goal`` (2,) [m] by ``sd`` (a SparseDiffusion with a
        placer): ``sparse`` itself, or SD's plan toward the subgoal followed by ``goal``
        (``first_leg`` "subgoal"). Callers apply it only past P^g - 1 iterations."""
        S = np.asarray(start, dtype=np.float64).reshape(2)
        G = np.asarray(goal, dtype=np.float64).reshape(2)
        to_go = self.cost_to_go(G, times)
        if to_go is None:
            return sparse
        wp = sparse.waypoints
        g_start, g_next = to_go(wp[:2])
        blocked = sd.leg_blocked(wp)
        if not blocked and g_next <= g_start - SUBGOAL_TRIGGER:
            return sparse
        route = to_go.route(S, SUBGOAL_REACH * self.spacing)
        if route is None:
            return sparse
        # the farthest point of the route a straight leg from S reaches (the route's end if
        # none does): SD then plans round the corner from there on
        seen = np.flatnonzero(route_sight(sd.placer, S, route))
        sub = route[seen[-1] if len(seen) else -1]
        if np.linalg.norm(sub - S) < sd.placer.step:
            return sparse
        # the subgoal is at most SUBGOAL_REACH x spacing of route away: its plan keeps a waypoint
        # per spacing of it (at least one interior waypoint), not Algorithm 1's P^g - p (eleven
        # waypoints over 3 m on a goal's first plan dithered round the start)
        P_g = sd.config.horizon
        h = min(P_g, max(3, distance_horizon(P_g, S, sub, self.spacing)))
        alt = sd.plan(S, sub, horizon=h, generator=generator, repair_legs=1)
        w = alt.waypoints
        if sd.leg_blocked(w) or not (to_go(w[1:2])[0]
                                      < (g_start if blocked else g_next) - SUBGOAL_GAIN):
            return sparse
        return replace(alt, waypoints=np.concatenate([w, G[None]]), first_leg="subgoal")
