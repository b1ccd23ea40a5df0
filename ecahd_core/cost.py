"""The cost function J of Algorithm 2 (lines 11-25), batched in torch, and its literal loop form.

J(t_k, G, P, R, M) returns (dist_cost, collision_cost) for every trajectory of a batch:

- dist_cost: mean over the P points of the squared distance to the goal G (Eq. 3, written as a
  cost to minimise, so positive).
- collision_cost: the footprint R is placed at every trajectory point, turned towards the next
  point (psi_p = atan2 of segment p, Eq. 4; the last point keeps the last segment's heading, as
  psi_end of Algorithm 2 lines 15-16), rotated and translated (Eqs. 7-8); between consecutive
  poses N_interp DDA points join corresponding footprint points (Eq. 9); the cost map is read at
  each of them by bilinear interpolation (Eqs. 10-11) and everything is summed, then scaled by
  sigma_dist / sigma_col (line 24).

DDA sampling: segment p contributes the points start + k * (end - start) / N for k = 0 .. N-1
(Eq. 9); the pose of the last trajectory point is added once at the end. Consecutive segments
share the pose at t[p + 1] (R_end of segment p is R_start of segment p + 1), so every pose is
counted exactly once and a single point (P = 1) costs its own footprint only.

Modes (the Point / Line / Surface rows of Table II):
- ``point``   the footprint centre at each trajectory point, no sweep;
- ``line``    the centre line swept by DDA;
- ``surface`` the swept footprint (the paper's method).

Headings of zero-length segments (shorter than MIN_SEGMENT_LENGTH) are inherited from the
previous non-degenerate segment, or 0 if there is none; atan2 is only ever evaluated at safe
arguments ("double where"), so values and gradients stay finite.

Implementation: placing the footprint (Eqs. 7-8) is linear in [cos psi, sin psi, x, y] and the
DDA (Eq. 9) is linear in the poses, so all B x M x R sample points come from one matrix product
with a (P*4, M*2*R) matrix cached per footprint tensor; the cost map lookup returns its gradient
(Eqs. 12-13) together with the value. :func:`trajectory_cost_loops` is Algorithm 2 written
literally with Python loops, the reference that tests and ``ecahd bench cost`` compare against.
"""
from __future__ import annotations

import math
import numbers
import threading
from collections import OrderedDict
from dataclasses import dataclass
from functools import lru_cache

import torch

from ecahd_core.costmap import DEFAULT_DILATION, DEFAULT_MARGIN, CostMap, auto_margin
from ecahd_core.errors import EcahdError, FootprintError, TrajectoryError
from ecahd_core.maps import GridMap

MODES = ("point", "line", "surface")
MIN_SEGMENT_LENGTH = 1e-6  # [m] shorter segments have no meaningful heading


@dataclass(frozen=True, kw_only=True)
class CostConfig:
    """Settings of the cost J (one place defines each default).

    Attributes:
        mode: how the cost map is read: "point", "line" or "surface" (Table II).
        n_interp: N_interp, DDA points per segment (Eq. 9).
        sigma_dist: sigma_dist of Algorithm 2 line 24.
        sigma_col: sigma_col of Algorithm 2 line 24; collision_cost is scaled by
            sigma_dist / sigma_col.
        margin: [m] distance from an obstacle at which the map cost reaches 0 (see costmap).
        dilation: [m] obstacle inflation of the cost map (Table II "dilation").
    """

    mode: str = "surface"
    n_interp: int = 8
    sigma_dist: float = 1.0
    sigma_col: float = 1.0
    margin: float = DEFAULT_MARGIN
    dilation: float = DEFAULT_DILATION

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise EcahdError(f"cost mode {self.mode!r} is not one of {list(MODES)}")
        n = self.n_interp
        if isinstance(n, bool) or not isinstance(n, numbers.Integral) or n < 1:
            raise EcahdError(f"n_interp must be an integer >= 1, got {n!r}")
        for name in ("sigma_dist", "sigma_col", "margin", "dilation"):
            value = getattr(self, name)
            zero_ok = name == "dilation"
            if not (isinstance(value, numbers.Real) and math.isfinite(value)
                    and (value > 0 or (zero_ok and value == 0))):
                bound = ">= 0" if zero_ok else "> 0"
                raise EcahdError(f"{name} must be a finite number {bound}, got {value!r}")

    @classmethod
    def for_map(cls, grid, **kwargs) -> "CostConfig":
        """A config whose margin is chosen by ``grid`` (:func:`~ecahd_core.costmap.auto_margin`)
        unless ``kwargs`` give one (``margin=None`` also means by the map)."""
        if kwargs.get("margin") is None:
            kwargs["margin"] = auto_margin(grid)
        return cls(**kwargs)

    def cost_kwargs(self) -> dict:
        """The keyword arguments of :func:`trajectory_cost` taken from this config."""
        return dict(mode=self.mode, n_interp=self.n_interp, sigma_dist=self.sigma_dist,
                    sigma_col=self.sigma_col)

    def make_costmap(self, grid: GridMap, *, dtype: torch.dtype = torch.float32,
                     device: torch.device | str = "cpu") -> CostMap:
        """The cost map of ``grid`` with this config's margin and dilation."""
        return CostMap.from_grid(grid, margin=self.margin, dilation=self.dilation, dtype=dtype,
                                 device=device)


