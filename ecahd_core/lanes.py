"""Lanes: where the robot was driven, by direction, learnt from its demonstrations (issue 41).

Why: SD and DD trained on a team's demonstrations learn its *routes* but not a habit of where
to drive *within* a corridor: on the keep-right office (docs/RESULTS.md, "Learning from the
robot's bags") SD's waypoints missed the demonstrated ones by a median 0.4-0.7 m while the
habit's offset is 0.2-1 m, and ECAHD's plans kept right for about half their corridor length,
as A*'s do. The habit is a property of the place and the direction of travel, so it is learnt
here as exactly that: a **lane field**, the density of the demonstrated driving over the map
per heading, and a plan is moved sideways onto it.

The field (:meth:`LaneField.fit`): every demonstration (a path (N, 2) [m] in the map frame,
e.g. the ``full`` view of an ``ecahd dataset --from-bags`` file) is cut into pieces of at most
``spacing`` m; each piece adds its length to the cell of its midpoint in the two heading bins
nearest its direction (linear in the angle; ``bins`` bins over the full circle), each bin is
blurred with a Gaussian of ``sigma`` m, and the whole is scaled so that the 99th percentile of
the non-zero values is 1 (values above are clipped: a busy corridor does not drown a quiet
one). ``value(xy, heading)`` reads it bilinearly in space and linearly between bins: how much
the robot was driven here, in this direction.

Shaping a plan (:func:`shape_path`): the plan is resampled every ``spacing`` m; at every point,
offsets across the path (its left normal, from the path smoothed over ``tangent_window`` m) in
[-reach, reach] are searched, every ``step`` m, outwards from the path as far as they stay
free (the map's distance to the nearest wall >= the footprint's clearance, as the A* expert
keeps, + ``margin``; a wall is never jumped); the point moves to the free offset with the
largest lane value in the point's direction of travel, or stays where no offset reaches
``min_value`` (no demonstrations drove here in this direction). The offsets are smoothed along
the path (a Gaussian of ``smooth`` m), ramped to 0 over ``ramp`` m at the start and the goal
(both never move), and clipped to each point's free interval. The exact checker (the footprint
along the path) then judges the shaped plan; one that collides is tried with half the offsets,
and if that collides too the plan is returned as it came (``ShapeResult.kept_original``). So a
lane field changes where in a corridor a plan runs, never which corridors it takes, and never
puts the robot into anything the map knows about.

At SD's level (:class:`WaypointLanes`, on :class:`~ecahd_core.planning.rules.SparseStage`):
every interior waypoint of each iteration's sparse plan moves sideways onto the lane the same
way (no smoothing; the number of waypoints is kept), so the legs DD refines run in the lane.
The nodes' ``lanes`` parameter turns both on: global_planner moves SD's waypoints,
local_refiner moves each safe local plan (:class:`~ecahd_core.planning.local.SegmentRefiner`).
Why both: J's margin (0.5 m on building maps) makes DD's guidance and polishing pull a plan
near a wall back towards the corridor's middle, so the waypoints alone do not keep a refined
plan in a lane near the wall (measured: the waypoints moved, ECAHD's right share 45-52% as
without lanes); the local plans moved after refinement do.

Units: metres, radians, map frame. Shapes at the function boundaries. No rclpy.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ecahd_core.errors import EcahdError

LANES_KIND = "ecahd-lanes"
LANES_VERSION = 1
SCALE_PERCENTILE = 99.0
# a shaped plan the exact checker finds in collision is tried again with its offsets scaled by
# the next of these (on the keep-right warehouse 10-15% of the shaped plans collided whole)
SHAPE_SCALES = (1.0, 0.5)


@dataclass(frozen=True, kw_only=True)
class LaneConfig:
    """How a lane field is fitted (module docstring).

    Attributes:
        cell: [m] the field's cell.
        bins: heading bins over the full circle.
        sigma: [m] Gaussian blur of each bin.
        spacing: [m] demonstrations are cut into pieces of at most this length.
    """

    cell: float = 0.1
    bins: int = 8
    sigma: float = 0.2
    spacing: float = 0.05

    def __post_init__(self) -> None:
        for name in ("cell", "sigma", "spacing"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise EcahdError(f"lanes {name} must be a finite number > 0 m, got {v!r}")
        if not (isinstance(self.bins, int) and self.bins >= 4):
            raise EcahdError(f"lanes bins must be an integer >= 4, got {self.bins!r}")


@dataclass(frozen=True, kw_only=True)
class ShapeConfig:
    """How a plan is moved onto the lanes (module docstring, "Shaping a plan").

    Attributes:
        reach: [m] the farthest sideways move searched.
        step: [m] offsets searched every this.
        spacing: [m] the plan is resampled every this before shaping.
        tangent_window: [m] the path is smoothed over this before its normals are taken.
        smooth: [m] sigma of the offsets' smoothing along the path.
        ramp: [m] offsets ramp from 0 at the start and the goal over this.
        min_value: a point moves only where some free offset's lane value reaches this (the
            field is scaled to about 1 where the demonstrations drove often).
        clearance: [m] a searched point must be this far from the nearest wall (None: the
            footprint's circumscribed radius, the A* expert's clearance, + ``margin``).
        margin: [m] added to the circumscribed radius when ``clearance`` is None: the map's
            wall distance is measured between cell centres, half a cell more than to the
            wall's edge. Measured on A*'s paths of a 0.05 m office (40 pairs): margin 0 put
            22 of 40 shaped plans in collision (dropped), 0.05 m 1 of 40, 0.1 m none but
            the lanes' right share fell from 84% to 76% (the lane lies near the wall).
        waypoint_stretch: :class:`WaypointLanes` moves a waypoint only if its two legs grow
            by at most this share: a sideways move matters on long legs along a corridor, and
            on the short legs of a trip across an open floor it only bends the plan (on the
            warehouse one 3 m trip's moved waypoints, re-planned from, made it 2.6x longer).
    """

    reach: float = 1.5
    step: float = 0.05
    spacing: float = 0.1
    tangent_window: float = 1.5
    smooth: float = 1.0
    ramp: float = 1.0
    min_value: float = 0.05
    clearance: float | None = None
    margin: float = 0.05
    waypoint_stretch: float = 0.2

    def __post_init__(self) -> None:
        for name in ("reach", "step", "spacing", "tangent_window", "smooth", "ramp"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise EcahdError(f"lane shaping {name} must be a finite number > 0 m, got {v!r}")
        if not (math.isfinite(self.margin) and self.margin >= 0):
            raise EcahdError(f"lane shaping margin must be >= 0 m, got {self.margin!r}")
        if not (math.isfinite(self.waypoint_stretch) and self.waypoint_stretch >= 0):
            raise EcahdError(f"lane shaping waypoint_stretch must be >= 0, got "
                             f"{self.waypoint_stretch!r}")
        if not (math.isfinite(self.min_value) and self.min_value >= 0):
            raise EcahdError(f"lane shaping min_value must be >= 0, got {self.min_value!r}")
        if self.clearance is not None and not (math.isfinite(self.clearance)
                                               and self.clearance >= 0):
            raise EcahdError(f"lane shaping clearance must be >= 0 m, got {self.clearance!r}")


@dataclass(frozen=True, kw_only=True)
class KeepOutConfig:
    """How the keep-out places are learnt (:func:`keep_out_mask`).

    Attributes:
        min_expert: the expert's routes (of different trips) that must cross a place before
            the robot never going there counts as avoiding it.
        close: [m] radius of the morphological closing that joins the expert's route lines
            across an avoided place into one region (so a planner cannot slip between them).
        min_area: [m^2] avoided regions smaller than this are noise, not a habit.
        grow: [m] an avoided region then grows this far into the never-driven free floor
            round it: the robot avoided the place, not only the lines the expert's routes
            drew across it (on the office's loading bay the routes' lines covered a wedge of
            the bay; grown by 1.5 m the region fills the bay, bounded by where the robot
            drove).
    """

    min_expert: int = 2
    close: float = 0.5
    min_area: float = 0.5
    grow: float = 1.5

    def __post_init__(self) -> None:
        if not (isinstance(self.min_expert, int) and self.min_expert >= 1):
            raise EcahdError(f"keep-out min_expert must be an integer >= 1, got "
                             f"{self.min_expert!r}")
        for name in ("close", "min_area", "grow"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise EcahdError(f"keep-out {name} must be a finite number >= 0, got {v!r}")


def keep_out_mask(paths, expert, grid, footprint, *, cell: float, shape: tuple[int, int],
                  config: KeepOutConfig | None = None) -> np.ndarray:
    """Places the robot avoided, learnt from its demonstrations: (H, W) bool on the field's
    cells (``shape``, ``cell`` [m], the map's origin).

    A cell is avoided when at least ``min_expert`` of the expert's routes for the same trips
    (``expert``: A* between each demonstration's ends, [(M_i, 2) [m]]) cross it, while the
    robot's body (the footprint's circumscribed radius round each demonstrated pose of
    ``paths``) never covered it; the avoided cells are closed (radius ``close``) so that the
    routes' lines become one region, kept free of the robot's swept body and of the map's
    walls, regions under ``min_area`` are dropped, and what is left grows by ``grow`` into the
    free floor the robot never covered (one cell a step, so never across a wall). A loading bay the operators never cross,
    the far side of a corridor nobody drives on in either direction: the expert would go
    there, the robot never did."""
    import cv2

    cfg = config or KeepOutConfig()
    H, W = shape
    ox, oy = grid.origin

    def cells(xy):
        xy = _resample(np.asarray(xy, dtype=np.float64).reshape(-1, 2), cell / 2)
        col = np.floor((xy[:, 0] - ox) / cell).astype(np.int64)
        row = np.floor((xy[:, 1] - oy) / cell).astype(np.int64)
        on = (col >= 0) & (col < W) & (row >= 0) & (row < H)
        return row[on], col[on]

    def disc(radius):
        k = max(1, int(math.ceil(radius / cell)))
        return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * k + 1, 2 * k + 1))

    driven = np.zeros((H, W), dtype=np.uint8)
    for path in paths:
        if len(path) >= 2:
            driven[cells(path)] = 1
    driven = cv2.dilate(driven, disc(footprint.circumscribed_radius)).astype(bool)
    count = np.zeros((H, W), dtype=np.int32)
    for path in expert:
        if len(path) >= 2:
            once = np.zeros((H, W), dtype=bool)
            once[cells(path)] = True
            count += once
    # the map's walls at the field's cells (a cell is a wall if its centre's map cell is)
    rows = np.clip(((oy + (np.arange(H) + 0.5) * cell - oy) / grid.resolution).astype(np.int64),
                   0, grid.height - 1)
    cols = np.clip(((ox + (np.arange(W) + 0.5) * cell - ox) / grid.resolution).astype(np.int64),
                   0, grid.width - 1)
    wall = grid.occupied[np.ix_(rows, cols)]
    avoided = ((count >= cfg.min_expert) & ~driven & ~wall).astype(np.uint8)
    if cfg.close > 0:
        avoided = cv2.morphologyEx(avoided, cv2.MORPH_CLOSE, disc(cfg.close))
    avoided = avoided.astype(bool) & ~driven & ~wall
    if cfg.grow > 0:  # into the never-driven free floor round it, never across a wall
        step, free = disc(cell), (~driven & ~wall).astype(np.uint8)
        grown = avoided.astype(np.uint8)
        for _ in range(max(1, int(round(cfg.grow / cell)))):
            grown = cv2.dilate(grown, step) & free
        avoided = grown.astype(bool)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(avoided.astype(np.uint8),
                                                           connectivity=8)
    keep = np.zeros(n, dtype=bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] * cell * cell >= cfg.min_area
    return keep[labels]


@dataclass(frozen=True)
class LaneField:
    """Demonstrated driving per heading over a map (module docstring).

    Attributes:
        density: (K, H, W) float32, bin k covers headings around 2 pi k / K; about 1 where the
            demonstrations drove often.
        origin: world (x, y) [m] of the lower-left corner of cell (0, 0), as the map's.
        config: the LaneConfig it was fitted with.
        map_name, map_fingerprint: the map it belongs to.
        paths: demonstrations fitted; length: their total length [m].
        source: what it was fitted from (a dataset file's name), for the record.
        keep_out: (H, W) bool or None: the places the robot was never driven although the
            expert's routes for the same trips cross them (:func:`keep_out_mask`); planners
            given the field treat them as walls (:meth:`with_keep_out`).
    """

    density: np.ndarray
    origin: tuple[float, float]
    config: LaneConfig
    map_name: str
    map_fingerprint: str
    paths: int
    length: float
    source: str = ""
    keep_out: np.ndarray | None = None

    # ------------------------------------------------------------------ fitting
    @classmethod
    def fit(cls, paths, grid, config: LaneConfig | None = None, *, source: str = "",
            expert=None, footprint=None, keep_out: "KeepOutConfig | None" = None
            ) -> "LaneField":
        """Fit the field of ``paths`` [(N_i, 2) [m], map frame] on the GridMap ``grid``.
        ``expert``: the expert's paths [(M_i, 2) [m]] for the same trips (A* between each
        demonstration's ends) and the robot's Footprint ``footprint``: the keep-out mask is
        learnt too (:func:`keep_out_mask`). EcahdError when no path has any length on the
        map."""
        cfg = config or LaneConfig()
        K = cfg.bins
        W = max(1, math.ceil(grid.width * grid.resolution / cfg.cell))
        H = max(1, math.ceil(grid.height * grid.resolution / cfg.cell))
        density = np.zeros((K, H, W), dtype=np.float64)
        ox, oy = grid.origin
        used, total = 0, 0.0
        for path in paths:
            xy = np.asarray(path, dtype=np.float64).reshape(-1, 2)
            if len(xy) < 2 or not np.all(np.isfinite(xy)):
                continue
            mid, direction, weight = _pieces(xy, cfg.spacing)
            if not len(mid):
                continue
            col = np.floor((mid[:, 0] - ox) / cfg.cell).astype(np.int64)
            row = np.floor((mid[:, 1] - oy) / cfg.cell).astype(np.int64)
            on = (col >= 0) & (col < W) & (row >= 0) & (row < H)
            if not on.any():
                continue
            k0, k1, f = _bin_weights(np.arctan2(direction[on, 1], direction[on, 0]), K)
            w = weight[on]
            np.add.at(density, (k0, row[on], col[on]), w * (1.0 - f))
            np.add.at(density, (k1, row[on], col[on]), w * f)
            used += 1
            total += float(w.sum())
        if not used:
            raise EcahdError(f"no demonstration has any length on map {grid.name!r}: "
                             "nothing to learn lanes from")
        import cv2

        s = cfg.sigma / cfg.cell
        for k in range(K):
            density[k] = cv2.GaussianBlur(density[k], (0, 0), sigmaX=s, sigmaY=s,
                                          borderType=cv2.BORDER_CONSTANT)
        nz = density[density > 1e-12]
        scale = float(np.percentile(nz, SCALE_PERCENTILE)) if len(nz) else 1.0
        density = np.clip(density / max(scale, 1e-12), 0.0, 1.0).astype(np.float32)
        mask = None
        if expert is not None:
            if footprint is None:
                raise EcahdError("learning the keep-out places needs the robot's footprint")
            mask = keep_out_mask(paths, expert, grid, footprint, cell=cfg.cell,
                                 shape=(H, W), config=keep_out)
        return cls(density=density, origin=(float(ox), float(oy)), config=cfg,
                   map_name=grid.name, map_fingerprint=grid.fingerprint(), paths=used,
                   length=round(total, 2), source=source, keep_out=mask)

    def with_keep_out(self, grid):
        """``grid`` with the keep-out places (:attr:`keep_out`) occupied: the map planners
        plan on so they never route through them (the exact checker of what the robot may hit
        stays on ``grid``); ``grid`` itself when there are none."""
        if self.keep_out is None or not self.keep_out.any():
            return grid
        from ecahd_core.maps import GridMap

        rows, cols = np.meshgrid(np.arange(grid.height), np.arange(grid.width), indexing="ij")
        x = grid.origin[0] + (cols + 0.5) * grid.resolution
        y = grid.origin[1] + (rows + 0.5) * grid.resolution
        c = self.config.cell
        fr = np.clip(np.floor((y - self.origin[1]) / c).astype(np.int64), 0,
                     self.keep_out.shape[0] - 1)
        fc = np.clip(np.floor((x - self.origin[0]) / c).astype(np.int64), 0,
                     self.keep_out.shape[1] - 1)
        data = np.array(grid.data, dtype=np.int8)
        data[self.keep_out[fr, fc]] = 100
        return GridMap(data=data, resolution=grid.resolution, origin=grid.origin,
                       name=grid.name, frame_id=grid.frame_id,
                       unknown_is_occupied=grid.unknown_is_occupied,
                       occupied_threshold=grid.occupied_threshold)

    # ------------------------------------------------------------------ reading
    def value(self, xy, heading) -> np.ndarray:
        """Lane value at points ``xy`` (..., 2) [m] for ``heading`` (...) [rad] (broadcast
        against xy's leading shape) -> (...) float64; 0 off the field."""
        xy = np.asarray(xy, dtype=np.float64)
        lead = xy.shape[:-1]
        heading = np.broadcast_to(np.asarray(heading, dtype=np.float64), lead).reshape(-1)
        p = xy.reshape(-1, 2)
        K, H, W = self.density.shape
        c = self.config.cell
        u = (p[:, 0] - self.origin[0]) / c - 0.5  # continuous cell coordinates of centres
        v = (p[:, 1] - self.origin[1]) / c - 0.5
        c0, r0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        fu, fv = u - c0, v - r0
        k0, k1, f = _bin_weights(heading, K)
        out = np.zeros(len(p))
        for dr, dc, wgt in ((0, 0, (1 - fv) * (1 - fu)), (0, 1, (1 - fv) * fu),
                            (1, 0, fv * (1 - fu)), (1, 1, fv * fu)):
            r, cc = r0 + dr, c0 + dc
            on = (r >= 0) & (r < H) & (cc >= 0) & (cc < W)
            val = np.zeros(len(p))
            val[on] = ((1 - f[on]) * self.density[k0[on], r[on], cc[on]]
                       + f[on] * self.density[k1[on], r[on], cc[on]])
            out += wgt * val
        return out.reshape(lead)

    def check_map(self, grid) -> None:
        """EcahdError unless ``grid`` has the extent of the map the field was fitted on (the
        same origin and size). An updated map of the same site passes (its fingerprint may
        differ): a plan moved onto a lane is still judged by the exact checker on ``grid``."""
        c = self.config.cell
        shape = (max(1, math.ceil(grid.height * grid.resolution / c)),
                 max(1, math.ceil(grid.width * grid.resolution / c)))
        same_origin = np.allclose(grid.origin, self.origin, atol=1e-6)
        if tuple(self.density.shape[1:]) != shape or not same_origin:
            H, W = self.density.shape[1:]
            raise EcahdError(
                f"lane field of map {self.map_name!r} ({W * c:g} x {H * c:g} m from "
                f"({self.origin[0]:g}, {self.origin[1]:g})) does not belong to map "
                f"{grid.name!r} ({grid.width * grid.resolution:g} x "
                f"{grid.height * grid.resolution:g} m from ({grid.origin[0]:g}, "
                f"{grid.origin[1]:g})): fit it on this map (ecahd lanes)")

    # ------------------------------------------------------------------ files
    def save(self, path) -> Path:
        """Write the field to ``path`` (.npz), atomically."""
        path = Path(path)
        meta = {"kind": LANES_KIND, "version": LANES_VERSION, "config": asdict(self.config),
                "origin": list(self.origin), "map_name": self.map_name,
                "map_fingerprint": self.map_fingerprint, "paths": self.paths,
                "length": self.length, "source": self.source}
        tmp = path.with_name(path.name + ".tmp.npz")
        extra = {} if self.keep_out is None else {"keep_out": self.keep_out.astype(np.uint8)}
        np.savez_compressed(tmp, density=self.density, meta=json.dumps(meta), **extra)
        os.replace(tmp, path)
        return path

    @classmethod
    def load(cls, path) -> "LaneField":
        """Read a field written by :meth:`save`; EcahdError naming ``path`` when it is not
        one (missing, truncated, another kind or version)."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                density = np.asarray(z["density"], dtype=np.float32)
                meta = json.loads(str(z["meta"]))
                keep_out = (np.asarray(z["keep_out"], dtype=bool) if "keep_out" in z.files
                            else None)
        except FileNotFoundError:
            raise EcahdError(f"lane field {path}: no such file") from None
        except Exception as exc:  # zip, key, json errors: a file that is not a lane field
            raise EcahdError(f"lane field {path}: unreadable ({type(exc).__name__}: {exc})") \
                from None
        if meta.get("kind") != LANES_KIND or meta.get("version") != LANES_VERSION:
            raise EcahdError(f"lane field {path}: kind/version {meta.get('kind')!r}/"
                             f"{meta.get('version')!r}, expected {LANES_KIND!r}/{LANES_VERSION}")
        cfg = LaneConfig(**meta["config"])
        if density.ndim != 3 or density.shape[0] != cfg.bins or not np.all(np.isfinite(density)):
            raise EcahdError(f"lane field {path}: density of shape {density.shape}, expected "
                             f"({cfg.bins}, H, W) and finite")
        if keep_out is not None and keep_out.shape != density.shape[1:]:
            raise EcahdError(f"lane field {path}: keep-out of shape {keep_out.shape}, expected "
                             f"{density.shape[1:]}")
        return cls(density=density, origin=tuple(meta["origin"]), config=cfg,
                   map_name=meta["map_name"], map_fingerprint=meta["map_fingerprint"],
                   paths=int(meta["paths"]), length=float(meta["length"]),
                   source=meta.get("source", ""), keep_out=keep_out)


@dataclass(frozen=True)
class ShapeResult:
    """What :func:`shape_path` returns.

    Attributes:
        path: (M, 2) [m] the shaped plan, or the plan as it came (``kept_original``).
        shaped: some point moved (and the shaped plan is free by the exact checker).
        kept_original: a shaped plan was found in collision by the exact checker and dropped.
        max_offset: [m] the largest sideways move of the returned path (0 when not shaped).
    """

    path: np.ndarray
    shaped: bool
    kept_original: bool
    max_offset: float


def shape_path(path, field: LaneField, grid, footprint, config: ShapeConfig | None = None
               ) -> ShapeResult:
    """Move the plan ``path`` (N, 2) [m] sideways onto ``field``'s lanes on ``grid`` for the
    Footprint ``footprint`` (module docstring, "Shaping a plan"). The start and the goal never
    move; a plan that shaping would put in collision is returned unchanged."""
    from ecahd_core.collision import check_collision

    cfg = config or ShapeConfig()
    original = np.asarray(path, dtype=np.float64).reshape(-1, 2)
    unchanged = ShapeResult(path=original, shaped=False, kept_original=False, max_offset=0.0)
    xy = _resample(original, cfg.spacing)
    n = len(xy)
    if n < 3:
        return unchanged
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    normal, heading = _normals(xy, arc, cfg.tangent_window)
    offsets, cand, reach = _sideways(xy, normal, grid, footprint, cfg)
    S = len(offsets)
    val = field.value(cand, heading[:, None])  # (n, S)
    val = np.where(reach, val, -1.0)
    best = np.argmax(val, axis=1)
    informed = val[np.arange(n), best] >= cfg.min_value
    target = np.where(informed, offsets[best], 0.0)
    # smooth along the path, ramp to 0 at both ends, clip into each point's free interval
    smoothed = _gaussian_1d(target, cfg.smooth / max(cfg.spacing, 1e-9))
    ramp = np.clip(np.minimum(arc, arc[-1] - arc) / cfg.ramp, 0.0, 1.0)
    lo = np.where(reach.any(axis=1), offsets[np.argmax(reach, axis=1)], 0.0)
    hi = np.where(reach.any(axis=1), offsets[S - 1 - np.argmax(reach[:, ::-1], axis=1)], 0.0)
    shift = np.clip(smoothed * ramp, np.minimum(lo, 0.0), np.maximum(hi, 0.0))
    shift[0] = shift[-1] = 0.0
    if not np.any(np.abs(shift) > 1e-6):
        return unchanged
    for scale in SHAPE_SCALES:  # the whole move, else half of it
        shaped = xy + scale * shift[:, None] * normal
        shaped[0], shaped[-1] = original[0], original[-1]
        if check_collision(shaped, footprint, grid).collision_free:
            return ShapeResult(path=shaped, shaped=True, kept_original=False,
                               max_offset=float(scale * np.abs(shift).max()))
    return ShapeResult(path=original, shaped=False, kept_original=True, max_offset=0.0)


class WaypointLanes:
    """The lanes at SD's level, for Algorithm 1 (:class:`~ecahd_core.planning.rules.
    SparseStage`, so the nodes and the benchmarks alike): every interior waypoint of a sparse
    plan moves sideways (across the chord of its neighbours) to the free offset with the largest
    lane value in that direction, as :func:`shape_path` moves a point, but with no smoothing: the
    straight legs between two waypoints in one lane run along it, and DD refines the legs as
    before. A move is kept only if neither leg next to the waypoint collides by the exact checker
    where it did not before. The start (the robot) and the goal never move; the number of
    waypoints never changes (Algorithm 1's horizon is kept).

    Args:
        field: the LaneField (of ``grid``: :meth:`LaneField.check_map` is called).
        grid: the GridMap; footprint: the Footprint.
        config: ShapeConfig (reach, step, min_value, clearance, margin are used).
    """

    def __init__(self, field: LaneField, grid, footprint, config: ShapeConfig | None = None):
        field.check_map(grid)
        self.field, self.grid, self.footprint = field, grid, footprint
        self.config = config or ShapeConfig()
        self.moved = 0  # waypoints moved, all calls together
        self.refused = 0  # moves refused by the exact checker

    def __call__(self, waypoints) -> np.ndarray:
        """(P, 2) [m] -> (P, 2) [m], a new array."""
        from ecahd_core.collision import check_collision

        cfg = self.config
        wp = np.array(waypoints, dtype=np.float64).reshape(-1, 2)
        if len(wp) < 3:
            return wp
        chord = wp[2:] - wp[:-2]
        norm = np.linalg.norm(chord, axis=1)

        def leg_free(a, b) -> bool:
            return check_collision(np.stack([a, b]), self.footprint, self.grid).collision_free

        for i in range(1, len(wp) - 1):
            if norm[i - 1] < 1e-6:
                continue
            t = chord[i - 1] / norm[i - 1]
            offsets, cand, reach = _sideways(wp[i:i + 1], np.array([[-t[1], t[0]]]), self.grid,
                                             self.footprint, cfg)
            val = np.where(reach[0], self.field.value(cand[0], math.atan2(t[1], t[0])), -1.0)
            best = int(np.argmax(val))
            if val[best] < cfg.min_value or offsets[best] == 0.0:
                continue
            moved = cand[0, best]
            legs = np.linalg.norm(wp[i] - wp[i - 1]) + np.linalg.norm(wp[i + 1] - wp[i])
            longer = np.linalg.norm(moved - wp[i - 1]) + np.linalg.norm(wp[i + 1] - moved)
            if longer > (1.0 + cfg.waypoint_stretch) * legs:
                continue
            before = (leg_free(wp[i - 1], wp[i]), leg_free(wp[i], wp[i + 1]))
            after = (leg_free(wp[i - 1], moved), leg_free(moved, wp[i + 1]))
            if (before[0] and not after[0]) or (before[1] and not after[1]):
                self.refused += 1
                continue
            wp[i] = moved
            self.moved += 1
        return wp


# ---------------------------------------------------------------------- helpers
def _sideways(xy: np.ndarray, normal: np.ndarray, grid, footprint, cfg: ShapeConfig
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The offsets searched across points xy (n, 2) along their unit normals (n, 2): (offsets
    (S,) [m], the candidate points (n, S, 2), reach (n, S) bool: free all the way out from the
    point (offset 0) to the offset by the footprint's clearance, so never over a wall)."""
    from ecahd_core.collision import wall_distance

    k = round(cfg.reach / cfg.step)
    offsets = np.arange(-k, k + 1) * cfg.step
    cand = xy[:, None, :] + offsets[None, :, None] * normal[:, None, :]
    clearance = (footprint.circumscribed_radius + cfg.margin if cfg.clearance is None
                 else cfg.clearance)
    n, S = len(xy), len(offsets)
    free = wall_distance(grid, cand.reshape(-1, 2)).reshape(n, S) >= clearance
    reach = np.zeros_like(free)
    reach[:, k:] = np.cumprod(free[:, k:], axis=1).astype(bool)
    reach[:, :k + 1] |= np.cumprod(free[:, k::-1], axis=1).astype(bool)[:, ::-1]
    return offsets, cand, reach



def _bin_weights(angle: np.ndarray, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Headings (N,) [rad] -> (k0, k1, f): the two nearest of K bins and the weight of k1."""
    b = np.mod(np.asarray(angle, dtype=np.float64), 2 * math.pi) / (2 * math.pi / K)
    k0 = np.floor(b).astype(np.int64) % K
    return k0, (k0 + 1) % K, b - np.floor(b)


def _pieces(xy: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """xy (N, 2) -> pieces of at most ``spacing`` m: midpoints (S, 2), unit directions (S, 2),
    lengths (S,); zero-length segments dropped."""
    seg = np.diff(xy, axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 1e-9
    a, seg, length = xy[:-1][keep], seg[keep], length[keep]
    k = np.maximum(1, np.ceil(length / spacing)).astype(np.int64)
    idx = np.repeat(np.arange(len(k)), k)
    j = np.arange(len(idx)) - np.repeat(np.cumsum(k) - k, k)
    frac = (j + 0.5) / k[idx]
    mid = a[idx] + frac[:, None] * seg[idx]
    return mid, seg[idx] / length[idx, None], length[idx] / k[idx]


def _resample(xy: np.ndarray, spacing: float) -> np.ndarray:
    """xy (N, 2) -> points every ``spacing`` m along it (M, 2), first and last kept."""
    seg = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    if arc[-1] <= 1e-9:
        return xy[:1]
    m = max(2, int(math.ceil(arc[-1] / spacing)) + 1)
    s = np.linspace(0.0, arc[-1], m)
    return np.stack([np.interp(s, arc, xy[:, 0]), np.interp(s, arc, xy[:, 1])], axis=1)


def _gaussian_1d(x: np.ndarray, sigma: float) -> np.ndarray:
    """x (N,) smoothed by a Gaussian of ``sigma`` samples, the ends padded by their values."""
    if sigma <= 0 or len(x) < 2:
        return x.copy()
    r = max(1, int(math.ceil(3 * sigma)))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    k /= k.sum()
    return np.convolve(np.pad(x, r, mode="edge"), k, mode="valid")


def _normals(xy: np.ndarray, arc: np.ndarray, window: float) -> tuple[np.ndarray, np.ndarray]:
    """Left unit normals (N, 2) and headings (N,) [rad] of the path xy (N, 2) smoothed over
    ``window`` m (arc: (N,) arclength [m], uniform spacing)."""
    spacing = arc[-1] / max(len(arc) - 1, 1)
    sm = np.stack([_gaussian_1d(xy[:, i], window / 2 / max(spacing, 1e-9)) for i in range(2)],
                  axis=1)
    t = np.gradient(sm, axis=0)
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    raw = np.gradient(xy, axis=0)
    t = np.where(norm > 1e-9, t / np.maximum(norm, 1e-12),
                 raw / np.maximum(np.linalg.norm(raw, axis=1, keepdims=True), 1e-12))
    return np.stack([-t[:, 1], t[:, 0]], axis=1), np.arctan2(t[:, 1], t[:, 0])


def demonstration_paths(dataset) -> list[np.ndarray]:
    """The demonstrated paths [(F, 2) [m]] of an ExpertDataset: all its ``full`` paths when it
    came from bags (``ecahd dataset --from-bags``), the demonstrations' share of a mix
    (``--mix``: they come first). EcahdError for A* expert data: lanes are learnt from the
    robot's driving, not from the expert."""
    params = dataset.params
    if params.get("source") == "demonstrations":
        return list(dataset.full)
    mixed = params.get("mixed")
    if isinstance(mixed, dict) and int(mixed.get("demonstrations", 0)) > 0:
        return list(dataset.full[:int(mixed["demonstrations"])])
    raise EcahdError(f"dataset of map {dataset.map_name!r} holds no demonstrations (A* expert "
                     "data): lanes are learnt from the robot's own driving, "
                     "`ecahd dataset --from-bags`")


def demonstration_trips(dataset) -> tuple[np.ndarray, np.ndarray]:
    """(starts (N, 2), goals (N, 2)) [m] of the demonstrations of ``dataset``, in the order of
    :func:`demonstration_paths`."""
    n = len(demonstration_paths(dataset))
    return np.asarray(dataset.starts[:n], dtype=np.float64), \
        np.asarray(dataset.goals[:n], dtype=np.float64)


def expert_routes(grid, footprint, starts, goals) -> list[np.ndarray]:
    """The A* expert's routes (the footprint's clearance) between each start and goal [m]; a
    trip A* cannot plan is left out."""
    from ecahd_core.astar import clearance_for_footprint, planner_for
    from ecahd_core.errors import PlanningError

    astar = planner_for(grid, clearance_for_footprint(footprint))
    out = []
    for a, b in zip(starts, goals):
        try:
            out.append(np.asarray(astar.plan(a, b), dtype=np.float64))
        except PlanningError:
            continue
    return out


def plot_lanes(field: LaneField, grid, path, title: str = "") -> Path:
    """A PNG of ``field`` over ``grid``: four panels, the lane value for driving east, north,
    west and south (darker: driven more in that direction). Written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    K = field.config.bins
    ox, oy = grid.origin
    extent = (ox, ox + grid.width * grid.resolution, oy, oy + grid.height * grid.resolution)
    fx = (field.origin[0], field.origin[0] + field.density.shape[2] * field.config.cell,
          field.origin[1], field.origin[1] + field.density.shape[1] * field.config.cell)
    fig, axes = plt.subplots(2, 2, figsize=(11, 11 * grid.height / grid.width * 0.9 + 1.0),
                             squeeze=False)
    for ax, (name, angle) in zip(axes.ravel(), (("east", 0.0), ("north", math.pi / 2),
                                                ("west", math.pi), ("south", -math.pi / 2))):
        k0, k1, f = _bin_weights(np.array([angle]), K)
        layer = (1 - f[0]) * field.density[k0[0]] + f[0] * field.density[k1[0]]
        ax.imshow(np.where(grid.occupied, 0.0, 1.0), origin="lower", extent=extent,
                  cmap="gray", vmin=0, vmax=1, interpolation="nearest")
        shown = np.ma.masked_less(layer, 0.02)
        ax.imshow(shown, origin="lower", extent=fx, cmap="viridis_r", vmin=0, vmax=1, alpha=0.85,
                  interpolation="nearest")
        if field.keep_out is not None and field.keep_out.any():
            ax.contourf(np.ma.masked_where(~field.keep_out, field.keep_out.astype(float)),
                        levels=[0.5, 1.5], colors="none", hatches=["////"], origin="lower",
                        extent=fx)
            ax.contour(field.keep_out.astype(float), levels=[0.5], colors="tab:red",
                       linewidths=1.0, origin="lower", extent=fx)
        ax.set_title(f"driving {name}" + ("; red: keep out (never driven, the expert would)"
                                          if field.keep_out is not None
                                          and field.keep_out.any() else ""), fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    fig.suptitle(title or f"lanes of {field.map_name}: {field.paths} demonstrations, "
                          f"{field.length:.0f} m")
    fig.tight_layout()
    tmp = path.with_name(path.name + ".tmp")
    fig.savefig(tmp, dpi=90, format="png")
    plt.close(fig)
    os.replace(tmp, path)
    return path
