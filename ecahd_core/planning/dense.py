"""The local stage of Algorithm 1 (paper Sec. III-A lines 13-18) with Algorithm 2's Dense
Diffusion: for each segment of a global plan, the straight local plan, its collision cost c^l by
J, DD guided by J when c^l > c_th, and our rules after it (keep-better, polishing, the exact rule).
:class:`DenseStage` is used by the offline planner
(:class:`~ecahd_core.planning.hierarchical.HierarchicalPlanner`, all iterations in one batch),
by local_refiner (:class:`~ecahd_core.planning.local.SegmentRefiner`, one segment at a time) and
by the safety net (:meth:`DenseStage.resample_segment`)."""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import torch

from ecahd_core.errors import EcahdError


@dataclass(frozen=True, kw_only=True)
class DenseConfig:
    """Settings of the local stage (Algorithm 1 lines 13-18, Algorithm 2).

    Attributes:
        points: P^l, points of a local plan (endpoints included). None: the P^l the DD
            checkpoint learnt (:func:`~ecahd_core.model_zoo.dense_points`; 4, the paper's 2
            interior points, for every model ``train-all`` makes; another with
            ``ecahd dataset --dense-points N``), and ``DEFAULT_DENSE_POINTS`` without DD.
        c_th: DD runs when the straight local plan's collision cost exceeds this.
        enabled: run DD at all (False: follow the straight local plans, "w/o DD").
        guidance: guide DD by J (ECAHD) or not (HD without guidance).
        guidance_weight: omega of Algorithm 2 line 5 at J's 0.1 m cost-map margin. The paper
            leaves it open; 0.03 in "x0" space was the best of {0.01, 0.03, 0.1} and of
            "eps"-space omega 1 on 64 held-out problems (docs/RESULTS.md, "Guidance
            strength"). With a wider margin m (a building's 0.5 m) the HierarchicalPlanner
            guides DD by omega x 0.1 m / m (:func:`guidance_weight_for`).
        num_steps: DDIM steps (None: the checkpoint's).
        eta: DDIM eta.
        retries: our safety rule, beyond the paper: when the refined segment's collision cost
            is still above c_th, sample DD again (up to this many times) and keep the segment
            of lowest cost. 0 is the paper's behaviour.
        guide_last: guide only the last this-many DDIM steps (None: every step, as Alg. 2).
        max_guide_norm: cap of the per-waypoint guidance gradient (see diffusion.sampler).
        guidance_space: "eps" (Algorithm 2 as written) or "x0" (J at the clean estimate,
            step-dependent weight; see diffusion.sampler.sample).
        polish_steps: our second safety rule, beyond the paper: when a local plan's collision
            cost is still above c_th after DD, descend J's collision cost over its points for
            up to this many steps (ecahd_core.polish; the start and the final goal stay fixed,
            an intermediate waypoint may move). 0 is the paper's behaviour.
        polish_step_size: [m] the largest point move per polishing step.
        polish_across: polishing moves points only across the path (PolishConfig.across);
            False: along it too (the earlier behaviour, which let local plans double back).
        keep_better: our third rule, beyond the paper: when DD's plan costs more by J than the
            straight local plan it was asked to improve (DD can overshoot), keep the straight
            plan (polishing then starts from it). False is the paper's behaviour.
    """

    points: int | None = None
    c_th: float = 0.1
    enabled: bool = True
    guidance: bool = True
    guidance_weight: float = 0.03
    num_steps: int | None = None
    eta: float = 0.0
    retries: int = 0
    guide_last: int | None = None
    max_guide_norm: float | None = 1.0
    guidance_space: str = "x0"
    polish_steps: int = 30
    polish_step_size: float = 0.05
    polish_across: bool = True
    keep_better: bool = True

    def __post_init__(self) -> None:
        self.polish_config()  # validates the polishing settings
        if self.points is not None and self.points < 2:
            raise EcahdError(f"a local plan needs points >= 2 (P^l), got {self.points}")

    def polish_config(self):
        from ecahd_core.polish import PolishConfig

        return PolishConfig(steps=self.polish_steps, step_size=self.polish_step_size,
                            across=self.polish_across)