_DEFAULTS = CostConfig()


@dataclass(frozen=True)
class CollisionCost:
    """The one object that owns J's inputs for a map and a robot: the cost map, the footprint's
    sample points R as a float32 tensor (one tensor per robot, so J's sweep-matrix cache hits
    on every call) and the CostConfig. Build it once per map with :meth:`build`.

    Attributes:
        costmap: the collision cost map (Eqs. 10-13).
        footprint_points: (R, 2) [m] float32 tensor, the footprint's sample points.
        config: the CostConfig J runs with.
    """

    costmap: CostMap
    footprint_points: torch.Tensor
    config: CostConfig

    @classmethod
    def build(cls, grid: GridMap, footprint, config: CostConfig | None = None) -> "CollisionCost":
        """From a GridMap and a :class:`~ecahd_core.footprint.Footprint` (its ``points``);
        ``config`` None: the defaults with the margin chosen by the map
        (:meth:`CostConfig.for_map`)."""
        config = config or CostConfig.for_map(grid)
        points = torch.as_tensor(footprint.points, dtype=torch.float32).contiguous()
        return cls(costmap=config.make_costmap(grid), footprint_points=points, config=config)

    def terms(self, traj: torch.Tensor) -> "CostTerms":
        """J of each trajectory towards its own last point: traj (B, P, 2) [m] -> CostTerms."""
        return trajectory_cost(traj, traj[:, -1], self.footprint_points, self.costmap,
                               **self.config.cost_kwargs())

    def collision_cost(self, traj: torch.Tensor) -> torch.Tensor:
        """c^l of each trajectory: traj (B, P, 2) [m] -> (B,) J's collision cost."""
        return self.terms(traj).collision_cost


@dataclass(frozen=True)
class CostTerms:
    """The pair returned by J (Algorithm 2 line 24).

    Attributes:
        dist_cost: (B,) mean squared distance of the points to the goal [m^2].
        collision_cost: (B,) summed map cost, already scaled by sigma_dist / sigma_col.
        peak_cost: (B,) the largest single cost-map lookup of each trajectory (unscaled; 0 when
            every sample is farther than the margin from obstacles, 1 on an obstacle edge), or
            None where not computed (the loop reference).
    """

    dist_cost: torch.Tensor
    collision_cost: torch.Tensor
    peak_cost: torch.Tensor | None = None

    @property
    def total(self) -> torch.Tensor:
        """(B,) dist_cost + collision_cost, the quantity whose gradient guides the sampler."""
        return self.dist_cost + self.collision_cost


