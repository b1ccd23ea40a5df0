"""Sparse Diffusion (paper Sec. III-A, Algorithm 1 lines 2-11): the global sampler with best-of-N
selection, SD's free-first-leg rule and waypoint spacing by distance (ours).

Selection rules for the best of N candidates t^{g,(i)} (Sec. III-A):
- ``shortest_reaching`` (the paper's): among candidates with min_k ||t_k - G|| < epsilon the one
  of shortest path length L(t) = sum_k ||t_{k+1} - t_k||; if none reaches the goal, the
  shortest overall.
- ``collision_aware`` (ours): the same, but candidates are first ranked by J's collision cost of
  the linearly interpolated path (surface sweep of the footprint), keeping those within
  ``collision_tolerance`` of the least-colliding one, then the paper's rule among them.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass

import numpy as np
import torch

from ecahd_core.errors import EcahdError
from ecahd_core.placement import LEG_BATCHES

# of each batch's candidates whose first leg crosses a wall as sampled, how many SD's
# free-first-leg rule (SparseConfig.leg_batches) sends through placement and repair (tens of ms
# each): on office 2's 32 development plans 0 left 11 colliding, 2 left 4, 4 left 7
LEG_REPAIRS = 2
GENERAL_SAMPLE_STEPS = 10  # DDIM steps of the generalist SD (the per-map SD's recipe)
# SparseConfig.warm_fraction -1 ("by the map"): where the placer and the free-first-leg rule act
# (building maps), re-plans start warm from the plan before at this share of the schedule, and
# one whose first leg still crosses a wall is drawn again from noise (rules.SparseStage). The
# generalist on 9 held-out buildings, 324 plans (docs/RESULTS.md): offices' ECAHD alone 95.4% ->
# 96.3% on average, A* fallback 8.3 / 0 / 0% -> 5.6 / 0 / 0%, medians 1.2-2.1x lower;
# warehouses and depots 100% both ways, medians 1.2-2.3x lower, p95 1.9-4.1x lower.
# Elsewhere (maze2d-large): 0, the paper's.
AUTO_WARM_FRACTION = 0.3
SELECTION_RULES = ("shortest_reaching", "collision_aware")


@dataclass(frozen=True, kw_only=True)
class SparseConfig:
    """Settings of the Sparse Diffusion global planner.

    Attributes:
        num_candidates: I, candidates sampled in one batch (isSearchEnabled when > 1).
        horizon: P^g, waypoints of a global plan.
        epsilon: [m] goal-reaching radius of the selection rule (paper: 1.0).
        selection: one of SELECTION_RULES. "shortest_reaching" (Sec. III-A's rule, Algorithm 1
            line 10) here, as it needs no cost J; the commands and nodes default to
            "collision_aware" (it needs J): the paper's Table III runs select "the trajectory
            with the highest score based on the diffusion prediction and cost function"
            (Sec. IV-C), and with polishing it raised HD's collision-free share on 32 held-out
            problems from 93.8% to 100% for the quadruped (docs/RESULTS.md).
        collision_tolerance: slack on the collision cost for ``collision_aware``.
        num_steps: DDIM steps (None: the checkpoint's).
        eta: DDIM eta. 1.0 (stochastic, DDPM-like) by default: on 128 held-out problems the
            shipped SD's single unguided samples were collision-free for a point robot 87.5% of
            the time with eta 1 vs 82.8% with eta 0 at 10 steps (docs/RESULTS.md).
        guidance: guide SD itself by J towards G (the "SD with guidance" baseline of Table I;
            ECAHD leaves SD unguided).
        guidance_weight: omega when ``guidance``.
        max_spacing: [m] waypoint spacing by distance (ours, beyond the paper; None: off, the
            paper's fixed P^g). After the best of N is chosen, every leg longer than this is
            re-sampled by SD itself between its two waypoints (start and goal of the leg
            inpainted, best of N again, one batch per horizon) with
            ceil(length / max_spacing) + 1 <= P^g waypoints, up to ``densify_rounds`` times,
            so a long plan on a big map keeps its waypoints a few metres apart and each local
            segment stays within what DD learnt. The plan then has more than ``horizon``
            waypoints.
        densify_rounds: rounds of that re-sampling (a leg may still be long after the last).
        warm_fraction: warm-started re-planning (ours, beyond the paper): a re-plan
            (:meth:`SparseDiffusion.replan`; HierarchicalPlanner's ``every_waypoint`` loop) starts
            from the rest of the previous plan, noised to the DDIM step where the last
            ``warm_fraction`` (0..1) of the schedule begins, and runs only those steps
            (diffusion.sampler, "Warm start"). 0: off, every plan samples from noise (Algorithm
            1 as written). A goal's first plan always samples from noise. -1: by the map
            (:attr:`SparseDiffusion.warm_fraction`: AUTO_WARM_FRACTION where the ``placer`` and
            the free-first-leg rule act, i.e. building maps; else 0).
        precision: "fp32", "bf16" or "auto" (bf16 where the CPU computes it natively): the
            SD Transformer's inference precision (``SamplerConfig.precision``; ours).
        leg_batches: a free first leg (ours, beyond the paper; needs the ``placer``, and acts on
            re-plans whose caller follows only the first leg, ``repair_legs`` 1, as Algorithm
            1's every_waypoint loop does). When the selected candidate's first leg, after
            placement and leg repair, still passes nearer a wall than the footprint fits, the
            other candidates are tried in the rule's order and the first whose first leg is
            free is taken; if none is, up to ``leg_batches`` more batches of N are drawn, each
            with one waypoint more than the last up to the model's longest horizon (a straight
            last leg into the next room becomes a plan with a waypoint to place in the door).
            0: only the first batch's other candidates; -1: off (the selected candidate, as the
            paper).
    """

    num_candidates: int = 10
    horizon: int = 10
    epsilon: float = 1.0
    selection: str = "shortest_reaching"
    collision_tolerance: float = 0.1
    num_steps: int | None = None
    eta: float = 1.0
    guidance: bool = False
    guidance_weight: float = 1.0
    guidance_space: str = "eps"
    max_spacing: float | None = None
    densify_rounds: int = 2
    warm_fraction: float = 0.0
    precision: str = "fp32"
    leg_batches: int = LEG_BATCHES

    def __post_init__(self) -> None:
        if self.leg_batches < -1:
            raise EcahdError(f"leg_batches must be >= -1 (-1: off), got {self.leg_batches}")
        if self.max_spacing is not None and not (np.isfinite(self.max_spacing)
                                                 and self.max_spacing > 0):
            raise EcahdError(f"max_spacing must be None (off) or a finite number > 0 m, "
                             f"got {self.max_spacing}")
        if self.densify_rounds < 0:
            raise EcahdError(f"densify_rounds must be >= 0, got {self.densify_rounds}")
        if not (0.0 <= self.warm_fraction <= 1.0 or self.warm_fraction == -1):
            raise EcahdError(f"warm_fraction must lie in 0..1 (0: off) or be -1 (by the map), "
                             f"got {self.warm_fraction}")
        if self.selection not in SELECTION_RULES:
            raise EcahdError(f"selection rule {self.selection!r} is not one of "
                             f"{list(SELECTION_RULES)}")
        if self.num_candidates < 1 or self.horizon < 2:
            raise EcahdError(f"need num_candidates >= 1 and horizon >= 2, got "
                             f"{self.num_candidates}, {self.horizon}")
        if not self.epsilon > 0:
            raise EcahdError(f"epsilon must be > 0 m, got {self.epsilon}")


def path_lengths(traj: np.ndarray) -> np.ndarray:
    """(N, P, 2) -> (N,) polyline lengths L(t) [m]."""
    return np.linalg.norm(np.diff(traj, axis=1), axis=-1).sum(-1)


def select_best(candidates: np.ndarray, goal: np.ndarray, *, epsilon: float = 1.0,
                rule: str = "shortest_reaching", collision_costs: np.ndarray | None = None,
                collision_tolerance: float = 0.1) -> int:
    """Index of the best of N candidates. candidates: (N, P, 2) [m]; goal: (2,) [m];
    collision_costs: (N,) (needed by ``collision_aware``)."""
    if rule not in SELECTION_RULES:
        raise EcahdError(f"selection rule {rule!r} is not one of {list(SELECTION_RULES)}")
    candidates = np.asarray(candidates, dtype=np.float64)
    N = candidates.shape[0]
    keep = np.ones(N, dtype=bool)
    if rule == "collision_aware":
        if collision_costs is None:
            raise EcahdError("the collision_aware rule needs the candidates' collision costs")
        c = np.asarray(collision_costs, dtype=np.float64)
        keep = c <= c.min() + collision_tolerance
    lengths = path_lengths(candidates)
    reach = np.linalg.norm(candidates - np.asarray(goal)[None, None], axis=-1).min(-1) < epsilon
    pool = keep & reach if np.any(keep & reach) else keep
    idx = np.flatnonzero(pool)
    return int(idx[np.argmin(lengths[idx])])


def rank_candidates(candidates: np.ndarray, goal: np.ndarray, *, epsilon: float = 1.0,
                    rule: str = "shortest_reaching", collision_costs: np.ndarray | None = None,
                    collision_tolerance: float = 0.1) -> list[int]:
    """All N candidates (N, P, 2) [m], best first: :func:`select_best`'s choice, then the rest
    by collision cost (``collision_aware``; none under the paper's rule), then length."""
    first = select_best(candidates, goal, epsilon=epsilon, rule=rule,
                        collision_costs=collision_costs, collision_tolerance=collision_tolerance)
    lengths = path_lengths(np.asarray(candidates, dtype=np.float64))
    keys = (lengths,) if rule != "collision_aware" else (lengths, np.asarray(collision_costs))
    rest = [int(k) for k in np.lexsort(keys) if k != first]
    return [first] + rest


@dataclass(frozen=True)
class SparsePlan:
    """Attributes:
        waypoints: (P, 2) [m] the selected global plan t^g.
        candidates: (N, P, 2) [m] all sampled candidates.
        best: index of the selected candidate.
        collision_costs: (N,) J collision cost of each candidate (None if not computed).
        time_ms: sampling + selection wall time.
        placed: waypoints moved out of walls by the SparseDiffusion's ``placer`` (ours).
        first_leg: what SparseConfig.leg_batches's rule did (ours): "" (it did not act: the
            selected candidate's first leg was free, or the rule is off), "other" (another
            candidate of the batch), "batch" (a candidate of a further batch, whose
            ``candidates`` these are), "none" (no candidate's first leg was free; the selected
            one stays); ``SparseStage`` adds "cold" (a warm re-plan's first leg crossed a wall:
            drawn again from noise, whose selected first leg was free).
        warm: the candidates were warm-started from the plan before (``warm_fraction``).
    """

    waypoints: np.ndarray
    candidates: np.ndarray
    best: int
    collision_costs: np.ndarray | None
    time_ms: float
    placed: int = 0
    first_leg: str = ""
    warm: bool = False


class SparseDiffusion:
    """SparseDiffusion of Algorithm 1 (lines 2-11): N candidates in one batch, best of N.

    Args:
        checkpoint: a loaded SD checkpoint (``model_zoo.load_model("sd", ...)``).
        config: SparseConfig.
        cost: J's :class:`~ecahd_core.cost.CollisionCost` for the collision_aware rule and for
            guidance (optional otherwise).
        device: where the model runs.
        placer: a :class:`~ecahd_core.placement.WaypointPlacer` (ours, beyond the paper):
            the selected plan's waypoints that lie in a wall move to free space and legs that
            cross a wall get a placed midpoint, before the plan is returned (and after
            ``densify``); the start and goal stay.
            None: SD's waypoints as sampled (the paper).
    """

    def __init__(self, checkpoint, config: SparseConfig | None = None, *, cost=None,
                 device: str = "cpu", placer=None, grid=None) -> None:
        from ecahd_core.diffusion import DiffusionSampler, SamplerConfig
        from ecahd_core.general.checkpoint import GeneralCheckpoint
        from ecahd_core.model_zoo import sample_steps

        self.config = config or SparseConfig()
        general = isinstance(checkpoint, GeneralCheckpoint)
        steps = self.config.num_steps or (GENERAL_SAMPLE_STEPS if general
                                          else sample_steps(checkpoint))
        sampling = SamplerConfig(num_steps=steps, eta=self.config.eta,
                                 guidance_weight=self.config.guidance_weight,
                                 guidance_space=self.config.guidance_space,
                                 precision=self.config.precision)
        if general:  # the generalist sees the map: views of ``grid`` round each problem
            from ecahd_core.general.sampler import GeneralSampler

            if grid is None:
                raise EcahdError("the generalist SD plans on a map: pass its grid")
            self.sampler = GeneralSampler(checkpoint, grid, device=device, config=sampling)
        else:
            self.sampler = DiffusionSampler.from_checkpoint(checkpoint, device=device,
                                                            config=sampling)
        self.general = general
        if cost is None and (self.config.guidance or self.config.selection == "collision_aware"):
            raise EcahdError("SD guidance and the collision_aware rule need the cost J "
                             "(a CollisionCost)")
        self.cost = cost
        self.placer = placer
        # [m] the median spacing of the expert waypoints the model learnt (None: not recorded,
        # checkpoints before 2026-12-03)
        spacing = None if general else checkpoint.meta.get("expert_spacing")
        self.expert_spacing = float(spacing) if spacing else None

    def plan(self, start, goal, *, horizon: int | None = None,
             generator: torch.Generator | None = None, warm_start=None,
             warm_fraction: float | None = None, densify: bool = True,
             repair_legs: int | None = None) -> SparsePlan:
        """start, goal: (2,) [m] -> SparsePlan with waypoints (horizon, 2) from start to goal
        (more than ``horizon`` when the ``placer``'s leg repair bends a leg, also a
        horizon-2 plan's one leg, or when ``config.max_spacing`` is set; see :meth:`densify`).
        ``densify`` False: no densify, and a horizon-2 plan stays the straight (start, goal)
        (HierarchicalPlanner's forced last plan). ``repair_legs``: leg repair on the first
        this many legs only (None: all; ignored with ``config.max_spacing``): a re-plan whose
        caller follows only its first leg gets that leg as it would with all repaired.

        ``warm_start`` (horizon, 2) [m]: start the N candidates from this trajectory (its ends are
        replaced by start and goal) noised to the last ``warm_fraction`` of the DDIM schedule
        (default ``config.warm_fraction``) instead of from noise; see :meth:`replan`."""
        cfg = self.config
        horizon = horizon or cfg.horizon
        if warm_start is not None:
            warm_fraction = self.warm_fraction if warm_fraction is None else warm_fraction
            if not 0.0 < warm_fraction <= 1.0:
                raise EcahdError(f"a warm start needs 0 < warm_fraction <= 1 (here or in "
                                 f"SparseConfig; 0 is off), got {warm_fraction}")
            warm_start = np.asarray(warm_start, dtype=np.float32)
            if warm_start.shape != (horizon, 2):
                raise EcahdError(f"warm_start must have shape ({horizon}, 2) [m], "
                                 f"got {warm_start.shape}")
        else:
            warm_fraction = None
        t0 = time.perf_counter()
        start_t = torch.as_tensor(np.asarray(start, dtype=np.float32), device=self.sampler.device)
        goal_t = torch.as_tensor(np.asarray(goal, dtype=np.float32), device=self.sampler.device)
        if horizon <= 2:
            cands = torch.stack([start_t, goal_t])[None].expand(cfg.num_candidates, 2, 2)
        else:
            guide = None
            if cfg.guidance:
                from ecahd_core.guidance import CostJGuide

                guide = CostJGuide.of(self.cost, goal_t)
            cands = self.sampler.sample(batch=cfg.num_candidates, horizon=horizon,
                                        conditions={0: start_t, -1: goal_t},
                                        generator=generator, guide=guide,
                                        warm_start=warm_start,
                                        warm_fraction=warm_fraction).trajectories
        col = self._collision_costs(cands, goal_t)
        cands_np = cands.detach().cpu().numpy().astype(np.float64)
        best = select_best(cands_np, np.asarray(goal, dtype=np.float64), epsilon=cfg.epsilon,
                           rule=cfg.selection, collision_costs=col,
                           collision_tolerance=cfg.collision_tolerance)
        # a straight (start, goal) plan is one leg: leg repair may bend it, unless this is a
        # forced last plan (``densify`` False), which must reach the goal as it is
        legs = repair_legs if cfg.max_spacing is None else None
        waypoints, placed = (self._place(cands_np[best], legs=legs) if densify or horizon > 2
                             else (cands_np[best], 0))
        first_leg = ""
        if (densify and legs == 1 and cfg.leg_batches >= 0 and self.placer is not None
                and self.leg_blocked(waypoints)):
            found = self._free_first_leg(cands_np, col, best, start_t, goal_t, horizon,
                                         generator)
            first_leg = "none"
            if found is not None:
                first_leg = "other" if found[0] is cands_np else "batch"
                cands_np, col, best, waypoints, placed = found
        if densify and cfg.max_spacing is not None:
            waypoints, more = self._place(self.densify(waypoints, generator=generator))
            placed += more
        return SparsePlan(waypoints=waypoints, candidates=cands_np, best=best,
                          collision_costs=col, time_ms=(time.perf_counter() - t0) * 1e3,
                          placed=placed, first_leg=first_leg, warm=warm_start is not None)

    @classmethod
    def for_map(cls, grid, footprint, config: SparseConfig | None = None, *, cost=None,
                place_reach: float | None = None, model: str | None = None,
                device: str = "cpu") -> "SparseDiffusion":
        """SD on ``grid`` for ``footprint`` as the commands and benchmarks build it: the map's
        model (``model``: a checkpoint path, per-map or generalist; "general": the shipped
        generalist; None: the map's shipped one or one on $ECAHD_MODELS),
        J's ``cost`` (a CollisionCost; None: built with the map's margin) and the placer of
        ``place_reach`` [m] (None: by the map and the model, ``placement.placer_for``; 0:
        off)."""
        from ecahd_core.cost import CollisionCost
        from ecahd_core.general.checkpoint import GeneralCheckpoint
        from ecahd_core.model_zoo import load_sd
        from ecahd_core.placement import placer_for

        config = config or SparseConfig()
        if cost is None:
            cost = CollisionCost.build(grid, footprint)
        ckpt = load_sd(grid, path=model, footprint=footprint, horizon=config.horizon,
                       device=device)
        return cls(ckpt, config, cost=cost, device=device,
                   placer=placer_for(grid, footprint, place_reach,
                                     general=isinstance(ckpt, GeneralCheckpoint)), grid=grid)

    def on(self, *, cost=None, placer=None) -> "SparseDiffusion":
        """A view of this SD (the same model, sampler and settings) that weighs candidates by
        ``cost`` (J's CollisionCost) and places waypoints with
        ``placer``, where given: e.g. the static map fused with the obstacles the scans found.
        The view is cheap (a shallow copy) and leaves this SD as it is."""
        view = copy.copy(self)
        if cost is not None:
            view.cost = cost
        if placer is not None:
            view.placer = placer
        return view

    def warm_up(self, xy, *, horizon: int | None = None) -> float:
        """One throwaway plan from ``xy`` (2,) [m] to itself with its own generator, so that the
        first real plan does not pay torch's first-call costs (kernel set-up, bfloat16 weight
        copies, J's first sweep). Returns its wall time [ms]."""
        t0 = time.perf_counter()
        self.plan(xy, xy, horizon=horizon, generator=torch.Generator().manual_seed(0),
                  densify=False)
        return (time.perf_counter() - t0) * 1e3

    def _place(self, waypoints: np.ndarray, *, legs: int | None = None
               ) -> tuple[np.ndarray, int]:
        """(P, 2) [m] -> (waypoints with those in a wall moved by ``placer`` and legs crossing a
        wall bent (the first ``legs`` legs; None: all), how many moved or added); unchanged
        without a placer."""
        if self.placer is None or len(waypoints) < 2:
            return waypoints, 0
        return self.placer(waypoints, legs=legs)

    @property
    def warm_fraction(self) -> float:
        """The warm starts' share of the DDIM schedule in effect: ``config.warm_fraction``, or
        with -1 (by the map) AUTO_WARM_FRACTION where the ``placer`` is on and
        ``leg_batches`` >= 0 (building maps), else 0."""
        f = self.config.warm_fraction
        if f >= 0:
            return float(f)
        return AUTO_WARM_FRACTION if (self.placer is not None
                                      and self.config.leg_batches >= 0) else 0.0

    def leg_blocked(self, waypoints: np.ndarray) -> bool:
        """Whether the first leg of ``waypoints`` (P, 2) [m] passes nearer a wall than the
        footprint fits (the placer's ``wall_length`` > 0)."""
        return bool(self.placer.leg_walls(waypoints[:2])[0] > 0)

    def _free_first_leg(self, cands: np.ndarray, col: np.ndarray | None, best: int,
                        start: torch.Tensor, goal: torch.Tensor, horizon: int,
                        generator: torch.Generator | None):
        """SparseConfig.leg_batches: the first candidate, in the rule's order, whose first leg
        after placement and repair is free; from ``cands`` (N, horizon, 2) [m] (``best``
        already tried), then from up to ``leg_batches`` more batches of one waypoint more each.
        Returns (candidates, collision costs, index, placed waypoints, moved) of the batch it
        came from, or None."""
        cfg = self.config
        goal_np = goal.detach().cpu().numpy().astype(np.float64)
        tried = {best}
        # a horizon-2 batch is N copies of the straight leg, already tried
        for extra in range(1 if horizon <= 2 else 0, cfg.leg_batches + 1):
            if extra:
                horizon = min(horizon + 1, self.sampler.model.config.max_horizon)
                cands_t = self.sampler.sample(batch=cfg.num_candidates, horizon=horizon,
                                              conditions={0: start, -1: goal},
                                              generator=generator).trajectories
                col = self._collision_costs(cands_t, goal)
                cands = cands_t.detach().cpu().numpy().astype(np.float64)
                tried = set()
            order = [k for k in rank_candidates(cands, goal_np, epsilon=cfg.epsilon,
                                                rule=cfg.selection, collision_costs=col,
                                                collision_tolerance=cfg.collision_tolerance)
                     if k not in tried]
            # first the candidates whose first leg is free as sampled (one vectorised check),
            # then the best few through placement and repair (a repair costs tens of ms)
            straight = self.placer.wall_length(cands[order, 0], cands[order, 1]) == 0
            order = ([k for k, ok in zip(order, straight) if ok]
                     + [k for k, ok in zip(order, straight) if not ok][:LEG_REPAIRS])
            for k in order:
                # the first leg depends on the first three waypoints only (placement scores a
                # waypoint by its legs to both neighbours; repair bends the first leg alone)
                head, _ = self._place(cands[k, :3], legs=1)
                if not self.leg_blocked(head):
                    waypoints, placed = self._place(cands[k], legs=1)
                    return cands, col, k, waypoints, placed
        return None

    def _collision_costs(self, cands: torch.Tensor, goals: torch.Tensor) -> np.ndarray | None:
        """J's collision cost of candidates (B, P, 2) [m] towards goals (2,) or (B, 2) -> (B,),
        for the collision_aware rule (None under the paper's rule)."""
        if self.config.selection != "collision_aware":
            return None
        from ecahd_core.cost import trajectory_cost

        cost = self.cost
        with torch.no_grad():
            col = trajectory_cost(cands.to(cost.costmap.dtype), goals.to(cost.costmap.dtype),
                                  cost.footprint_points, cost.costmap,
                                  **cost.config.cost_kwargs()).collision_cost
        return col.cpu().numpy()

    def _candidates(self, starts: torch.Tensor, goals: torch.Tensor, horizon: int,
                    generator: torch.Generator | None) -> np.ndarray:
        """The best of N unguided SD samples for each of K legs, in one batch.
        starts, goals: (K, 2) [m] -> (K, horizon, 2) [m] float64."""
        cfg, K, N = self.config, starts.shape[0], self.config.num_candidates
        a = starts.repeat_interleave(N, dim=0)  # (K*N, 2)
        b = goals.repeat_interleave(N, dim=0)
        cands = self.sampler.sample(batch=K * N, horizon=horizon, conditions={0: a, -1: b},
                                    generator=generator).trajectories  # (K*N, h, 2)
        col = self._collision_costs(cands, b)
        col = None if col is None else col.reshape(K, N)
        cands_np = cands.detach().cpu().numpy().astype(np.float64).reshape(K, N, horizon, 2)
        goals_np = goals.cpu().numpy().astype(np.float64)
        out = np.empty((K, horizon, 2))
        for k in range(K):
            best = select_best(cands_np[k], goals_np[k], epsilon=cfg.epsilon,
                               rule=cfg.selection,
                               collision_costs=None if col is None else col[k],
                               collision_tolerance=cfg.collision_tolerance)
            out[k] = cands_np[k, best]
        return out

    def densify(self, waypoints, *, generator: torch.Generator | None = None) -> np.ndarray:
        """Waypoint spacing by distance (``config.max_spacing``, ours): every leg of
        ``waypoints`` (P, 2) [m] longer than max_spacing is replaced by SD's best of N between
        its two ends with ceil(length / max_spacing) + 1 (at most P^g) waypoints; legs of one
        horizon are sampled in one batch; up to ``config.densify_rounds`` rounds.
        Returns (P', 2) [m], P' >= P, with the same first and last waypoint."""
        cfg = self.config
        wp = np.asarray(waypoints, dtype=np.float64)
        if cfg.max_spacing is None:
            return wp
        for _ in range(cfg.densify_rounds):
            lengths = np.linalg.norm(np.diff(wp, axis=0), axis=-1)
            want = np.minimum(cfg.horizon, np.ceil(lengths / cfg.max_spacing - 1e-9) + 1
                              ).astype(int)
            long = np.flatnonzero(want > 2)
            if len(long) == 0:
                break
            legs: dict[int, np.ndarray] = {}
            for h in np.unique(want[long]):
                idx = long[want[long] == h]
                legs.update(zip(idx.tolist(), self._candidates(
                    torch.as_tensor(wp[idx], dtype=torch.float32),
                    torch.as_tensor(wp[idx + 1], dtype=torch.float32), int(h), generator)))
            pieces = [wp[:1]]
            for k in range(len(wp) - 1):
                leg = legs.get(k)
                pieces.append(wp[k + 1:k + 2] if leg is None else leg[1:])
            out = np.concatenate(pieces)
            out[0], out[-1] = wp[0], wp[-1]  # exact ends (the model works in float32)
            wp = out
        return wp

    def replan(self, start, goal, previous=None, *, horizon: int | None = None,
               generator: torch.Generator | None = None, densify: bool = True,
               repair_legs: int | None = None) -> SparsePlan:
        """Re-plan from ``start`` (2,) [m] to ``goal`` (2,) [m] while following ``previous``
        (P, 2) [m], the current plan (None: no plan yet).

        With warm starts on (:attr:`warm_fraction` > 0) and ``previous`` at least
        ``horizon`` long, the candidates start from its last ``horizon`` waypoints with the
        first replaced by ``start`` (Algorithm 1's P^g - p remaining waypoints after reaching
        waypoint p; the whole plan after a timeout), see :meth:`plan`. Otherwise this is
        :meth:`plan` from noise, bit for bit."""
        horizon = horizon or self.config.horizon
        return self.plan(start, goal, horizon=horizon, generator=generator,
                         warm_start=self.warm_start_for(start, previous, horizon),
                         densify=densify, repair_legs=repair_legs)

    def warm_start_for(self, start, previous, horizon: int) -> np.ndarray | None:
        """The warm start of a re-plan of ``horizon`` waypoints from ``start`` (2,) [m] while
        following ``previous`` (P, 2) [m] (None: no plan yet): its last ``horizon`` waypoints
        with the first replaced by ``start``, (horizon, 2) [m]; None where the re-plan samples
        from noise (warm starts off, no plan, a plan shorter than ``horizon``, horizon 2)."""
        if not (self.warm_fraction > 0 and previous is not None and horizon > 2):
            return None
        previous = np.asarray(previous, dtype=np.float64).reshape(-1, 2)
        if len(previous) < horizon:
            return None
        warm = previous[len(previous) - horizon:].copy()
        warm[0] = np.asarray(start, dtype=np.float64).reshape(2)
        return warm