@dataclass(frozen=True)
class LocalStage:
    """One segment's local stage (:meth:`HierarchicalPlanner.local_stage`).

    Attributes:
        plan: (P^l, 2) [m] float32, the local plan to follow.
        c_before, c_after: c^l of the straight plan, and of ``plan``.
        dd_used: DD ran (c_before > c_th).
        polished: polishing ran.
        timings_ms: wall time of "j_check", "dd" and "polish".
    """

    plan: torch.Tensor
    c_before: float
    c_after: float
    dd_used: bool
    polished: bool
    timings_ms: dict


@dataclass(frozen=True)
class LocalStages:
    """The local stage of K segments (:meth:`HierarchicalPlanner.local_stages`).

    Attributes:
        plans: (K, P^l, 2) [m] float32, the local plans to follow.
        c_before, c_after: (K,) c^l of the straight plans, and of ``plans``.
        dd_used: (K,) bool, DD ran (c_before > c_th).
        polished: (K,) bool, polishing ran on the plan (``joined``: moved it).
        timings_ms: the batch's wall time of "j_check", "dd", "polish" and "exact".
        exact_kept: (K,) bool, the exact rule put back the straight or unpolished DD plan.
    """

    plans: torch.Tensor
    c_before: torch.Tensor
    c_after: torch.Tensor
    dd_used: torch.Tensor
    polished: torch.Tensor
    timings_ms: dict
    exact_kept: torch.Tensor





def guidance_weight_for(omega: float, margin: float) -> float:
    """DD's guidance weight on a cost map of ``margin`` [m]: ``omega`` (chosen at the 0.1 m
    margin of the paper's tables) x DEFAULT_MARGIN / margin (ours). With a 0.5 m margin nearly
    every DD segment in a building's aisle lies in J's cost zone, and omega 0.03 bent them:
    plans 7-11% longer than unguided DD's on warehouse 2, none more collision-free; omega 0.006
    (this rule) gave unguided DD's lengths, 2-5% over A* (docs/RESULTS.md, 2026-12-03)."""
    from ecahd_core.costmap import DEFAULT_MARGIN

    return float(omega) * DEFAULT_MARGIN / float(margin)


