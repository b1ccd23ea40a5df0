"""Algorithm 1 over a whole problem (paper Sec. III-A) with Algorithm 2's Dense Diffusion local
stage: :class:`HierarchicalPlanner`, the offline planner behind ``ecahd plan`` and the planning
benchmarks. Each iteration's global plan comes from :class:`~ecahd_core.planning.rules.SparseStage`,
the same code the online planner behind global_planner calls; each segment's local plan from
:meth:`HierarchicalPlanner.local_stages`, the same code local_refiner calls."""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
import torch

from ecahd_core.errors import EcahdError
from ecahd_core.placement import BACKTRACKS
from ecahd_core.planning.dense import DenseConfig, DenseStage, LocalStages
from ecahd_core.planning.rules import SparseStage
from ecahd_core.planning.sparse import SparseDiffusion, SparsePlan, rank_candidates

# iterations a backtracking round (HierarchicalPlanner's ``backtracks``) may try: each tries its
# whole SD batch through placement, repair and one batch of local stages (hundreds of ms)
BACKTRACK_TRIES = 4


@dataclass(frozen=True)
class HierarchicalPlan:
    """Result of Algorithm 1 on one problem.

    Attributes:
        trajectory: (N, 2) [m] the executed dense path: the local plans joined end to end, pulled
            taut by the shortcut rule (``HierarchicalPlanner``'s ``shortcut``) when it acted.
        global_plans: the sparse plan t^g_p of every iteration p, each (P^g - p, 2) [m].
        segments: the local plan t^l_p of every iteration, each (P^l, 2) [m].
        dd_segments: per iteration, whether DD replaced the straight local plan.
        local_costs: per iteration, (c^l before DD, c^l after DD or the same).
        timings_ms: wall time per stage: "sd", "j_check", "dd", "polish", "total".
        polished: per iteration, whether polishing moved the local plan (see DenseConfig).
        placed: SD waypoints moved out of walls or added round them by the SparseDiffusion's
            ``placer``, summed over the iterations' SD plans.
        exact_kept: per iteration, whether the exact rule (``HierarchicalPlanner``'s
            ``exact_check``) put back the segment's straight or unpolished DD plan.
        first_leg: per iteration, :attr:`SparsePlan.first_leg` of its SD plan ("" for every
            iteration of replan "once"; "backtrack" where backtracking took another candidate;
            "subgoal" where the subgoal rule drew it toward a subgoal).
        backtracked: rounds in which backtracking (``HierarchicalPlanner``'s ``backtracks``)
            took another SD candidate.
        settled: the iteration whose SD plan the settle rule (``HierarchicalPlanner``'s
            ``settle``) followed whole, or None.
        shortcut: the shortcut rule pulled ``trajectory`` taut (``segments`` are still the
            local plans before it).
    """

    trajectory: np.ndarray
    global_plans: list
    segments: list
    dd_segments: list
    local_costs: list
    timings_ms: dict
    polished: list = field(default_factory=list)
    placed: int = 0
    exact_kept: list = field(default_factory=list)
    first_leg: list = field(default_factory=list)
    backtracked: int = 0
    settled: int | None = None
    shortcut: bool = False

    @property
    def dd_calls(self) -> int:
        return int(sum(self.dd_segments))

    @property
    def first_leg_changed(self) -> bool:
        """Whether SparseConfig.leg_batches's rule changed any iteration's SD plan."""
        return any(f in ("other", "batch") for f in self.first_leg)

    @property
    def subgoals(self) -> int:
        """Iterations whose SD plan the subgoal rule (HierarchicalPlanner's ``subgoals``)
        drew toward a subgoal."""
        return self.first_leg.count("subgoal")


