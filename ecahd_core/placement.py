"""Waypoints in free space (ours, beyond the paper; issue 10).

Sparse Diffusion works in coordinates normalised by the map's size, so its waypoint error grows
with the map: on a 60 x 60 m office 26-30% of the segments between SD's waypoints have a waypoint
inside a wall, often deeper than 0.2 m (docs/RESULTS.md, "Where ECAHD alone collides on the
office"). No local plan that ends in a wall is free, whatever DD and polishing do.
:class:`WaypointPlacer` moves each such waypoint to a pose the footprint clears, within
``reach``, choosing among the free positions the one whose straight legs to its neighbours
cross the fewest walls (then the nearest): a waypoint pushed out of a wall on the wrong side
would leave its segments crossing that wall.

Cost: one distance transform of the map (built once per map, ~40 ms on 2000 x 2000 cells) and,
for each waypoint in a wall, a lattice of candidate positions judged by the exact checker near
walls and scored on the distance transform.
"""
from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from ecahd_core.errors import EcahdError

PLACE_REACH = 1.0  # [m] how far a waypoint in a wall may move (docs/RESULTS.md, issue 10)
PLACE_STEP = 0.05  # [m] candidate lattice (at least the map's resolution)
LEG_WEIGHT = 4.0  # metres of displacement one metre of leg crossing a wall is worth
LEG_ROUNDS = 3  # rounds of leg repair (a leg crossing a wall gets a placed midpoint)
# [m] how far leg repair looks for a leg's new waypoint (at least ``reach``): a door or an aisle
# end a few metres from where SD's leg crosses a wall. 3 m took ECAHD alone on warehouse 2 from
# 89.1% to 94.8% of 192 held-out plans (docs/RESULTS.md, 2026-12-03 06:34)
REPAIR_REACH = 3.0
# more SD batches a re-plan may draw for a first leg that crosses no wall, one waypoint more each
# (planner.SparseConfig.leg_batches; office 2, 32 development plans: ECAHD alone 56% -> 88%)
LEG_BATCHES = 3
# rounds in which planner.HierarchicalPlanner takes another SD candidate at a re-plan whose local
# plan the exact checker still finds in collision (its ``backtracks``; 0: off)
BACKTRACKS = 2
REPAIR_CANDIDATES = 30  # lattice steps across a repair reach at most (a coarser step beyond)
# candidates per side the two-bend repair pairs up (TWO_BEND_SAMPLES^2 legs judged at most)
TWO_BEND_SAMPLES = 48
# legs per array in WaypointPlacer.wall_length (sorted by length: the short ones are not padded
# to the longest one's samples; fewer, larger arrays since its cells are read by cv2.remap)
WALL_CHUNK = 1024


