"""Polishing: a few steps of gradient descent on J's collision cost, our safety rule beyond the
paper (ECAHD's Algorithm 1 accepts whatever DD returns).

Why: J guides DD, but guidance is a nudge inside a stochastic sampler with only 10 DDIM steps;
with 0.1 m to spare on each side of the circle robot in maze2d-large's 1 m corridors, no guided
sample we drew was collision-free for that robot over a whole problem (docs/RESULTS.md). The
same J, descended directly on the points of the path, centres the path in the corridor: the
diffusion models choose the route, the descent makes it clear the walls.

The step is normalised per path: the point with the largest gradient moves ``step_size`` m, the
others proportionally less, so the step is in metres whatever J's scale (J sums thousands of
cost-map lookups); points marked fixed (the start, the goal) never move. A path is done when
every swept footprint sample J reads lies at least ``clearance`` m from obstacles (its largest
cost-map lookup is at most 1 - clearance / margin), when its collision cost is at most
``tolerance``, or (``patience``) when its cost has stopped falling; otherwise it runs ``steps``
steps. The lowest-cost iterate of each path is
returned, so polishing never makes a path's J worse.
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from ecahd_core.errors import EcahdError

STALL_GAIN = 0.01  # with ``patience``: a step that lowers a path's best J by less is no gain
WIDE_MARGIN = 0.3  # [m] cost maps with at least this margin (buildings) get ...
WIDE_MARGIN_PATIENCE = 3  # ... this patience by default


@dataclass(frozen=True, kw_only=True)
class PolishConfig:
    """Settings of :func:`polish_paths`.

    Attributes:
        steps: gradient steps at most (0 disables polishing).
        step_size: [m] how far the point with the largest gradient moves per step (constant:
            a linear decay to 0 was measured and did worse for the circle robot, 93.8% vs
            96.9% collision-free on 32 problems).
        clearance: [m] a path whose swept footprint samples all keep this distance from
            obstacles is done (only meaningful below the cost map's margin).
        tolerance: a path whose collision cost is at most this is done.
        across: each point moves only across the path (its gradient's component along the
            chord of its neighbours removed), so polishing centres the path and never
            shuffles points along it. Free to move along it, J's descent pulled a local
            plan's interior points back towards its start in a 1 m corridor (J reads the
            footprint at points and segments alike, so a path that doubles back costs no
            more): 65% of 150 local plans on exact-free corridor segments of maze2d-large
            doubled back by more than 0.05 m, and in the closed loop the robot turned round
            to follow them (docs/rules.md, "polishing across the path"). False: the earlier
            behaviour.
        patience: a path stops once this many steps in a row lowered its best J by less
            than STALL_GAIN (1%): a door a few cm wider than the robot never gives the
            ``clearance``, and the descent then runs all its steps round the door's centre
            line for nothing. 0: never (every step until done); -1 (default): by the cost
            map, WIDE_MARGIN_PATIENCE (3) where its margin is at least WIDE_MARGIN (0.3 m;
            building maps, ``cost_margin`` by the map) and 0 on narrower ones (maze2d's
            0.1 m). Measured with ``ecahd bench general --problems 12`` (docs/RESULTS.md):
            on offices the circle robot's plans 91.7% -> 100% alone, median 333 -> 259 ms,
            p95 5.7 -> 2.0 s; other buildings unchanged; on maze2d-large (32 problems) 3
            switched on cost one problem of 32 for two of the robots, so it stays off there.
    """

    steps: int = 30
    step_size: float = 0.05
    clearance: float = 0.1
    tolerance: float = 1e-6
    across: bool = True
    patience: int = -1

    def __post_init__(self) -> None:
        if self.steps < 0:
            raise EcahdError(f"polish steps must be >= 0, got {self.steps}")
        if not self.step_size > 0:
            raise EcahdError(f"polish step_size must be > 0 m, got {self.step_size}")
        if not self.clearance >= 0:
            raise EcahdError(f"polish clearance must be >= 0 m, got {self.clearance}")
        if not self.tolerance >= 0:
            raise EcahdError(f"polish tolerance must be >= 0, got {self.tolerance}")
        if self.patience < -1:
            raise EcahdError(f"polish patience must be >= 0 (or -1: by the map), got "
                             f"{self.patience}")

    def patience_for(self, margin: float) -> int:
        """The patience on a cost map of this ``margin`` [m] (resolving -1: by the map)."""
        if self.patience >= 0:
            return self.patience
        return WIDE_MARGIN_PATIENCE if margin >= WIDE_MARGIN else 0


def polish_paths(paths: torch.Tensor, fixed: torch.Tensor, costmap, footprint_points,
                 cost_config=None, config: PolishConfig | None = None
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    """Descend J's collision cost over the free points of a batch of paths.

    Args:
        paths: (B, P, 2) [m] paths in the map frame.
        fixed: (P,) or (B, P) bool, True where a point must not move.
        costmap, footprint_points ((R, 2) [m]), cost_config: the cost J (ecahd_core.cost).
        config: PolishConfig.

    Returns:
        (paths (B, P, 2), collision_cost (B,)): the lowest-cost iterate of every path and its
        collision cost; float32 on the cost map's device.
    """
    from ecahd_core.cost import CostConfig, trajectory_cost

    cfg = config or PolishConfig()
    cc = cost_config or CostConfig()
    x = torch.as_tensor(paths).to(device=costmap.device, dtype=costmap.dtype).clone()
    if x.ndim != 3 or x.shape[-1] != 2:
        raise EcahdError(f"paths must be (B, P, 2), got {tuple(x.shape)}")
    B, P, _ = x.shape
    fixed = torch.as_tensor(fixed, dtype=torch.bool, device=x.device).expand(B, P)
    fp = torch.as_tensor(footprint_points, dtype=x.dtype, device=x.device)
    kwargs = cc.cost_kwargs()
    peak_limit = max(0.0, 1.0 - cfg.clearance / costmap.margin)
    patience = cfg.patience_for(costmap.margin)
    best, best_cost = x.clone(), torch.full((B,), float("inf"), dtype=x.dtype, device=x.device)
    active = torch.arange(B, device=x.device)
    stall = torch.zeros(B, dtype=torch.long, device=x.device)  # steps since J last fell by 1%
    for step in range(cfg.steps + 1):
        xa = x[active].requires_grad_(True)
        with torch.enable_grad():
            terms = trajectory_cost(xa, xa[:, -1].detach(), fp, costmap, **kwargs)
            (grad,) = torch.autograd.grad(terms.collision_cost.sum(), xa)
        cost = terms.collision_cost.detach()
        better = cost < best_cost[active]
        gained = cost < best_cost[active] * (1.0 - STALL_GAIN)
        stall[active] = torch.where(gained, 0, stall[active] + 1)
        best[active[better]] = xa.detach()[better]
        best_cost[active[better]] = cost[better]
        keep = (cost > cfg.tolerance) & (terms.peak_cost > peak_limit)
        if patience:
            keep &= stall[active] < patience
        if step == cfg.steps or not keep.any():
            break
        active, grad, xa = active[keep], grad[keep], xa.detach()[keep]
        grad = grad.masked_fill(fixed[active][..., None], 0.0)
        if cfg.across:
            grad = _across(grad, xa)
        scale = grad.norm(dim=-1).amax(dim=1).clamp_min(1e-12)  # (B',) largest point gradient
        x[active] = xa - cfg.step_size * grad / scale[:, None, None]
    return best, best_cost


def _across(grad: torch.Tensor, paths: torch.Tensor) -> torch.Tensor:
    """grad (B, P, 2) without its component along each point's chord of ``paths`` (B, P, 2):
    x[i + 1] - x[i - 1] inside, the first and last segments' directions at the ends; a point
    whose chord has no length keeps its gradient."""
    chord = torch.empty_like(paths)
    chord[:, 1:-1] = paths[:, 2:] - paths[:, :-2]
    chord[:, 0] = paths[:, 1] - paths[:, 0]
    chord[:, -1] = paths[:, -1] - paths[:, -2]
    norm = chord.norm(dim=-1, keepdim=True)
    t = torch.where(norm > 1e-9, chord / norm.clamp_min(1e-9), torch.zeros_like(chord))
    return grad - (grad * t).sum(dim=-1, keepdim=True) * t
