"""Quality of a Sparse Diffusion model alone: unguided, one sample per problem.

Per problem: does some waypoint come within ``epsilon`` (1.0 m) of the goal (the paper's success
rule), and is the linearly interpolated plan collision-free for a point robot by the exact
checker (``ecahd_core.collision``)? Problems are held out (``ecahd_core.problems``).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

POINT_ROBOT_RADIUS = 1e-3  # [m] a "point robot" for the exact checker


@dataclass(frozen=True)
class SDQuality:
    problems: int
    horizon: int
    num_steps: int
    eta: float
    goal_reached: float  # fraction with a waypoint within epsilon of the goal
    collision_free_point: float  # fraction collision-free for a point robot
    expert_collision_free_point: float  # the same for the A* paths resampled to the horizon
    mean_length_ratio: float  # plan length / A* length
    sample_ms: float  # wall time of sampling all problems in one batch
    seed: int
    precision: str = "fp32"  # the Transformer's inference precision (SamplerConfig.precision)

    def to_dict(self) -> dict:
        return asdict(self)


def evaluate_sd(checkpoint, grid, problems, *, horizon: int = 10, num_steps: int = 10,
                eta: float = 0.0, seed: int = 0, epsilon: float = 1.0,
                device: str = "cpu", precision: str = "fp32") -> tuple[SDQuality, np.ndarray]:
    """Sample one SD plan per problem in one batch -> (metrics, plans (N, horizon, 2) [m])."""
    import torch

    from ecahd_core.collision import check_collision
    from ecahd_core.diffusion import DiffusionSampler, SamplerConfig
    from ecahd_core.footprint import circle_footprint

    sampler = DiffusionSampler.from_checkpoint(
        checkpoint, device=device, config=SamplerConfig(num_steps=num_steps, eta=eta,
                                                        precision=precision))
    starts = torch.tensor(np.stack([p.start for p in problems]), dtype=torch.float32)
    goals = torch.tensor(np.stack([p.goal for p in problems]), dtype=torch.float32)
    gen = torch.Generator(device=device).manual_seed(seed)
    t0 = time.perf_counter()
    out = sampler.sample(batch=len(problems), horizon=horizon,
                         conditions={0: starts.to(device), -1: goals.to(device)}, generator=gen)
    elapsed = time.perf_counter() - t0
    plans = out.trajectories.cpu().numpy().astype(np.float64)
    from ecahd_core.dataset import resample_by_arclength

    point = circle_footprint(POINT_ROBOT_RADIUS)
    reached, free, ratio, expert = [], [], [], []
    for plan, prob in zip(plans, problems):
        expert.append(check_collision(resample_by_arclength(prob.astar_path, horizon), point,
                                      grid).collision_free)
        reached.append(bool(np.min(np.linalg.norm(plan - prob.goal, axis=1)) < epsilon))
        free.append(check_collision(plan, point, grid).collision_free)
        ratio.append(float(np.sum(np.linalg.norm(np.diff(plan, axis=0), axis=1)))
                     / max(prob.astar_length, 1e-9))
    metrics = SDQuality(problems=len(problems), horizon=horizon, num_steps=num_steps, eta=eta,
                        goal_reached=float(np.mean(reached)),
                        collision_free_point=float(np.mean(free)),
                        expert_collision_free_point=float(np.mean(expert)),
                        mean_length_ratio=float(np.mean(ratio)), sample_ms=elapsed * 1e3,
                        seed=seed, precision=sampler.precision)
    return metrics, plans


def plot_plans(grid, problems, plans, path) -> None:
    """Draw SD plans (waypoints joined by straight lines) with their A* references."""
    from ecahd_core.collision import check_collision
    from ecahd_core.footprint import circle_footprint
    from ecahd_core.viz import PlanFigure, save_figures

    point = circle_footprint(POINT_ROBOT_RADIUS)
    figures = []
    for i, (prob, plan) in enumerate(zip(problems, plans)):
        rep = check_collision(plan, point, grid)
        figures.append(PlanFigure(
            grid=grid, footprint=point, start=prob.start, goal=prob.goal, trajectory=plan,
            waypoints=plan, extra_paths=[prob.astar_path],
            colliding_poses=rep.dense_poses[rep.colliding][::8],
            title=f"problem {i}: {'free' if rep.collision_free else 'collides'} "
                  f"(grey: A*)"))
    save_figures(figures, path, cols=4, panel_size=4.0)