# ------------------------------------------------------------------------------ batched J
def trajectory_cost(traj: torch.Tensor, goal, footprint_points, costmap: CostMap, *,
                    mode: str = _DEFAULTS.mode, n_interp: int = _DEFAULTS.n_interp,
                    sigma_dist: float = _DEFAULTS.sigma_dist,
                    sigma_col: float = _DEFAULTS.sigma_col) -> CostTerms:
    """The cost J of Algorithm 2 for a batch of trajectories, differentiable w.r.t. ``traj``.

    Args:
        traj: (B, P, 2) B trajectories of P points (x, y) [m], float32 or float64; the
            computation runs on its device and dtype.
        goal: (B, 2) or (2,) goal position(s) G [m].
        footprint_points: (R, 2) robot-frame sample points R [m] (x forward); ignored by the
            "point" and "line" modes, which use the centre only. Pass a tensor already on
            traj's device and dtype so the sweep matrix built from it is reused between calls.
        costmap: the cost map M (moved to traj's device and dtype if needed).
        mode, n_interp, sigma_dist, sigma_col: see :class:`CostConfig`.

    Returns:
        CostTerms with dist_cost (B,) and collision_cost (B,).
    """
    CostConfig(mode=mode, n_interp=n_interp, sigma_dist=sigma_dist, sigma_col=sigma_col)
    B, P = _check_traj(traj)
    goal = _check_goal(goal, traj)  # (B or 1, 2)
    cmap = costmap.to(traj.device, traj.dtype)

    # Eq. 3 as a cost: mean over points of ||t[i] - G||^2
    dist_cost = (traj - goal[:, None, :]).square().sum(-1).mean(-1)  # (B,)

    if mode == "point":
        xy, pair_dim = traj, 2  # (B, P, 2): the centres, no sweep
    elif mode == "line":
        # DDA (Eq. 9) along the centre line: one linear map from the P points to the
        # M = (P-1) N + 1 sample points
        dda = _dda_matrix(P, n_interp, traj.dtype, traj.device)  # (M, P)
        xy, pair_dim = traj.transpose(1, 2) @ dda.T, 1  # (B, 2, M)
    else:
        # The footprint at a pose (Eqs. 7-8) is linear in [cos psi, sin psi, x, y] and the DDA
        # points (Eq. 9) are linear in the poses, so both are one (P*4, M*2*R) matrix; for long
        # trajectories (SWEEP_MATRIX_POINTS) the same map is applied pose by pose.
        psi = pose_headings(traj)  # (B, P) Eq. 4
        pose = torch.cat([torch.stack([torch.cos(psi), torch.sin(psi)], -1), traj], -1)  # (B, P, 4)
        if P <= SWEEP_MATRIX_POINTS:
            sweep, R = _sweep_matrix(footprint_points, traj, n_interp)
            xy = (pose.reshape(B, P * 4) @ sweep).view(B, -1, 2, R)  # (B, M, 2, R)
        else:
            xy = _swept(pose, footprint_points, n_interp)  # (B, M, 2, R)
        pair_dim = 2
    cost = cmap.sample(xy, dim=pair_dim)  # (B, P), (B, M) or (B, M, R): lines 19-20
    collision = cost.sum(dim=tuple(range(1, cost.ndim)))  # (B,) line 21
    collision_cost = collision * (sigma_dist / sigma_col)  # line 24
    peak = cost.detach().flatten(1).amax(dim=1)  # (B,)
    return CostTerms(dist_cost=dist_cost, collision_cost=collision_cost, peak_cost=peak)


def pose_headings(traj: torch.Tensor) -> torch.Tensor:
    """Heading [rad] of the footprint at each trajectory point: (B, P, 2) -> (B, P).

    Point p faces point p + 1 (psi_p = atan2 of segment p, Eq. 4); the last point keeps the last
    segment's heading (psi_end of Algorithm 2 line 16). A segment shorter than
    MIN_SEGMENT_LENGTH inherits the heading of the previous non-degenerate segment (0 if none);
    atan2 never sees it ("double where"), so the gradient is finite (and zero through it).
    """
    B, P, _ = traj.shape
    seg = _facing_matrix(P, traj.dtype, traj.device) @ traj  # (B, P, 2) segment faced by point p
    with torch.no_grad():
        ok = seg.square().sum(-1) > MIN_SEGMENT_LENGTH ** 2  # (B, P)
    safe = torch.where(ok[..., None], seg, _unit_x(traj.dtype, traj.device))  # where #1: no (0, 0)
    dx, dy = safe.unbind(-1)
    psi = torch.atan2(dy, dx)  # (B, P)
    if not bool(ok.all()):
        # where #2, a forward fill: index of the last non-degenerate segment at or before p
        steps = torch.arange(P, device=traj.device).expand(B, P)
        last_ok = torch.where(ok, steps, -1).cummax(dim=1).values  # (B, P), -1 if none yet
        psi = torch.where(last_ok >= 0, psi.gather(1, last_ok.clamp(min=0)), 0.0)
    return psi


