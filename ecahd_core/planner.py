"""Planners of ECAHD (paper Sec. III-A, Algorithm 1): the Sparse Diffusion global sampler with
best-of-N selection.

Selection rules for the best of N candidates t^{g,(i)} (Sec. III-A):
- ``shortest_reaching`` (the paper's): among candidates with min_k ||t_k - G|| < epsilon the one
  of shortest path length L(t) = sum_k ||t_{k+1} - t_k||; if none reaches the goal, the
  shortest overall.
- ``collision_aware`` (ours): the same, but candidates are first ranked by J's collision cost of
  the linearly interpolated path (surface sweep of the footprint), keeping those within
  ``collision_tolerance`` of the least-colliding one, then the paper's rule among them.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from ecahd_core.errors import EcahdError

SELECTION_RULES = ("shortest_reaching", "collision_aware")


@dataclass(frozen=True, kw_only=True)
class SparseConfig:
    """Settings of the Sparse Diffusion global planner.

    Attributes:
        num_candidates: I, candidates sampled in one batch (isSearchEnabled when > 1).
        horizon: P^g, waypoints of a global plan.
        epsilon: [m] goal-reaching radius of the selection rule (paper: 1.0).
        selection: one of SELECTION_RULES.
        collision_tolerance: slack on the collision cost for ``collision_aware``.
        num_steps: DDIM steps (None: the checkpoint's).
        eta: DDIM eta.
    """

    num_candidates: int = 10
    horizon: int = 10
    epsilon: float = 1.0
    selection: str = "shortest_reaching"
    collision_tolerance: float = 0.1
    num_steps: int | None = None
    eta: float = 0.0

    def __post_init__(self) -> None:
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


@dataclass(frozen=True)
class SparsePlan:
    """Attributes:
        waypoints: (P, 2) [m] the selected global plan t^g.
        candidates: (N, P, 2) [m] all sampled candidates.
        best: index of the selected candidate.
        collision_costs: (N,) J collision cost of each candidate (None if not computed).
        time_ms: sampling + selection wall time.
    """

    waypoints: np.ndarray
    candidates: np.ndarray
    best: int
    collision_costs: np.ndarray | None
    time_ms: float


class SparseDiffusion:
    """SparseDiffusion of Algorithm 1 (lines 2-11): N candidates in one batch, best of N.

    Args:
        checkpoint: a loaded SD checkpoint (``model_zoo.load_model("sd", ...)``).
        config: SparseConfig.
        cost: optional (costmap, footprint_points, CostConfig) for the collision_aware rule.
        device: where the model runs.
    """

    def __init__(self, checkpoint, config: SparseConfig | None = None, *, cost=None,
                 device: str = "cpu") -> None:
        from ecahd_core.diffusion import DiffusionSampler, SamplerConfig
        from ecahd_core.model_zoo import sample_steps

        self.config = config or SparseConfig()
        steps = self.config.num_steps or sample_steps(checkpoint)
        self.sampler = DiffusionSampler.from_checkpoint(
            checkpoint, device=device, config=SamplerConfig(num_steps=steps, eta=self.config.eta))
        self.cost = cost

    def plan(self, start, goal, *, horizon: int | None = None,
             generator: torch.Generator | None = None) -> SparsePlan:
        """start, goal: (2,) [m] -> SparsePlan with waypoints (horizon, 2) from start to goal."""
        cfg = self.config
        horizon = horizon or cfg.horizon
        t0 = time.perf_counter()
        start_t = torch.as_tensor(np.asarray(start, dtype=np.float32), device=self.sampler.device)
        goal_t = torch.as_tensor(np.asarray(goal, dtype=np.float32), device=self.sampler.device)
        if horizon <= 2:
            cands = torch.stack([start_t, goal_t])[None].expand(cfg.num_candidates, 2, 2)
        else:
            cands = self.sampler.sample(batch=cfg.num_candidates, horizon=horizon,
                                        conditions={0: start_t, -1: goal_t},
                                        generator=generator).trajectories
        col = None
        if self.cost is not None:
            from ecahd_core.cost import trajectory_cost

            costmap, fp, cost_config = self.cost
            with torch.no_grad():
                col = trajectory_cost(cands.to(costmap.dtype), goal_t.to(costmap.dtype), fp,
                                      costmap, **cost_config.cost_kwargs()).collision_cost
            col = col.cpu().numpy()
        cands_np = cands.detach().cpu().numpy().astype(np.float64)
        best = select_best(cands_np, np.asarray(goal, dtype=np.float64), epsilon=cfg.epsilon,
                           rule=cfg.selection, collision_costs=col,
                           collision_tolerance=cfg.collision_tolerance)
        return SparsePlan(waypoints=cands_np[best], candidates=cands_np, best=best,
                          collision_costs=col, time_ms=(time.perf_counter() - t0) * 1e3)
