"""One iteration's global plan of Algorithm 1 (paper Sec. III-A, lines 2-12) with our rules round
Sparse Diffusion, as one object: :class:`SparseStage`. The offline planner
(:class:`~ecahd_core.planning.hierarchical.HierarchicalPlanner`, behind ``ecahd plan`` and the
planning benchmarks) and the online one (:class:`~ecahd_core.planning.online.OnlinePlanner`,
behind global_planner) both call :meth:`SparseStage.step` for every SD plan, so what the
benchmarks measure is what the robot runs.

The rules (ours, beyond the paper), each with its one gate here:

- **free first leg** (:meth:`SparseStage.leg_rule`; ``SparseConfig.leg_batches``): a re-plan
  whose caller follows only its first leg (every_waypoint) takes another candidate, or a further
  batch, when the selected one's first leg crosses a wall after placement and leg repair. Needs
  the SD's ``placer`` (building maps) and acts with cold re-plans only: a warm-started re-plan
  (``SparseConfig.warm_fraction``) repairs every leg instead, and one whose first leg still
  crosses a wall is drawn again from noise under the rule (``first_leg`` "cold" when that
  draw's first leg was free as selected).
- **subgoal** (:meth:`SparseStage.subgoaling`; :class:`~ecahd_core.progress.SubgoalRule`): a
  re-plan beyond Algorithm 1's P^g - 1 iterations, or (online) a stalled one (:func:`stalled`:
  the robot asked for the goal's last plans within a metre), whose first leg makes no progress
  by the goal's cost-to-go plans toward a point on the shortest route.
- **settle** (:meth:`SparseStage.settling`): a plan whose every straight leg is free by the
  placer's leg test is followed whole (no re-plan at its waypoints); a plan toward a subgoal
  whose legs up to it are free is followed to the subgoal.
- **forced last plan** (:data:`~ecahd_core.planning.horizon.MAX_EXTRA_ITERATIONS`): a re-plan
  loop that has run that many iterations beyond P^g - 2 follows its last SD plan whole.

The subgoal and settle rules act where re-plans have a replan spacing and the free-first-leg
rule is on: building maps by default (maze2d-large keeps the paper's Algorithm 1).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ecahd_core.errors import EcahdError
from ecahd_core.planning.horizon import (MAX_EXTRA_ITERATIONS, REPLAN_POLICIES,
                                         check_replan_spacing, replan_horizon)
from ecahd_core.planning.sparse import SparseDiffusion, SparsePlan


# a re-plan is stalled when the goal's last STALL_PLANS plans, itself included, all started
# within STALL_RADIUS of where it starts: the robot is turning in loops where it is (the office
# closed loop of 2026-12-07: SD's re-plans aimed through the wall beside the door the robot stood
# in, 9 plans in 26 s within about a metre, until a blocked segment's A* fallback took it
# through). The online runner judges it (the robot's progress); the offline loop, whose agent
# jumps to each waypoint, does not: there it changed 20 of 432 office plans and 14 of 648 on
# maps never used in development, one of them lost (docs/rules.md)
STALL_PLANS = 3
STALL_RADIUS = 1.0  # [m]


def stalled(starts) -> bool:
    """Whether a re-plan is stalled: ``starts`` (K, 2) [m] are where the goal's plans started,
    oldest first, the last being the re-plan's own; at least STALL_PLANS, the last STALL_PLANS
    all within STALL_RADIUS of the last."""
    s = np.asarray(starts, dtype=np.float64).reshape(-1, 2)
    if len(s) < STALL_PLANS:
        return False
    s = s[-STALL_PLANS:]
    return bool((np.linalg.norm(s - s[-1], axis=1) <= STALL_RADIUS).all())


@dataclass(frozen=True)
class GlobalStep:
    """One iteration's global plan (:meth:`SparseStage.step`).

    Attributes:
        sparse: SD's plan after the rules (its ``first_leg`` says what the free-first-leg and
            subgoal rules did).
        waypoints: (P, 2) [m] the plan to follow, ``sparse.waypoints``.
        follow: index of the waypoint whose reach asks for the next re-plan: 1 is Algorithm 1
            (re-plan at the next waypoint), P - 1 follows the whole plan (the policy "once", the
            settle rule, a forced last plan), in between a plan followed to its subgoal.
        settled: the settle rule accepted the whole plan.
        forced: the loop ran out of iterations and follows this plan whole.
    """

    sparse: SparsePlan
    waypoints: np.ndarray
    follow: int
    settled: bool = False
    forced: bool = False


class SparseStage:
    """Algorithm 1's SD call of one iteration with every rule round it (see the module docstring).

    Args:
        sd: the SparseDiffusion, on the static map (its ``placer`` and ``cost``); a caller that
            knows more (obstacles the scans found) passes a view of it
            (:meth:`SparseDiffusion.on`) to :meth:`step`.
        replan: "every_waypoint" (Algorithm 1) or "once" (one SD plan per goal, ours).
        replan_spacing: [m] every_waypoint: re-plans keep a waypoint per this many metres left to
            the goal (:func:`~ecahd_core.planning.horizon.replan_horizon`); None: P^g - p.
        subgoals: the subgoal rule (on where its gate allows).
        settle: the settle rule (on where its gate allows).
    """

    def __init__(self, sd: SparseDiffusion, *, replan: str = "every_waypoint",
                 replan_spacing: float | None = None, subgoals: bool = True,
                 settle: bool = True) -> None:
        if replan not in REPLAN_POLICIES:
            raise EcahdError(f"replan policy {replan!r} is not one of {list(REPLAN_POLICIES)}")
        self.sd = sd
        self.replan = replan
        self.replan_spacing = check_replan_spacing(replan_spacing)
        self.subgoals = bool(subgoals)
        self.settle = bool(settle)
        self._subgoal_rule = None  # progress.SubgoalRule on the static placer's map, built once
        self._roundabout_goal, self._roundabout_value = None, False  # the last goal's verdict
        # the lanes learnt from demonstrations (ecahd_core.lanes.WaypointLanes) or None: every
        # plan's interior waypoints are moved onto them before they are followed
        self.lanes = None

    # ------------------------------------------------------------------------------- gates
    @property
    def every_waypoint(self) -> bool:
        return self.replan == "every_waypoint"

    def leg_rule(self, sd: SparseDiffusion | None = None) -> bool:
        """Whether SD's free-first-leg rule acts: every_waypoint, a placer and ``leg_batches``
        >= 0 (``sd``: the view planned with; None: the static one). With warm starts it acts
        on the re-plans drawn again from noise (:meth:`step`)."""
        sd = sd or self.sd
        return self.every_waypoint and sd.placer is not None and sd.config.leg_batches >= 0

    def subgoaling(self, sd: SparseDiffusion | None = None) -> bool:
        """Whether the subgoal rule acts: ``subgoals``, a replan spacing, the free-first-leg
        rule."""
        return self.subgoals and self.replan_spacing is not None and self.leg_rule(sd)

    def settling(self, sd: SparseDiffusion | None = None) -> bool:
        """Whether the settle rule acts: ``settle``, every_waypoint, a replan spacing, a placer
        and ``leg_batches`` >= 0 (warm re-plans too: they repair every leg)."""
        sd = sd or self.sd
        return (self.settle and self.every_waypoint and self.replan_spacing is not None
                and sd.placer is not None and sd.config.leg_batches >= 0)

    def legs_free(self, waypoints: np.ndarray, sd: SparseDiffusion | None = None) -> bool:
        """The settle rule's test: every straight leg of ``waypoints`` (P, 2) [m] is free by the
        placer's leg test (``WaypointPlacer.leg_walls``); False where the rule is off."""
        sd = sd or self.sd
        return self.settling(sd) and not sd.placer.leg_walls(waypoints).any()

    def forced(self, iteration: int) -> bool:
        """Whether iteration ``iteration`` (p) is the forced last plan (MAX_EXTRA_ITERATIONS
        beyond P^g - 2, every_waypoint)."""
        return self.every_waypoint and iteration >= self.sd.config.horizon - 2 + \
            MAX_EXTRA_ITERATIONS

    # -------------------------------------------------------------------------------- step
    def _roundabout(self, sd, S: np.ndarray, G: np.ndarray, times: dict | None) -> bool:
        """The goal G lies behind walls from S (SubgoalRule.roundabout), judged once per
        start of a goal's plans: from the robot's pose when the goal came."""
        key = tuple(G.tolist())
        if self._roundabout_goal != key:
            self._roundabout_goal = key
            self._roundabout_value = self.subgoal_rule().roundabout(sd, S, G, times)
        return self._roundabout_value

    def subgoal_rule(self):
        """The SubgoalRule on the static placer's map and footprint (built on first use; call
        it when a map arrives so the cost-to-go's graph is not built during a re-plan)."""
        if self._subgoal_rule is None:
            from ecahd_core.progress import SubgoalRule

            placer = self.sd.placer
            self._subgoal_rule = SubgoalRule(placer.grid, placer.footprint, self.replan_spacing)
        return self._subgoal_rule

    def horizon(self, iteration: int, start, goal) -> int:
        """The horizon of iteration ``iteration``'s plan from ``start`` to ``goal`` ((2,) [m]):
        P^g for a goal's first plan and under "once", else
        :func:`~ecahd_core.planning.horizon.replan_horizon`."""
        P_g = self.sd.config.horizon
        if not self.every_waypoint:
            return P_g
        return replan_horizon(P_g, iteration, start, goal, self.replan_spacing)

    def step(self, start, goal, previous=None, *, iteration: int = 0,
             horizon: int | None = None, sd: SparseDiffusion | None = None, generator=None,
             settle: bool = True, times: dict | None = None, stalled: bool = False
             ) -> GlobalStep:
        """Iteration ``iteration`` (p, waypoints reached since the goal's first plan) of
        Algorithm 1 from ``start`` (2,) [m] to ``goal`` (2,) [m].

        Args:
            previous: (P, 2) [m] the plan being followed (a warm start's source; None: none).
            horizon: the plan's horizon (None: :meth:`horizon`; the online runner passes its
                own, the same number).
            sd: the SparseDiffusion view to plan with (None: the static one).
            generator: SD's random numbers.
            settle: False turns the settle rule off for this call (backtracking re-plans).
            times: the subgoal rule's cost-to-go time is added to ``times["goal_field"]`` [ms].
            stalled: the online caller's :func:`stalled` verdict on this re-plan: the subgoal
                rule acts whatever the iteration.

        Returns:
            GlobalStep.
        """
        sd = sd or self.sd
        S = np.asarray(start, dtype=np.float64).reshape(2)
        G = np.asarray(goal, dtype=np.float64).reshape(2)
        forced = self.forced(iteration)
        if horizon is None:
            horizon = self.horizon(iteration, S, G)
        # the free-first-leg rule and first-leg repair act on cold every_waypoint re-plans,
        # whose caller follows only the first leg; a forced plan is followed whole
        # (a warm-started re-plan has every leg repaired: the next warm start comes from them)
        warm = sd.warm_start_for(S, previous, horizon) is not None
        first_leg_only = self.every_waypoint and not forced and not warm
        sparse = sd.replan(S, G, previous, horizon=horizon, generator=generator,
                           repair_legs=1 if first_leg_only else None)
        if warm and not forced and self.leg_rule(sd) and sd.leg_blocked(sparse.waypoints):
            # a warm re-plan whose first leg still crosses a wall after every leg's repair:
            # drawn again from noise, with the free-first-leg rule (the warm start's speed
            # where the plan before was right, the rule's choice where it was not)
            sparse = sd.plan(S, G, horizon=horizon, generator=generator, repair_legs=1)
            sparse = replace(sparse, first_leg=sparse.first_leg or "cold")
        if (self.every_waypoint and not forced and self.subgoaling(sd)
                and (iteration >= sd.config.horizon - 1  # beyond where Algorithm 1 reaches G
                     or stalled or self._roundabout(sd, S, G, times))):
            sparse = self.subgoal_rule().apply(sd, S, G, sparse, iteration,
                                               generator=generator, times=times)
        wp = sparse.waypoints if self.lanes is None else self.lanes(sparse.waypoints)
        whole = len(wp) - 1
        if not self.every_waypoint or forced:
            return GlobalStep(sparse, wp, whole, forced=forced)
        if settle and len(wp) > 2 and self.legs_free(wp, sd):
            return GlobalStep(sparse, wp, whole, settled=True)
        # a plan toward a subgoal whose legs up to the subgoal are free: followed to the
        # subgoal (its last leg, to G, is left to the re-plans)
        if settle and sparse.first_leg == "subgoal" and self.legs_free(wp[:-1], sd):
            return GlobalStep(sparse, wp, max(1, len(wp) - 2))
        return GlobalStep(sparse, wp, 1)