_CACHE_SIZE = 32


@lru_cache(maxsize=_CACHE_SIZE)
def _unit_x(dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """(2,) the direction (1, 0): what atan2 sees instead of a degenerate segment."""
    return torch.tensor([1.0, 0.0], dtype=dtype, device=device)


@lru_cache(maxsize=_CACHE_SIZE)
def _facing_matrix(P: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """(P, P) D with (D @ traj)[p] = t[p+1] - t[p], and row P-1 = row P-2 (the last point faces
    along the last segment). All zeros for P = 1."""
    d = torch.zeros(P, P, dtype=dtype)
    for p in range(P - 1):
        d[p, p], d[p, p + 1] = -1.0, 1.0
    if P > 1:
        d[P - 1] = d[P - 2]
    return d.to(device)


@lru_cache(maxsize=_CACHE_SIZE)
def _dda_matrix(P: int, n: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """(M, P) weights, M = (P-1) n + 1: row p n + k is the DDA point k of segment p,
    (1 - k/n) pose[p] + (k/n) pose[p+1] (Eq. 9: start + k (end - start) / n, k = 0 .. n-1);
    the last row is the last pose."""
    frac = torch.arange(n, dtype=torch.float64) / n  # (n,)
    w = torch.zeros(P - 1, n, P, dtype=torch.float64)
    seg = torch.arange(P - 1)
    w[seg, :, seg] = 1.0 - frac
    w[seg, :, seg + 1] = frac
    last = torch.zeros(1, P, dtype=torch.float64)
    last[0, P - 1] = 1.0
    return torch.cat([w.reshape(-1, P), last]).to(dtype=dtype, device=device)


def _placement_matrix(footprint: torch.Tensor) -> torch.Tensor:
    """(4, 2R) matrix A with [cos psi, sin psi, x, y] @ A = the footprint R rotated by psi and
    moved to (x, y) (Eqs. 7-8), laid out as (2, R): first the R x coordinates
    x_r = x + cos psi R_x - sin psi R_y, then the R y coordinates
    y_r = y + sin psi R_x + cos psi R_y."""
    rx, ry = footprint[:, 0], footprint[:, 1]
    one, zero = torch.ones_like(rx), torch.zeros_like(rx)
    x_cols = torch.stack([rx, -ry, one, zero])  # (4, R) coefficients of (cos, sin, x, y) in x_r
    y_cols = torch.stack([ry, rx, zero, one])  # (4, R) ... in y_r
    return torch.cat([x_cols, y_cols], dim=1)  # (4, 2R)


# trajectories of at most this many points are swept by one cached (P*4, M*2*R) matrix (one
# matmul: the fastest for SD's and DD's short plans); longer ones, such as the joined path that
# polishing descends, pose by pose and then along each segment (:func:`_swept`): the matrix grows
# as P^2 (121 points: 126 MB; polishing such a path took 1.27 s of 3.5 s in the profile of
# docs/general.md, "What remains", and 0.14 s pose by pose)
SWEEP_MATRIX_POINTS = 16


def _swept(pose: torch.Tensor, footprint_points, n: int) -> torch.Tensor:
    """Every DDA point (Eq. 9) of every footprint point (Eqs. 7-8) of poses (B, P, 4)
    ([cos psi, sin psi, x, y]) -> (B, M, 2, R), M = (P-1) n + 1: the footprint placed at each
    pose, then point k of segment p at (1 - k/n) of pose p's and k/n of pose p+1's (the last
    row: the last pose's), the same as the sweep matrix of :func:`_sweep_matrix`."""
    B, P, _ = pose.shape
    footprint = _check_footprint(_as_footprint_tensor(footprint_points, pose))
    placed = pose @ _placement_matrix(footprint)  # (B, P, 2R)
    frac = torch.arange(n, dtype=pose.dtype, device=pose.device) / n  # (n,)
    inner = placed[:, :-1, None] + frac[:, None] * (placed[:, 1:] - placed[:, :-1])[:, :, None]
    xy = torch.cat([inner.reshape(B, (P - 1) * n, -1), placed[:, -1:]], dim=1)  # (B, M, 2R)
    return xy.view(B, -1, 2, footprint.shape[0])


_sweep_cache: OrderedDict[tuple, tuple[torch.Tensor, torch.Tensor]] = OrderedDict()
_sweep_cache_lock = threading.Lock()


def _sweep_matrix(footprint_points, traj: torch.Tensor, n: int) -> tuple[torch.Tensor, int]:
    """(P*4, M*2*R) matrix S = kron(DDA^T, A) and R: row (p, q), column (m, c, r) of S is
    dda[m, p] * placement[q, (c, r)], so [cos psi_p, sin psi_p, x_p, y_p] flattened over p
    times S gives every DDA point of every footprint point (Eqs. 7-9).

    Remembered per footprint tensor, as J runs at every denoising step: the cache holds the
    tensor itself, so its identity and in-place version number stand for its values.
    """
    P = traj.shape[1]
    footprint = _as_footprint_tensor(footprint_points, traj)
    key = (id(footprint), footprint._version, P, n)
    with _sweep_cache_lock:
        hit = _sweep_cache.get(key)
        if hit is not None and hit[0] is footprint:
            _sweep_cache.move_to_end(key)
            return hit[1], footprint.shape[0]
    _check_footprint(footprint)
    dda = _dda_matrix(P, n, footprint.dtype, footprint.device)
    sweep = torch.kron(dda.T.contiguous(), _placement_matrix(footprint))
    with _sweep_cache_lock:
        _sweep_cache[key] = (footprint, sweep)
        if len(_sweep_cache) > _CACHE_SIZE:
            _sweep_cache.popitem(last=False)
    return sweep, footprint.shape[0]


# ---------------------------------------------------------------------------- loop version
def trajectory_cost_loops(traj: torch.Tensor, goal, footprint_points, costmap: CostMap, *,
                          mode: str = _DEFAULTS.mode, n_interp: int = _DEFAULTS.n_interp,
                          sigma_dist: float = _DEFAULTS.sigma_dist,
                          sigma_col: float = _DEFAULTS.sigma_col) -> CostTerms:
    """Algorithm 2 lines 11-25 written literally, with Python loops over the batch, the
    segments, the DDA points and the footprint points. Same arguments, result and gradient as
    :func:`trajectory_cost`; thousands of times slower. Reference for tests and benchmarks only.
    """
    CostConfig(mode=mode, n_interp=n_interp, sigma_dist=sigma_dist, sigma_col=sigma_col)
    B, P = _check_traj(traj)
    goal = _check_goal(goal, traj).expand(B, 2)
    cmap = costmap.to(traj.device, traj.dtype)
    if mode == "surface":
        fp = _check_footprint(_as_footprint_tensor(footprint_points, traj))
        shape = [(r[0], r[1]) for r in fp]
    else:
        shape = [(0.0, 0.0)]  # the centre only
    N = n_interp
    dist_costs, collision_costs = [], []
    for b in range(B):
        t, G = traj[b], goal[b]
        # line 12: dist_cost <- MSE(t_k, G) (Eq. 3, as a positive cost)
        dist_cost = sum((t[i, 0] - G[0]) ** 2 + (t[i, 1] - G[1]) ** 2 for i in range(P)) / P
        collision_cost = traj.new_zeros(())  # line 13
        if mode == "point":
            for p in range(P):
                collision_cost = collision_cost + cmap.sample_point(t[p, 0], t[p, 1])
        else:
            psi = _segment_headings_loop(t)  # Eq. 4 for every segment
            for p in range(P - 1):  # line 14
                psi_start = psi[p]  # line 15
                psi_end = psi[p + 1] if p + 1 < P - 1 else psi[p]  # line 16
                R_start = [_place(t[p], psi_start, r) for r in shape]  # line 17, Eqs. 7-8
                R_end = [_place(t[p + 1], psi_end, r) for r in shape]  # line 18
                for k in range(N):  # line 19: DDA(R_start, R_end), Eq. 9
                    for (x1, y1), (x2, y2) in zip(R_start, R_end):
                        x = x1 + k * (x2 - x1) / N
                        y = y1 + k * (y2 - y1) / N
                        collision_cost = collision_cost + cmap.sample_point(x, y)  # lines 20-21
            psi_last = psi[P - 2] if P > 1 else traj.new_zeros(())
            for x, y in (_place(t[P - 1], psi_last, r) for r in shape):  # the last pose, once
                collision_cost = collision_cost + cmap.sample_point(x, y)
        dist_costs.append(dist_cost)
        collision_costs.append(collision_cost * (sigma_dist / sigma_col))  # line 24
    return CostTerms(dist_cost=torch.stack(dist_costs), collision_cost=torch.stack(collision_costs))


def _segment_headings_loop(t: torch.Tensor) -> list[torch.Tensor]:
    """psi_p (Eq. 4) of each segment of one (P, 2) trajectory, with the degenerate-segment rule
    of :func:`pose_headings`."""
    headings, previous = [], t.new_zeros(())
    for p in range(t.shape[0] - 1):
        dx, dy = t[p + 1, 0] - t[p, 0], t[p + 1, 1] - t[p, 1]
        if (dx * dx + dy * dy).item() > MIN_SEGMENT_LENGTH ** 2:
            previous = torch.atan2(dy, dx)
        headings.append(previous)
    return headings


def _place(position: torch.Tensor, psi: torch.Tensor, r) -> tuple[torch.Tensor, torch.Tensor]:
    """One footprint point r = (R_x, R_y) rotated by psi and moved to position (Eqs. 7-8)."""
    c, s = torch.cos(psi), torch.sin(psi)
    return position[0] + c * r[0] - s * r[1], position[1] + s * r[0] + c * r[1]


# ------------------------------------------------------------------------------ validation
def _check_traj(traj) -> tuple[int, int]:
    if not isinstance(traj, torch.Tensor):
        raise TrajectoryError(f"trajectory must be a torch tensor of shape (B, P, 2), "
                              f"got {type(traj).__name__}")
    if traj.ndim != 3 or traj.shape[-1] != 2:
        raise TrajectoryError(f"trajectory must have shape (B, P, 2), got {tuple(traj.shape)}")
    B, P, _ = traj.shape
    if B < 1 or P < 1:
        raise TrajectoryError(f"trajectory is empty: shape {tuple(traj.shape)} "
                              f"(need B >= 1 trajectories of P >= 1 points)")
    if traj.dtype not in (torch.float32, torch.float64):
        raise TrajectoryError(f"trajectory must be float32 or float64, got {traj.dtype}")
    if not bool(torch.isfinite(traj).all()):
        raise TrajectoryError("trajectory has non-finite (NaN or inf) coordinates")
    return B, P


def _check_goal(goal, traj: torch.Tensor) -> torch.Tensor:
    """-> (B, 2) or (1, 2) tensor on traj's device and dtype."""
    try:
        g = torch.as_tensor(goal, dtype=traj.dtype, device=traj.device)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise TrajectoryError(f"goal must be an (x, y) pair or a (B, 2) array: {exc}") from exc
    B = traj.shape[0]
    if g.shape == (2,):
        g = g[None]
    elif g.shape not in ((B, 2), (1, 2)):
        raise TrajectoryError(f"goal must have shape (2,), (1, 2) or (B, 2) = ({B}, 2), "
                              f"got {tuple(g.shape)}")
    if not bool(torch.isfinite(g).all()):
        raise TrajectoryError("goal has non-finite (NaN or inf) coordinates")
    return g


def _as_footprint_tensor(points, traj: torch.Tensor) -> torch.Tensor:
    """Footprint points as a tensor on traj's device and dtype (no copy if already so)."""
    try:
        return torch.as_tensor(points, dtype=traj.dtype, device=traj.device)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise FootprintError(f"footprint points must be an (R, 2) array: {exc}") from exc


def _check_footprint(fp: torch.Tensor) -> torch.Tensor:
    """Raise FootprintError unless fp is a finite (R, 2) tensor with R >= 1."""
    if fp.ndim != 2 or fp.shape[1] != 2 or fp.shape[0] < 1:
        raise FootprintError(f"footprint points must have shape (R, 2) with R >= 1, "
                             f"got {tuple(fp.shape)}")
    if not bool(torch.isfinite(fp).all()):
        raise FootprintError("footprint points have non-finite coordinates")
    return fp