class WaypointPlacer:
    """Moves the waypoints that the exact checker finds in collision into free space.

    Args:
        grid: the GridMap the waypoints must clear (occupied cells, off-map counts as occupied).
        footprint: the robot's Footprint (judged facing along each waypoint's incoming leg).
        reach: [m] the farthest a waypoint moves; one with no free position within reach stays.
        step: [m] spacing of the candidate positions (None: max(PLACE_STEP, resolution)).
        leg_rounds: rounds of :meth:`repair` after :meth:`place` (0: waypoints only).
        repair_reach: [m] how far from a leg's middle :meth:`repair` looks for its new
            waypoint (at most half the leg; None: the larger of ``reach`` and REPAIR_REACH);
            its lattice step is at least repair_reach / REPAIR_CANDIDATES.
        two_bends: where no single new waypoint makes a leg cross less wall, :meth:`repair`
            tries two (:meth:`_two_bends`, on the same lattice).
    """

    def __init__(self, grid, footprint, *, reach: float = PLACE_REACH,
                 step: float | None = None, leg_rounds: int = LEG_ROUNDS,
                 repair_reach: float | None = None, two_bends: bool = True) -> None:
        from ecahd_core.sensing import StaticClearance

        if not (math.isfinite(reach) and reach > 0):
            raise EcahdError(f"the waypoint placement's reach must be a finite number > 0 m, "
                             f"got {reach}")
        self.grid, self.footprint, self.reach = grid, footprint, float(reach)
        self.step = float(step) if step is not None else max(PLACE_STEP, grid.resolution)
        if leg_rounds < 0:
            raise EcahdError(f"leg_rounds must be >= 0, got {leg_rounds}")
        self.leg_rounds = int(leg_rounds)
        self.two_bends = bool(two_bends)
        self.repair_reach = (max(self.reach, REPAIR_REACH) if repair_reach is None
                             else float(repair_reach))
        if not (math.isfinite(self.repair_reach) and self.repair_reach > 0):
            raise EcahdError(f"leg repair's reach must be a finite number > 0 m, "
                             f"got {repair_reach}")
        self.clearance = StaticClearance(grid)
        self._offsets = self.lattice(self.reach)  # (K, 2), nearest first
        repair_step = max(self.step, self.repair_reach / REPAIR_CANDIDATES)
        self._repair_offsets = (self._offsets if repair_step <= self.step
                                else self.lattice(self.repair_reach, step=repair_step))
        # a circle of the inscribed radius centred on a cell centre this near an occupied cell
        # centre may overlap that cell (whose corner lies half a cell diagonal nearer)
        self._near = footprint.inscribed_radius + math.sqrt(0.5) * grid.resolution
        # a straight leg's interior sweeps a band of the footprint's half-width across its
        # heading (wider than the inscribed radius for a robot wider than long, the humanoid)
        self._band, self._trim = leg_band(footprint)

    def __call__(self, waypoints, *, last_reach: float | None = 0.0,
                 legs: int | None = None) -> tuple[np.ndarray, int]:
        """:meth:`place`, then :meth:`repair` (``leg_rounds``, the first ``legs`` legs; None:
        all): (P, 2) [m] -> ((P', 2) [m], waypoints moved or added)."""
        xy, moved = self.place(waypoints, last_reach=last_reach)
        xy, added = self.repair(xy, legs=legs)
        return xy, moved + added

    def lattice(self, reach: float, *, step: float | None = None) -> np.ndarray:
        """(K, 2) [m] offsets of a square lattice of ``step`` (None: the placer's) within
        ``reach``, nearest first."""
        step = self.step if step is None else step
        n = int(reach / step)
        off = np.stack(np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1)), -1)
        off = off.reshape(-1, 2) * step
        dist = np.linalg.norm(off, axis=1)
        keep = dist <= reach + 1e-9
        return off[keep][np.argsort(dist[keep], kind="stable")]

    def _repair_lattice(self, reach: float) -> np.ndarray:
        """The lattice leg repair searches within ``reach`` [m] (<= ``repair_reach``):
        placement's own, or a coarser one for a repair reach wider than REPAIR_CANDIDATES
        steps."""
        return _nearest_within(self._repair_offsets, reach)

    def _within(self, reach: float) -> np.ndarray:
        """:meth:`lattice` of ``reach`` (a prefix of the one built for ``self.reach``)."""
        return _nearest_within(self._offsets, reach)

    def blocked(self, waypoints) -> np.ndarray:
        """(P, 2) [m] -> (P,) bool: the footprint placed at each waypoint, facing along its
        incoming leg (the first along its outgoing one), overlaps the map."""
        from ecahd_core.collision import DEFAULT_TOLERANCE

        xy = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
        return self.clearance.depths(np.column_stack([xy, headings(xy)]),
                                     self.footprint) > DEFAULT_TOLERANCE

    def place(self, waypoints, *, last_reach: float | None = 0.0) -> tuple[np.ndarray, int]:
        """Move every blocked waypoint after the first (the robot's start stays) to the free
        position within reach whose straight legs to the previous and next waypoints cross the
        least wall (length [m] of leg within the footprint's inscribed radius of an occupied
        cell, weighted by LEG_WEIGHT), then the nearest. Waypoints are placed in order, so each
        one's previous neighbour is already placed.

        waypoints: (P, 2) [m]; last_reach: [m] the last waypoint's own reach (0: it stays, as a
        goal the caller checked does; None: ``reach``).
        Returns (placed (P, 2) [m] float64, how many moved)."""
        xy = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2).copy()
        if len(xy) < 2 or not np.isfinite(xy).all():
            return xy, 0
        bad = np.flatnonzero(self.blocked(xy))
        bad = bad[bad > 0]
        last = len(xy) - 1
        moved = 0
        for i in bad.tolist():
            reach = self.reach if i < last or last_reach is None else float(last_reach)
            if reach <= 0:
                continue
            nxt = xy[i + 1] if i < last else None
            best = self._best(xy[i], self._within(reach), xy[i - 1], nxt)
            if best is not None:
                xy[i] = best
                moved += 1
        return xy, moved

    def repair(self, waypoints, *, rounds: int | None = None,
               legs: int | None = None) -> tuple[np.ndarray, int]:
        """Leg repair (ours): every straight leg that passes nearer a wall than the footprint
        fits (:meth:`wall_length` > 0) gets a new waypoint, its midpoint placed (within half the
        leg's length, at most ``reach``) where the two new legs cross the least wall; kept only
        if that is less than the old leg's; where no single waypoint does, two
        (:meth:`_two_bends`, when ``two_bends``). ``rounds`` (default ``leg_rounds``) times.
        ``legs``: only the first ``legs`` legs, and what they become (None: every leg; a
        re-plan that follows only its first leg needs no more, and gets the same first leg).
        waypoints: (P, 2) [m] -> ((P', 2) [m], P' - P waypoints added); the ends stay."""
        xy = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
        added = 0
        span = len(xy) - 1 if legs is None else min(int(legs), len(xy) - 1)  # legs to repair
        failed = set()  # legs no waypoint improved: a later round would search them in vain
        for _ in range(self.leg_rounds if rounds is None else rounds):
            if len(xy) < 2:
                break
            walls = self.leg_walls(xy[:span + 1])  # (span,)
            if not (walls > 0).any():
                break
            pieces, grown = [xy[:1]], 0
            for k in range(len(xy) - 1):
                a, b = xy[k], xy[k + 1]
                if k < span and walls[k] > 0 and (leg := (a.tobytes(), b.tobytes())) not in failed:
                    reach = min(self.repair_reach, 0.5 * float(np.linalg.norm(b - a)))
                    mid = self._best(0.5 * (a + b), self._repair_lattice(reach), a, b,
                                     need=walls[k])
                    if mid is None and self.two_bends:
                        mid = self._two_bends(a, b, need=walls[k])
                    if mid is None:
                        failed.add(leg)
                    else:
                        mid = mid.reshape(-1, 2)
                        pieces.append(mid)
                        grown += len(mid)
                pieces.append(b[None])
            xy = np.concatenate(pieces)
            span, added = span + grown, added + grown
        return xy, added

    def _two_bends(self, a: np.ndarray, b: np.ndarray, *, need: float) -> np.ndarray | None:
        """Two new waypoints (2, 2) [m] for the leg a -> b, m1 seen from ``a`` and m2 seen from
        ``b`` (their legs cross no more wall than the least of any candidate's) with m1 -> m2
        crossing none: the way round an obstacle that no single bend finds. Candidates: the
        repair lattice round the leg's middle, at most TWO_BEND_SAMPLES per side (the best by
        the detour's length, then evenly over the rest); the shortest pair whose three legs
        cross less wall than ``need`` [m] and whose two poses the exact checker finds free.
        None if there is none."""
        from ecahd_core.collision import DEFAULT_TOLERANCE

        cand = 0.5 * (a + b) + self._repair_offsets
        cand = cand[self.grid.in_bounds(cand)]
        cand = cand[self.clearance.wall_distance(cand) >= self._near]
        if len(cand) == 0:
            return None
        tol = self.grid.resolution
        sides = []
        for end in (a, b):
            walls = self.wall_length(end, cand)
            seen = cand[walls <= walls.min() + tol]
            detour = np.linalg.norm(seen - a, axis=1) + np.linalg.norm(seen - b, axis=1)
            sides.append(_spread(seen[np.argsort(detour, kind="stable")], TWO_BEND_SAMPLES))
        m1 = np.repeat(sides[0], len(sides[1]), axis=0)  # (K1 K2, 2)
        m2 = np.tile(sides[1], (len(sides[0]), 1))
        free = self.wall_length(m1, m2) == 0
        m1, m2 = m1[free], m2[free]
        if len(m1) == 0:
            return None
        length = (np.linalg.norm(m1 - a, axis=1) + np.linalg.norm(m2 - m1, axis=1)
                  + np.linalg.norm(b - m2, axis=1))
        for i in np.argsort(length, kind="stable")[:TWO_BEND_SAMPLES].tolist():
            path = np.stack([a, m1[i], m2[i], b])
            if not float(self.leg_walls(path).sum()) < need:
                continue
            pose = np.column_stack([path[1:3], headings(path)[1:3]])
            if (self.clearance.depths(pose, self.footprint) <= DEFAULT_TOLERANCE).all():
                return path[1:3]
        return None

    def leg_walls(self, xy: np.ndarray) -> np.ndarray:
        """(P, 2) [m] -> (P - 1,) :meth:`wall_length` of each straight leg."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return self.wall_length(xy[:-1], xy[1:])

    def _best(self, at: np.ndarray, off: np.ndarray, prev: np.ndarray, nxt: np.ndarray | None,
              *, need: float | None = None) -> np.ndarray | None:
        """The free position among ``at + off`` ((K, 2) [m], nearest first) with the least
        LEG_WEIGHT x (wall length of the legs from ``prev`` and to ``nxt``) + distance from
        ``at``; None if no position is free, or (with ``need``) none makes the legs cross less
        wall than ``need`` [m].

        The score needs only the distance transform, so every candidate is scored first and the
        exact checker (the cost: a polygon test per pose near walls) judges them in score order,
        a chunk at a time, until one is free: the first free one is the argmin over the free
        ones (ties: the nearest, as ``off`` is ordered)."""
        from ecahd_core.collision import DEFAULT_TOLERANCE

        cand = at + off
        cand = cand[self.grid.in_bounds(cand)]
        # the footprint cannot fit where the nearest wall is nearer than its inscribed radius
        if len(cand):
            near = self.clearance.wall_distance(cand) + math.sqrt(2.0) * self.grid.resolution
            cand = cand[near > self.footprint.inscribed_radius]
        if len(cand) == 0:
            return None
        walls = self.wall_length(prev, cand)
        if nxt is not None:
            walls = walls + self.wall_length(nxt, cand)
        score = LEG_WEIGHT * walls + np.linalg.norm(cand - at, axis=1)
        order = np.argsort(score, kind="stable")  # stable: the nearest first among ties
        start, chunk = 0, 16
        while start < len(order):
            idx = order[start:start + chunk]
            d = cand[idx] - prev
            heading = np.arctan2(d[:, 1], d[:, 0])  # facing along the incoming leg
            depth = self.clearance.depths(np.column_stack([cand[idx], heading]),
                                          self.footprint)
            free = np.flatnonzero(depth <= DEFAULT_TOLERANCE)
            if len(free):
                k = int(idx[free[0]])
                if need is not None and not walls[k] < need:
                    return None
                return cand[k]
            start, chunk = start + chunk, chunk * 4
        return None

    def wall_length(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Length [m] of each straight leg from ``a`` (2,) or (K, 2) to ``b`` (K, 2) where the
        footprint moving along it may touch an occupied cell -> (K,): where a circle of the
        footprint's inscribed radius may touch one, or, farther than :func:`leg_band`'s trim
        from both ends, a circle of its half-width across the heading (a circle that lies
        within the swept footprint, so a leg this finds near a wall collides; the distance
        transform of cell centres, less half a cell diagonal; each leg sampled at
        ceil(length / resolution) + 1 evenly spaced points, so a leg's value does not depend on
        the others)."""
        b = np.asarray(b, dtype=np.float64).reshape(-1, 2)
        a = np.broadcast_to(np.asarray(a, dtype=np.float64), b.shape)
        d = b - a
        length = np.linalg.norm(d, axis=1)  # (K,)
        counts = np.ceil(length / self.grid.resolution).astype(np.int64) + 1  # (K,) >= 1
        counts = np.maximum(counts, 2)
        if len(b) <= WALL_CHUNK:
            return self._wall_length(a, d, length, counts)
        # legs of similar sample counts together, so that few samples pad the shorter ones
        order = np.argsort(counts, kind="stable")
        out = np.empty(len(b))
        for rows in np.array_split(order, -(-len(b) // WALL_CHUNK)):
            out[rows] = self._wall_length(a[rows], d[rows], length[rows], counts[rows])
        return out

    def _wall_length(self, a: np.ndarray, d: np.ndarray, length: np.ndarray,
                     counts: np.ndarray) -> np.ndarray:
        """:meth:`wall_length` of K legs from ``a`` (K, 2) [m] along ``d`` (K, 2) [m] of
        ``length`` (K,) [m], each sampled at ``counts`` (K,) >= 2 points -> (K,) [m].

        The samples' cells are read by one ``cv2.remap`` (nearest) on float32 cell coordinates
        (a sample within ~1e-4 cell of a cell's edge may be read in its neighbour): a quarter of
        the time per call of numpy's index arithmetic in float64 before 2026-12-07 21:30 (the
        profile of docs/general.md, "What remains")."""
        grid = self.grid
        res, (ox, oy) = grid.resolution, grid.origin[:2]
        n = int(counts.max(initial=2))
        t = np.arange(n, dtype=np.float32)[None, :] / (counts[:, None] - 1).astype(np.float32)
        np.minimum(t, 1.0, out=t)  # samples past a leg's count repeat its end (t = 1)
        # cell coordinates less half a cell (remap's nearest rounds where GridMap.world_to_cell
        # floors) plus EDGE_SHIFT, so that a sample on a cell's edge (waypoints on a lattice of
        # the resolution) is read in the cell above it, as floor reads it, not rounded to even
        u = t * (d[:, :1] / res).astype(np.float32)
        u += ((a[:, :1] - ox) / res - (0.5 - EDGE_SHIFT)).astype(np.float32)
        v = t * (d[:, 1:] / res).astype(np.float32)
        v += ((a[:, 1:] - oy) / res - (0.5 - EDGE_SHIFT)).astype(np.float32)
        near = read_cells(self._near_image, u, v)  # (K, n) 0 / 1
        if self._band is not None:
            along = t * length[:, None]  # (K, n) [m] from a
            inner = (along >= self._trim) & (along <= length[:, None] - self._trim)
            near |= inner & read_cells(self._band_image, u, v).astype(bool)
        # the samples from a leg's count - 1 on are all its end (t = 1): counted once
        hits = near.sum(axis=1, dtype=np.int64) - (n - counts) * near[:, -1]
        return hits / counts * length

    @cached_property
    def _near_image(self) -> np.ndarray:
        """(H, W) uint8: 1 where a cell's centre lies nearer an occupied cell centre than
        ``_near`` (:meth:`wall_length`'s test, the same as ``StaticClearance.wall_distance(...)
        < _near``; off the map reads as 1)."""
        return (self.grid.free_distance < self._near).astype(np.uint8)

    @cached_property
    def _band_image(self) -> np.ndarray:
        """As :attr:`_near_image` for a circle of the footprint's half-width (:func:`leg_band`)."""
        near = self._band + math.sqrt(0.5) * self.grid.resolution
        return (self.grid.free_distance < near).astype(np.uint8)


# [cells] WaypointPlacer.wall_length reads a sample this near below a cell's edge in the cell
# above it (float32 cell coordinates; an edge is where waypoints on a lattice of the resolution lie)
EDGE_SHIFT = 2.0 ** -10
# cv2.remap takes images and outputs under 32 767 pixels a side: larger ones are read in pieces
REMAP_SIDE = 16_384


def read_cells(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``image`` (H, W) uint8 read at the nearest pixel of each (column ``u``, row ``v``)
    ((K, n) float32 each) -> (K, n) uint8; off the image (or NaN): 1. One ``cv2.remap`` where
    the image and the output fit it; else in pieces: columns of the output, then windows of
    the image round the samples (maps wider than REMAP_SIDE cells)."""
    import cv2

    K, n = u.shape
    if K == 0 or n == 0:
        return np.ones((K, n), dtype=np.uint8)
    if n > REMAP_SIDE:
        return np.concatenate([read_cells(image, u[:, j:j + REMAP_SIDE], v[:, j:j + REMAP_SIDE])
                               for j in range(0, n, REMAP_SIDE)], axis=1)
    H, W = image.shape
    x0 = y0 = 0
    if max(H, W) > REMAP_SIDE or K > REMAP_SIDE:
        with np.errstate(invalid="ignore"):
            lo = [np.nanmin(u, initial=np.inf), np.nanmin(v, initial=np.inf)]
            hi = [np.nanmax(u, initial=-np.inf), np.nanmax(v, initial=-np.inf)]
        x0, y0 = (int(np.clip(np.floor(q) - 1, 0, m)) for q, m in zip(lo, (W, H)))
        x1, y1 = (int(np.clip(np.ceil(q) + 2, 0, m)) for q, m in zip(hi, (W, H)))
        if max(x1 - x0, y1 - y0, K) > REMAP_SIDE:  # samples spread wider: half the legs each
            if K == 1:
                half = n // 2
                return np.concatenate([read_cells(image, u[:, :half], v[:, :half]),
                                       read_cells(image, u[:, half:], v[:, half:])], axis=1)
            return np.concatenate([read_cells(image, u[:K // 2], v[:K // 2]),
                                   read_cells(image, u[K // 2:], v[K // 2:])])
        if x1 <= x0 or y1 <= y0:  # every sample off the map
            return np.ones((K, n), dtype=np.uint8)
        image, u, v = image[y0:y1, x0:x1], u - np.float32(x0), v - np.float32(y0)
    return cv2.remap(image, u, v, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=1)


def leg_band(footprint) -> tuple[float | None, float]:
    """(half-width [m] of the band a straight leg's interior sweeps, trim [m]): the footprint's
    half-width across its heading (its polygon's largest |y|) where that exceeds its inscribed
    radius (else None: the inscribed circle is the test everywhere, as for a circle or a robot
    longer than wide), and how far from each end of a leg a circle of that half-width would
    reach beyond the footprint's front or back (half-width - the shorter of its front and back
    half-lengths; 0.125 m for the 0.25 x 0.5 m humanoid)."""
    poly = np.asarray(footprint.polygon, dtype=np.float64)
    half = float(np.abs(poly[:, 1]).max())
    if footprint.is_circle or half <= footprint.inscribed_radius + 1e-9:
        return None, 0.0
    ahead = min(float(poly[:, 0].max()), float(-poly[:, 0].min()))
    return half, max(0.0, half - ahead)


def _spread(points: np.ndarray, n: int) -> np.ndarray:
    """At most ``n`` of ``points`` (K, 2) in their order: the first n / 2, then evenly spaced
    over the rest."""
    if len(points) <= n:
        return points
    head = n // 2
    rest = np.linspace(head, len(points) - 1, n - head).round().astype(np.int64)
    return np.concatenate([points[:head], points[rest]])


def _nearest_within(offsets: np.ndarray, reach: float) -> np.ndarray:
    """The offsets (K, 2) [m] of a lattice ordered nearest first that lie within ``reach`` [m]:
    a prefix, the same as the lattice built for ``reach`` itself."""
    norms = np.linalg.norm(offsets, axis=1)
    return offsets[:np.searchsorted(norms, reach + 1e-9, "right")]


def headings(xy: np.ndarray) -> np.ndarray:
    """(P, 2) [m] -> (P,) [rad]: each waypoint's incoming leg direction (the first: its
    outgoing one)."""
    if len(xy) < 2:
        return np.zeros(len(xy))
    d = np.diff(xy, axis=0)
    h = np.arctan2(d[:, 1], d[:, 0])
    return np.concatenate([h[:1], h])


def placer_for(grid, footprint, reach: float | None = None, *,
               leg_rounds: int = LEG_ROUNDS, general: bool = False) -> WaypointPlacer | None:
    """The SparseDiffusion ``placer`` the commands use: ``reach`` [m] > 0 places within it, 0
    turns placement off (SD's waypoints as sampled, the paper), None chooses by the map: on
    (PLACE_REACH) for maps over ``astar.COARSE_ABOVE_CELLS`` cells, the building maps where
    SD's waypoint error exceeds a wall's thickness; off on smaller maps such as maze2d-large,
    whose tables keep the paper's setting, unless SD is the map-conditioned generalist
    (``general``; :func:`auto_reach`)."""
    if reach is None:
        reach = auto_reach(grid, general=general)
    if reach < 0 or not math.isfinite(reach):
        raise EcahdError(f"the waypoint placement's reach must be >= 0 m (0: off), got {reach}")
    if reach == 0:
        return None
    return WaypointPlacer(grid, footprint, reach=reach, leg_rounds=leg_rounds)


def auto_reach(grid, *, general: bool = False) -> float:
    """[m] the placement ``reach`` chosen by the map and the SD model: PLACE_REACH on maps over
    ``astar.COARSE_ABOVE_CELLS`` cells and, for the map-conditioned generalist (``general``),
    on any map; 0 (off) on smaller maps with a per-map model (maze2d's tables keep the
    paper's setting)."""
    from ecahd_core.astar import COARSE_ABOVE_CELLS

    return PLACE_REACH if general or grid.width * grid.height > COARSE_ABOVE_CELLS else 0.0