class HierarchicalPlanner(DenseStage):
    """Algorithm 1 with Algorithm 2's DenseDiffusion, over a whole problem (the local stage is
    :class:`~ecahd_core.planning.dense.DenseStage`'s).

    Args:
        sparse: the SparseDiffusion global planner.
        dense_checkpoint: the DD checkpoint (None when ``dense.enabled`` is False).
        costmap, footprint_points, cost_config, dense: DenseStage's.
        replan: "every_waypoint" (Algorithm 1: SD best-of-N again from each reached waypoint,
            horizon P^g - p; warm-started from the previous plan when
            ``sparse.config.warm_fraction`` is set; the local stages of all iterations then
            run in one batch) or "once" (ours, faster: SD best-of-N once, then its remaining
            waypoints are the global plan of every later iteration; in a static known map the
            replanned distribution is the same, so this trades resampling for ~P^g times less SD
            work).
        replan_spacing: [m] every_waypoint: each SD re-plan keeps enough waypoints for the
            distance left to the goal (:func:`replan_horizon`; ours; None: Algorithm 1's
            P^g - p).
        exact_check: the exact rule (DenseStage's).
        backtracks: every_waypoint, with ``exact_check`` and the SparseDiffusion's free-first-leg
            rule on (a ``placer`` and ``leg_batches`` >= 0: building maps): up to this many
            rounds of backtracking (ours). When the exact checker still finds iterations'
            local plans in collision after DD, polishing and the exact rule, the first of them
            (or else the iteration before it, which chose where it starts; then the next
            colliding one, at most BACKTRACK_TRIES iterations a round) takes another candidate
            of its SD batch instead: the best-ranked one whose first leg (placed and repaired)
            gets a local plan the checker finds free, the candidates' local stages run in one
            batch. The iterations after it are
            planned again from its new waypoint. 0 turns it off. :attr:`HierarchicalPlan.
            backtracked` counts the rounds that took a candidate.
        subgoals: the subgoal rule (ours; every_waypoint with a replan spacing and the
            SparseDiffusion's free-first-leg rule on: building maps). A re-plan beyond
            Algorithm 1's P^g - 1 iterations (the loop circling a wall with the goal behind it)
            whose first leg makes no progress by the goal's cost-to-go over the free space the
            footprint fits is drawn again by SD toward a subgoal on the shortest route
            (:class:`~ecahd_core.progress.SubgoalRule`). SD still draws the waypoints and DD
            the local plans. :attr:`HierarchicalPlan.subgoals` counts the iterations it
            changed.
        settle: the settle rule (ours; every_waypoint with a replan spacing and the
            free-first-leg rule on: building maps). An SD plan whose every straight leg is
            free by the placer's leg test (``WaypointPlacer.leg_walls``, the test the
            free-first-leg rule applies to the first leg) is followed whole, each leg an
            iteration, instead of drawn again at each waypoint: a re-plan would only judge its
            first leg by the same test; a plan toward a subgoal (``subgoals``) whose legs up to
            the subgoal are all free is followed to the subgoal the same way (the re-plans then
            start there). DD and the exact rule still make every local plan. With backtracking
            on, a leg of that plan (after its first) whose local plan the exact checker still
            finds in collision (the leg test judges the footprint by circles) is cut there, and
            from its start the iterations re-plan at each waypoint as without the rule (a
            backtracking round). :attr:`HierarchicalPlan.settled` is the iteration whose plan
            was followed (None after such a cut).
        shortcut: the shortcut rule (ours; with ``exact_check``): a whole plan the exact
            checker finds free is pulled taut by straight segments that pass Algorithm 1's
            local test (J's c^l <= c_th over P^l points) and the exact checker
            (:func:`~ecahd_core.shortcut.shortcut_path`). :attr:`HierarchicalPlan.shortcut`
            says when it acted; its time is ``timings_ms["shortcut"]``.
        shortcut_room: the shortcut rule also takes a straight segment that comes no nearer a
            wall than the stretch of the plan it replaces (J's peak cost;
            :func:`~ecahd_core.shortcut.shortcut_path`'s ``by_peak``). For a round footprint the
            peak is a function of the room beside it in any heading, so the plan's least room
            does not shrink (to the cost map's accuracy, about a cell); ``for_map`` turns it on
            for round footprints only.
    """

    def __init__(self, sparse: SparseDiffusion, dense_checkpoint, *, costmap, footprint_points,
                 cost_config=None, dense: DenseConfig | None = None, device: str = "cpu",
                 replan: str = "every_waypoint", exact_check=None,
                 replan_spacing: float | None = None, backtracks: int = BACKTRACKS,
                 subgoals: bool = True, settle: bool = True, shortcut: bool = True,
                 shortcut_room: bool = False) -> None:
        if int(backtracks) != backtracks or backtracks < 0:
            raise EcahdError(f"backtracks must be an integer >= 0 (0: off), got {backtracks!r}")
        # one iteration's SD plan with its rules: the same object the online planner calls
        self.stage = SparseStage(sparse, replan=replan, replan_spacing=replan_spacing,
                                 subgoals=subgoals, settle=settle)
        super().__init__(dense_checkpoint, costmap=costmap, footprint_points=footprint_points,
                         cost_config=cost_config, dense=dense, device=device,
                         exact_check=exact_check)
        self.backtracks = int(backtracks)
        self.sparse = sparse
        self.shortcut = bool(shortcut)
        self.shortcut_room = bool(shortcut_room)

    @classmethod
    def for_map(cls, grid, footprint, sd: SparseDiffusion, *, dense: DenseConfig | None = None,
                replan: str = "every_waypoint", replan_spacing: float | None = None,
                exact: bool = True, backtracks: int = BACKTRACKS, subgoals: bool = True,
                settle: bool = True, shortcut: bool = True, model: str | None = None,
                device: str = "cpu", learnt=None) -> "HierarchicalPlanner":
        """Algorithm 1 on ``grid`` for ``footprint`` over ``sd`` (``SparseDiffusion.for_map``)
        as ``ecahd plan`` and the benchmarks build it: the map's DD model (``model``: a path,
        per-map or segment-frame; "general": the shipped segment-frame DD), J from
        ``sd.cost``, the re-plans' spacing by the map and the model (``replan_spacing`` None; 0:
        off; ``horizon.replan_spacing_for``) and the exact rule (``exact``)."""
        from ecahd_core.collision import exact_check_for
        from ecahd_core.model_zoo import load_dd
        from ecahd_core.planning.horizon import replan_spacing_for

        return cls(sd, load_dd(learnt if learnt is not None else grid, path=model,
                               footprint=footprint),
                   costmap=sd.cost.costmap, footprint_points=sd.cost.footprint_points,
                   cost_config=sd.cost.config,
                   dense=dense, device=device, replan=replan,
                   replan_spacing=replan_spacing_for(grid, replan_spacing, sd.expert_spacing,
                                                     general=sd.general),
                   exact_check=exact_check_for(grid, footprint) if exact else None,
                   backtracks=backtracks, subgoals=subgoals, settle=settle,
                   shortcut=shortcut, shortcut_room=footprint.is_circle)

    @property
    def replan(self) -> str:
        """The re-plan policy (``SparseStage.replan``)."""
        return self.stage.replan

    @property
    def replan_spacing(self) -> float | None:
        """[m] the re-plans' spacing (``SparseStage.replan_spacing``; None: P^g - p)."""
        return self.stage.replan_spacing

    def plan(self, start, goal, *, generator: torch.Generator | None = None) -> HierarchicalPlan:
        """Run Algorithm 1 from ``start`` to ``goal`` ((2,) [m] each)."""
        S = torch.as_tensor(np.asarray(start, dtype=np.float32))
        G = torch.as_tensor(np.asarray(goal, dtype=np.float32))
        t_total = time.perf_counter()
        times = {"sd": 0.0}
        if self.replan == "once":
            return self._plan_once(S, G, generator, t_total)
        global_plans, first_leg = [], []
        sparse_plans: list = []  # per iteration its SD plan (None: a leg of a forced plan)
        settled = self._iterate(S, G, global_plans, first_leg, sparse_plans, times, generator)
        stages = self._joined_stages(global_plans, generator)
        backtracked = 0
        for _ in range(self.backtracks if self._backtracking else 0):
            bad = self._colliding(stages.plans, joined=True).tolist()
            # the colliding iterations, each then the one before it (which chose where it starts)
            tries = [j for i, b in enumerate(bad) if b for j in (i, i - 1)
                     if j >= 0 and sparse_plans[j] is not None]
            t0 = time.perf_counter()
            q, alt = None, None
            for j in list(dict.fromkeys(tries))[:BACKTRACK_TRIES]:
                alt = self._free_alternative(sparse_plans[j], global_plans[j], generator)
                if alt is not None:
                    q = j
                    break
            times["backtrack"] = times.get("backtrack", 0.0) + (time.perf_counter() - t0) * 1e3
            if alt is None and settled is not None:
                # a colliding leg of the plan the settle rule followed, after its first (the
                # leg test passed it, judging the footprint by circles): from that leg's start
                # the iterations re-plan at each waypoint, as without the rule
                inside = [i for i, b in enumerate(bad) if b and i > settled]
                if inside:
                    q = inside[0]
                    del global_plans[q:], first_leg[q:], sparse_plans[q:]
                    settled, backtracked = None, backtracked + 1
                    self._iterate(torch.as_tensor(global_plans[-1][1], dtype=torch.float32), G,
                                  global_plans, first_leg, sparse_plans, times, generator,
                                  settle=False)
                    stages = self._joined_stages(global_plans, generator)
                    continue
            if alt is None:
                break
            backtracked += 1
            del global_plans[q:], first_leg[q:], sparse_plans[q:]
            if settled is not None and settled >= q:
                settled = None
            global_plans.append(alt)
            first_leg.append("backtrack")
            sparse_plans.append(None)
            if len(alt) > 2:
                again = self._iterate(torch.as_tensor(alt[1], dtype=torch.float32), G,
                                      global_plans, first_leg, sparse_plans, times, generator)
                settled = settled if again is None else again
            stages = self._joined_stages(global_plans, generator)
        placed = sum(sp.placed for sp in sparse_plans if sp is not None)
        times.update(stages.timings_ms)
        result = self._result(global_plans, stages, times, t_total, placed, first_leg)
        return self._pulled(replace(result, backtracked=backtracked, settled=settled), t_total)

    def _pulled(self, result: HierarchicalPlan, t_total: float) -> HierarchicalPlan:
        """The shortcut rule (``shortcut``) on a finished plan: its trajectory pulled taut when
        the exact checker finds it free; the total time then includes the rule's."""
        if not (self.shortcut and self.exact_check is not None
                and not self.exact_check(result.trajectory).any()):
            return result
        from ecahd_core.shortcut import shortcut_path

        t0 = time.perf_counter()
        pulled = shortcut_path(result.trajectory,
                               terms=lambda plans: self.local_terms(plans, plans[:, -1]),
                               c_th=self.dense.c_th, points=self.dense.points,
                               exact_check=self.exact_check, by_peak=self.shortcut_room)
        times = dict(result.timings_ms)
        times["shortcut"] = (time.perf_counter() - t0) * 1e3
        times["total"] = (time.perf_counter() - t_total) * 1e3
        return replace(result, trajectory=pulled, timings_ms=times,
                       shortcut=len(pulled) < len(result.trajectory))

    @property
    def _backtracking(self) -> bool:
        """Whether backtracking can act (see the class docstring)."""
        sp = self.sparse
        return (self.backtracks > 0 and self.exact_check is not None and self.dd is not None
                and sp.placer is not None and sp.config.leg_batches >= 0)

    def _iterate(self, S: torch.Tensor, G: torch.Tensor, global_plans: list, first_leg: list,
                 sparse_plans: list, times: dict, generator, *, settle: bool = True
                 ) -> int | None:
        """Algorithm 1's SD calls (lines 2-12) from ``S`` (2,) to ``G`` (2,), appending each
        iteration's SD plan, first-leg note and SparsePlan to the lists, which hold the
        iterations before (their count is the iteration index p). Returns the iteration whose
        plan the settle rule followed whole, or None (always with ``settle`` False)."""
        p = len(global_plans)
        # Algorithm 1 line 1: P^g - 1 iterations, the last one reaching G. With waypoint spacing
        # by distance (SparseConfig.max_spacing) a plan may have more waypoints than its
        # horizon, and with a replan spacing the horizon stays up while G is far: the
        # iterations go on until a plan is just (S, G); each iteration's plan, and how much of
        # it is followed before the next (one leg; the whole plan or up to a subgoal under the
        # settle rule; the whole last plan once the loop runs out of iterations), come from
        # SparseStage.step, as for the online planner.
        # MoveAgent takes the agent to the end of the local plan, t^g_p[1] (DD inpaints it), so
        # iteration p + 1's SD call needs only iteration p's SD plan: the SD calls run first,
        # then every iteration's local stage (lines 13-18) in one batch, as for replan "once":
        # J and DD give each segment what it would get alone, and polishing (ours) descends J
        # over the joined path, start and goal fixed, so a waypoint near a wall may move (the
        # SD calls after it start from where SD put it).
        while True:
            t0 = time.perf_counter()
            step = self.stage.step(S.numpy(), G.numpy(),
                                   global_plans[-1] if global_plans else None, iteration=p,
                                   generator=generator, settle=settle, times=times)
            sparse, waypoints, legs = step.sparse, step.waypoints, step.follow
            times["sd"] += (time.perf_counter() - t0) * 1e3
            global_plans += [waypoints[q:] for q in range(legs)]
            first_leg += [sparse.first_leg] + [""] * (legs - 1)
            sparse_plans += [sparse] + [None] * (legs - 1)
            if step.forced or step.settled:  # the whole plan to G, one iteration per leg
                return p if step.settled else None
            S = torch.as_tensor(waypoints[legs], dtype=torch.float32)  # MoveAgent
            p += legs
            if len(waypoints) == 2:
                return None

    def _joined_stages(self, global_plans: list, generator) -> LocalStages:
        """Every iteration's local stage (lines 13-18) in one batch, polished as one path."""
        ends = torch.as_tensor(np.stack([w[:2] for w in global_plans]), dtype=torch.float32)
        return self.local_stages(ends[:, 0], ends[:, 1],
                                 end_fixed=torch.ones(len(global_plans), dtype=torch.bool),
                                 joined=True, generator=generator)

    def _free_alternative(self, sparse: SparsePlan, followed: np.ndarray, generator
                          ) -> np.ndarray | None:
        """Backtracking (``backtracks``): of the other candidates of ``sparse`` (the SD plan of
        an iteration whose local plan collides; ``followed`` (P, 2) [m] its waypoints as
        followed), in the selection's order, the placed and repaired waypoints (P', 2) [m] of
        the first whose first leg differs from ``followed``'s and whose local plan (one batch
        of local stages, both ends fixed) the exact checker finds free; None if none is."""
        sd, cfg = self.sparse, self.sparse.config
        cands = sparse.candidates
        goal = cands[sparse.best, -1]
        order = rank_candidates(cands, goal, epsilon=cfg.epsilon, rule=cfg.selection,
                                collision_costs=sparse.collision_costs,
                                collision_tolerance=cfg.collision_tolerance)
        options = []
        for k in order:
            waypoints, _ = sd._place(cands[k], legs=1)
            if len(waypoints) >= 2 and not any(
                    np.allclose(waypoints[1], w[1]) for w in [followed] + options):
                options.append(waypoints)
        if not options:
            return None
        a = torch.as_tensor(np.stack([w[0] for w in options]), dtype=torch.float32)
        b = torch.as_tensor(np.stack([w[1] for w in options]), dtype=torch.float32)
        stages = self.local_stages(a, b, end_fixed=torch.ones(len(options), dtype=torch.bool),
                                   generator=generator)
        bad = self._colliding(stages.plans, joined=False).tolist()
        return next((w for w, b_ in zip(options, bad) if not b_), None)

    def _plan_once(self, S: torch.Tensor, G: torch.Tensor, generator, t_total: float
                   ) -> HierarchicalPlan:
        """Algorithm 1 with one SD plan: every iteration's local stage depends on that plan only,
        so all of them run in one batch (:meth:`local_stages`). Polishing (when on and some
        local plan is still above c_th) descends J over the whole joined path at once, start
        and goal fixed, so the waypoints where segments meet may move too."""
        times = {"sd": 0.0}
        t0 = time.perf_counter()
        step = self.stage.step(S.numpy(), G.numpy(), generator=generator)
        sparse, waypoints = step.sparse, step.waypoints
        times["sd"] = (time.perf_counter() - t0) * 1e3
        wp = torch.as_tensor(waypoints, dtype=torch.float32)
        stages = self.local_stages(wp[:-1], wp[1:], end_fixed=torch.ones(len(wp) - 1,
                                                                          dtype=torch.bool),
                                   joined=True, generator=generator)
        times.update(stages.timings_ms)
        return self._pulled(self._result([waypoints[p:] for p in range(len(waypoints) - 1)],
                                         stages, times, t_total, sparse.placed,
                                         [""] * (len(waypoints) - 1)), t_total)

    @staticmethod
    def _result(global_plans: list, stages: LocalStages, times: dict, t_total: float,
                placed: int, first_leg: list) -> HierarchicalPlan:
        """The HierarchicalPlan of the iterations' SD plans and their local stages."""
        segments = [seg.numpy().astype(np.float64) for seg in stages.plans]
        traj = np.concatenate([segments[0]] + [sg[1:] for sg in segments[1:]])
        times["total"] = (time.perf_counter() - t_total) * 1e3
        return HierarchicalPlan(trajectory=traj, global_plans=global_plans, segments=segments,
                                dd_segments=stages.dd_used.tolist(),
                                local_costs=list(zip(stages.c_before.tolist(),
                                                     stages.c_after.tolist())),
                                timings_ms=times, polished=stages.polished.tolist(),
                                placed=placed, exact_kept=stages.exact_kept.tolist(),
                                first_leg=first_leg)