class DenseStage:
    """Algorithm 1's local stage (lines 13-18) with DD (Algorithm 2) and our rules.

    Args:
        dense_checkpoint: the DD checkpoint (None when ``dense.enabled`` is False).
        costmap, footprint_points, cost_config: the cost J (Algorithm 2 lines 11-25).
        dense: DenseConfig.
        exact_check: the exact rule (ours; None: off, the paper's). A function of a path
            (N, 2) [m] float64 giving (N - 1,) bool, its segments that collide:
            ``collision.exact_check_for(grid, footprint)``.
            J (with its margin) only triggers DD and polishing; when the exact checker finds a
            refined local plan in collision, the unpolished DD plan or else the straight one
            is put back where the checker finds it free (its points then stay fixed while the
            rest is polished again). Plans the checker finds free are never touched.
    """

    def __init__(self, dense_checkpoint, *, costmap, footprint_points, cost_config=None,
                 dense: DenseConfig | None = None, device: str = "cpu",
                 exact_check=None) -> None:
        from ecahd_core.cost import CostConfig
        from ecahd_core.diffusion import DiffusionSampler, SamplerConfig
        from ecahd_core.model_zoo import DEFAULT_DENSE_POINTS, dense_points, sample_steps

        self.exact_check = exact_check
        self.dense = dense or DenseConfig()
        if self.dense.points is None:  # P^l: the DD checkpoint's
            self.dense = replace(self.dense, points=(
                dense_points(dense_checkpoint) if self.dense.enabled else DEFAULT_DENSE_POINTS))
        elif self.dense.enabled and self.dense.points not in dense_checkpoint.horizons:
            raise EcahdError(f"DenseConfig.points = {self.dense.points}, but the DD checkpoint "
                             f"learnt P^l in {list(dense_checkpoint.horizons)}")
        self.cost_config = cost_config or CostConfig()
        self.costmap = costmap
        self.footprint_points = torch.as_tensor(footprint_points, dtype=costmap.dtype,
                                                device=costmap.device)
        self.dd = None
        if self.dense.enabled:
            steps = self.dense.num_steps or sample_steps(dense_checkpoint)
            from ecahd_core.general.segment_dd import SegmentSampler, is_segment_frame

            sampler = SegmentSampler if is_segment_frame(dense_checkpoint) else DiffusionSampler
            self.dd = sampler.from_checkpoint(
                dense_checkpoint, device=device, config=SamplerConfig(
                    num_steps=steps, eta=self.dense.eta,
                    guidance_weight=guidance_weight_for(self.dense.guidance_weight,
                                                        self.cost_config.margin),
                    guide_last=self.dense.guide_last, max_guide_norm=self.dense.max_guide_norm,
                    guidance_space=self.dense.guidance_space))

    def local_cost(self, segments: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        """J's collision cost c^l of local plans. segments: (B, P^l, 2), goals: (B, 2) -> (B,)."""
        return self.local_terms(segments, goals).collision_cost

    def local_terms(self, segments: torch.Tensor, goals: torch.Tensor):
        """J of local plans (CostTerms: c^l, and the peak, the highest cost map value the
        swept footprint reads). segments: (B, P^l, 2), goals: (B, 2) -> (B,) each."""
        from ecahd_core.cost import trajectory_cost

        with torch.no_grad():
            return trajectory_cost(segments.to(self.costmap.dtype), goals.to(self.costmap.dtype),
                                   self.footprint_points, self.costmap,
                                   **self.cost_config.cost_kwargs())

    def refine(self, starts: torch.Tensor, goals: torch.Tensor, *,
               generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """DenseDiffusion (Algorithm 2 lines 1-9) for K segments in one batch, with the optional
        retry rule. starts, goals: (K, 2) [m] -> (segments (K, P^l, 2), collision costs (K,))."""
        from ecahd_core.guidance import CostJGuide

        K = starts.shape[0]
        best = torch.zeros(K, self.dense.points, 2)
        best_cost = torch.full((K,), float("inf"))
        todo = torch.arange(K)
        for _ in range(1 + max(0, self.dense.retries)):
            a, b = starts[todo], goals[todo]
            guide = (CostJGuide(self.costmap, self.footprint_points, b, self.cost_config)
                     if self.dense.guidance else None)
            seg = self.dd.sample(batch=len(todo), horizon=self.dense.points,
                                 conditions={0: a, -1: b}, generator=generator,
                                 guide=guide).trajectories
            cost = self.local_cost(seg, b).float().cpu()
            better = cost < best_cost[todo]
            best[todo[better]] = seg[better].float().cpu()
            best_cost[todo[better]] = cost[better]
            todo = todo[best_cost[todo] > self.dense.c_th]
            if len(todo) == 0:
                break
        return best, best_cost

    def polish(self, paths: torch.Tensor, fixed: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Our safety rule (DenseConfig.polish_steps): descend J's collision cost.
        paths: (B, P, 2) [m], fixed: (P,) or (B, P) bool -> (paths (B, P, 2), costs (B,)),
        float32 on the CPU."""
        from ecahd_core.polish import polish_paths

        out, cost = polish_paths(paths, fixed, self.costmap, self.footprint_points,
                                 self.cost_config, self.dense.polish_config())
        return out.float().cpu(), cost.float().cpu()

    @property
    def polishing(self) -> bool:
        """Whether the polishing rule is on (it follows DD: off when DD is disabled)."""
        return self.dd is not None and self.dense.polish_steps > 0

    def local_stage(self, a: torch.Tensor, b: torch.Tensor, *, end_fixed: bool = True,
                    generator: torch.Generator | None = None) -> LocalStage:
        """:meth:`local_stages` for one segment. a, b: (2,) [m] float32 -> LocalStage."""
        stages = self.local_stages(a[None], b[None], end_fixed=torch.tensor([end_fixed]),
                                   generator=generator)
        return LocalStage(plan=stages.plans[0], c_before=float(stages.c_before[0]),
                          c_after=float(stages.c_after[0]), dd_used=bool(stages.dd_used[0]),
                          polished=bool(stages.polished[0]), timings_ms=stages.timings_ms)

    def local_stages(self, a: torch.Tensor, b: torch.Tensor, *, end_fixed: torch.Tensor,
                     joined: bool = False, generator: torch.Generator | None = None
                     ) -> LocalStages:
        """Algorithm 1 lines 13-18 for K segments in one batch, with our rules: the straight
        LocalPlan(a, b) of P^l points, its collision cost c^l, DD when c^l > c_th (all such
        segments in one DD batch; keep-better: DD's plan only if J finds it no costlier),
        polishing while still above c_th (the starts stay; an end too where ``end_fixed``).

        Every segment's result is that of running it alone (J, DD and polishing treat the
        batch's rows independently; DD's random draws come in another order).

        Args:
            a, b: (K, 2) [m] float32, the segments' starts t^g_p[0] and ends t^g_p[1].
            end_fixed: (K,) bool.
            joined: the segments are consecutive (b[k] == a[k + 1]) and are polished as one
                path with only its start and (where ``end_fixed[-1]``) its end fixed, so the
                points where they meet may move together (:meth:`plan`, both policies).
            generator: DD's random numbers.

        Returns:
            LocalStages.
        """
        K, P_l = a.shape[0], self.dense.points
        times = {"j_check": 0.0, "dd": 0.0, "polish": 0.0, "exact": 0.0}
        frac = torch.linspace(0.0, 1.0, P_l)[None, :, None]
        straight = a[:, None] + frac * (b - a)[:, None]  # (K, P^l, 2) LocalPlan
        local = straight.clone()
        t0 = time.perf_counter()
        c = self.local_cost(local, b).float().cpu()  # (K,) line 14
        times["j_check"] = (time.perf_counter() - t0) * 1e3
        c_after = c.clone()
        used = (c > self.dense.c_th) if self.dd is not None else torch.zeros(K, dtype=torch.bool)
        if used.any():  # line 15
            t0 = time.perf_counter()
            idx = torch.nonzero(used).flatten()
            seg, cost = self.refine(a[idx], b[idx], generator=generator)
            if self.dense.keep_better:  # ours: DD never replaces a cheaper straight plan
                better = cost <= c[idx]
                idx, seg, cost = idx[better], seg[better], cost[better]
            local[idx] = seg
            c_after[idx] = cost
            times["dd"] = (time.perf_counter() - t0) * 1e3
        polished = torch.zeros(K, dtype=torch.bool)
        rough = (c_after > self.dense.c_th) if self.polishing else polished
        unpolished = local.clone()
        if rough.any():
            t0 = time.perf_counter()
            if joined:
                local, polished = self._polish_joined(local, end_fixed)
                c_after = self.local_cost(local, local[:, -1]).float().cpu()
            else:
                idx = torch.nonzero(rough).flatten()
                fixed = torch.zeros(len(idx), P_l, dtype=torch.bool)
                fixed[:, 0] = True
                fixed[:, -1] = end_fixed[idx]
                local[idx], c_after[idx] = self.polish(local[idx], fixed)
                polished = rough
            times["polish"] = (time.perf_counter() - t0) * 1e3
        kept = torch.zeros(K, dtype=torch.bool)
        if self.exact_check is not None and bool((used | polished).any()):
            t0 = time.perf_counter()
            local, polished, kept = self._exact_rule(straight, unpolished, local, polished,
                                                     end_fixed, joined)
            if kept.any():
                c_after = self.local_cost(local, local[:, -1]).float().cpu()
            times["exact"] = (time.perf_counter() - t0) * 1e3
        return LocalStages(plans=local, c_before=c, c_after=c_after, dd_used=used,
                           polished=polished, timings_ms=times, exact_kept=kept)

    def _polish_joined(self, local: torch.Tensor, end_fixed: torch.Tensor,
                       frozen: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Join K consecutive local plans (K, P^l, 2), polish the whole path with its start, its
        end (where ``end_fixed[-1]``) and the points of the ``frozen`` (K,) segments fixed, and
        split it again -> (plans (K, P^l, 2), moved (K,) bool)."""
        K, P_l = local.shape[:2]
        path = self._join(local)[None]
        fixed = torch.zeros(path.shape[1], dtype=torch.bool)
        fixed[0], fixed[-1] = True, bool(end_fixed[-1])
        idx = torch.arange(K)[:, None] * (P_l - 1) + torch.arange(P_l)[None]  # (K, P^l)
        if frozen is not None:
            fixed[idx[frozen].flatten()] = True
        path, _ = self.polish(path, fixed)
        new = path[0][idx]
        return new, (new - local).abs().amax(dim=(1, 2)) > 0

    @staticmethod
    def _join(plans: torch.Tensor) -> torch.Tensor:
        """K consecutive local plans (K, P^l, 2) -> the path through them (K (P^l - 1) + 1, 2)."""
        return torch.cat([plans[:1, 0], plans[:, 1:].reshape(-1, 2)])

    def _colliding(self, plans: torch.Tensor, joined: bool) -> torch.Tensor:
        """The exact checker's verdict on K local plans (K, P^l, 2) -> (K,) bool (collides);
        consecutive (``joined``) plans are checked as one path."""
        K, P_l = plans.shape[:2]
        if joined:
            path = self._join(plans).double().numpy()
            bad = np.asarray(self.exact_check(path), dtype=bool).reshape(K, P_l - 1)
            return torch.as_tensor(bad.any(axis=1))
        return torch.tensor([bool(np.any(self.exact_check(p.double().numpy()))) for p in plans],
                            dtype=torch.bool)

    def _exact_rule(self, straight: torch.Tensor, unpolished: torch.Tensor, local: torch.Tensor,
                    polished: torch.Tensor, end_fixed: torch.Tensor, joined: bool
                    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The exact rule (``exact_check``) on K local plans, all (K, P^l, 2): where the checker
        finds ``local[k]`` in collision, ``unpolished[k]`` (DD's or the straight plan) or else
        ``straight[k]`` if it finds that free. When the plans were polished as one joined path
        (``joined``), the kept plans' points are fixed and the others polished again from
        ``unpolished``; that result is taken only if fewer segments collide.
        Returns (plans, polished, kept), kept: (K,) bool."""
        K = local.shape[0]
        kept = torch.zeros(K, dtype=torch.bool)
        bad = self._colliding(local, joined)
        if not bad.any():
            return local, polished, kept
        choice = unpolished.clone()
        for k in torch.nonzero(bad).flatten().tolist():
            options = [unpolished[k]] if torch.equal(unpolished[k], straight[k]) else [
                unpolished[k], straight[k]]
            for plan in options:
                if not np.any(self.exact_check(plan.double().numpy())):
                    choice[k], kept[k] = plan, True
                    break
        if not kept.any():
            return local, polished, kept
        if joined and bool(polished.any()):
            new, moved = self._polish_joined(choice, end_fixed, frozen=kept)
            if int(self._colliding(new, joined).sum()) >= int(bad.sum()):
                return local, polished, torch.zeros(K, dtype=torch.bool)
            return new, moved & ~kept, kept
        out = local.clone()
        out[kept] = choice[kept]
        return out, polished & ~kept, kept

    def resample_segment(self, a: torch.Tensor, b: torch.Tensor, *, samples: int,
                         generator: torch.Generator | None = None
                         ) -> tuple[torch.Tensor, torch.Tensor]:
        """The safety net's retry rule (ecahd_core.safety, ours): ``samples`` fresh DD plans from
        a to b in one batch, each polished (when polishing is on) while still above c_th, both
        ends fixed. a, b: (2,) [m] -> (candidates (samples, P^l, 2), c^l (samples,)), float32
        on the CPU. Leaves :meth:`plan` and :meth:`local_stage` as they are."""
        if self.dd is None:
            raise EcahdError("resampling a local segment needs DD (dense.enabled is False)")
        a = torch.as_tensor(a, dtype=torch.float32).reshape(1, 2).expand(samples, 2)
        b = torch.as_tensor(b, dtype=torch.float32).reshape(1, 2).expand(samples, 2)
        seg, cost = self.refine(a, b, generator=generator)  # (samples, P^l, 2), (samples,)
        rough = cost > self.dense.c_th
        if self.polishing and bool(rough.any()):
            fixed = torch.zeros(self.dense.points, dtype=torch.bool)
            fixed[0] = fixed[-1] = True
            seg[rough], cost[rough] = self.polish(seg[rough], fixed)
        return seg, cost
