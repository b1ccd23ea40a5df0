"""Robot footprints and their interior sample points R (paper Sec. III-B, Algorithm 2 line 17).

Robot frame: x forward (the heading), y to the left, metres. A footprint is a polygon (or an
exact circle) plus the set of points R placed inside it and on its outline; the cost J sweeps
those points along a trajectory.

Presets (top views):
- ``circle``    radius 0.4 m (the paper's circular robot)
- ``quadruped`` Unitree Go1, about 0.65 m long x 0.30 m wide (long along the heading)
- ``humanoid``  Unitree G1, about 0.25 m deep x 0.50 m wide (wide across the heading)
Any polygon can be given in Nav2's footprint string format ``"[[x, y], [x, y], ...]"``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ecahd_core.errors import FootprintError

DEFAULT_SPACING = 0.15  # [m] distance between footprint sample points
CIRCLE_RADIUS = 0.4  # [m] the paper's circular robot
PRESETS: dict[str, tuple[float, float] | float] = {
    "circle": CIRCLE_RADIUS,  # radius [m]
    "quadruped": (0.65, 0.30),  # length along x, width along y [m] (Unitree Go1)
    "humanoid": (0.25, 0.50),  # depth along x, width along y [m] (Unitree G1)
}
_CIRCLE_OUTLINE_VERTICES = 32


@dataclass(frozen=True)
class Footprint:
    """A robot footprint.

    Attributes:
        name: preset name or "polygon".
        polygon: (V, 2) outline [m] in the robot frame, counter-clockwise. For a circle, a
            regular 32-gon inscribed in the circle, used for drawing only.
        points: (R, 2) sample points R [m]: outline plus interior, centre included.
        radius: the exact radius [m] for circular robots, else None.
    """

    name: str
    polygon: np.ndarray
    points: np.ndarray
    radius: float | None = None

    @property
    def is_circle(self) -> bool:
        return self.radius is not None

    @property
    def circumscribed_radius(self) -> float:
        """Largest distance [m] from the robot centre to the outline."""
        if self.radius is not None:
            return float(self.radius)
        return float(np.max(np.linalg.norm(self.polygon, axis=1)))

    @property
    def inscribed_radius(self) -> float:
        """Smallest distance [m] from the robot centre to the outline."""
        if self.radius is not None:
            return float(self.radius)
        a = self.polygon
        b = np.roll(a, -1, axis=0)
        return float(np.min(point_segment_distance(np.zeros((1, 2)), a, b)))

    def transformed(self, xy: np.ndarray, heading: np.ndarray, which: str = "points") -> np.ndarray:
        """Place the footprint at poses. xy: (..., 2) [m], heading: (...) [rad]
        -> (..., N, 2) world coordinates of ``points`` or ``polygon`` (Eqs. 7-8)."""
        local = self.points if which == "points" else self.polygon
        c, s = np.cos(heading)[..., None], np.sin(heading)[..., None]
        x = c * local[:, 0] - s * local[:, 1]
        y = s * local[:, 0] + c * local[:, 1]
        return np.stack([x, y], axis=-1) + np.asarray(xy)[..., None, :]


# ------------------------------------------------------------------------------- builders
def make_footprint(spec: str = "circle", *, radius: float | None = None,
                   spacing: float = DEFAULT_SPACING, padding: float = 0.0) -> Footprint:
    """Build a footprint from a preset name or a Nav2 footprint string.

    Args:
        spec: "circle", "quadruped", "humanoid", or "[[x, y], [x, y], ...]" (Nav2 format).
        radius: overrides the circle radius [m] (only with spec "circle").
        spacing: distance between sample points [m]; smaller gives more points R.
        padding: grows the shape by this much [m] (Nav2 ``footprint_padding``).
    """
    if not (math.isfinite(spacing) and spacing > 0):
        raise FootprintError(f"footprint sample spacing must be > 0 m, got {spacing}")
    if not (math.isfinite(padding) and padding >= 0):
        raise FootprintError(f"footprint padding must be >= 0 m, got {padding}")
    spec = spec.strip()
    if spec.startswith("["):
        return polygon_footprint(parse_nav2_footprint(spec), spacing=spacing, padding=padding)
    if spec not in PRESETS:
        raise FootprintError(f"unknown robot footprint {spec!r}; choose one of "
                             f"{sorted(PRESETS)} or give a Nav2 polygon '[[x, y], ...]'")
    if radius is not None and spec != "circle":
        raise FootprintError("radius can only be set for the 'circle' footprint")
    preset = PRESETS[spec]
    if spec == "circle":
        r = float(radius if radius is not None else preset)
        return circle_footprint(r + padding, spacing=spacing)
    length, width = preset  # type: ignore[misc]
    half_l, half_w = length / 2, width / 2
    poly = np.array([[half_l, half_w], [-half_l, half_w], [-half_l, -half_w], [half_l, -half_w]])
    fp = polygon_footprint(poly, spacing=spacing, padding=padding)
    return Footprint(name=spec, polygon=fp.polygon, points=fp.points)


def circle_footprint(radius: float, *, spacing: float = DEFAULT_SPACING) -> Footprint:
    """A circular robot: concentric rings of points every ``spacing`` [m] from the rim inwards,
    plus the centre."""
    if not (math.isfinite(radius) and radius > 0):
        raise FootprintError(f"robot radius must be > 0 m, got {radius}")
    pts = [np.zeros((1, 2))]
    r = radius
    while r > 1e-9:
        n = max(3, int(math.ceil(2 * math.pi * r / spacing)))
        a = np.arange(n) * 2 * math.pi / n
        pts.append(np.stack([r * np.cos(a), r * np.sin(a)], axis=1))
        r -= spacing
    a = np.arange(_CIRCLE_OUTLINE_VERTICES) * 2 * math.pi / _CIRCLE_OUTLINE_VERTICES
    outline = np.stack([radius * np.cos(a), radius * np.sin(a)], axis=1)
    return Footprint(name="circle", polygon=outline, points=np.concatenate(pts), radius=float(radius))


def polygon_footprint(polygon, *, spacing: float = DEFAULT_SPACING, padding: float = 0.0,
                      name: str = "polygon") -> Footprint:
    """A polygonal robot: points along every edge every ``spacing`` [m], the interior on a grid of
    the same spacing (centred on the robot), and the centre."""
    poly = np.asarray(polygon, dtype=np.float64)
    if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 3:
        raise FootprintError(f"a footprint polygon needs at least 3 [x, y] vertices, "
                             f"got shape {poly.shape}")
    if not np.all(np.isfinite(poly)):
        raise FootprintError("footprint polygon has non-finite coordinates")
    if padding:
        poly = poly + np.sign(poly) * padding  # Nav2 padFootprint
    area = signed_area(poly)
    if abs(area) < 1e-9:
        raise FootprintError("footprint polygon has zero area")
    if area < 0:
        poly = poly[::-1].copy()
    if not point_in_polygon(np.zeros((1, 2)), poly)[0]:
        raise FootprintError("footprint polygon must contain the robot centre (0, 0)")
    edge_pts = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0)):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / spacing)))
        t = np.arange(n)[:, None] / n
        edge_pts.append(a + t * (b - a))
    lo, hi = poly.min(axis=0), poly.max(axis=0)
    gx = np.arange(math.ceil(lo[0] / spacing), math.floor(hi[0] / spacing) + 1) * spacing
    gy = np.arange(math.ceil(lo[1] / spacing), math.floor(hi[1] / spacing) + 1) * spacing
    grid = np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)
    inner = grid[point_in_polygon(grid, poly)]
    # keep interior points that are not (almost) on top of an outline point
    outline = np.concatenate(edge_pts)
    if len(inner):
        d = np.linalg.norm(inner[:, None, :] - outline[None, :, :], axis=-1).min(axis=1)
        inner = inner[d > 0.5 * spacing]
    pts = np.concatenate([np.zeros((1, 2)), inner, outline])
    pts = np.unique(np.round(pts, 9), axis=0)
    return Footprint(name=name, polygon=poly, points=pts)


def parse_nav2_footprint(text: str) -> np.ndarray:
    """Parse Nav2's footprint string "[[x, y], [x, y], ...]" -> (V, 2) array [m]."""
    import yaml

    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise FootprintError(f"footprint {text!r} is not of the form '[[x, y], [x, y], ...]'") from exc
    if (not isinstance(value, list) or len(value) < 3
            or not all(isinstance(p, list) and len(p) == 2 for p in value)):
        raise FootprintError(f"footprint {text!r} must be a list of at least 3 [x, y] pairs")
    try:
        poly = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise FootprintError(f"footprint {text!r} has non-numeric coordinates") from exc
    if not np.all(np.isfinite(poly)):
        raise FootprintError(f"footprint {text!r} has non-finite coordinates")
    return poly


# ------------------------------------------------------------------------------- geometry
def point_in_polygon(pts: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Even-odd rule. pts: (N, 2), poly: (V, 2) -> (N,) bool (points on an edge may go either way)."""
    x, y = pts[:, 0:1], pts[:, 1:2]
    ax, ay = poly[:, 0], poly[:, 1]
    bx, by = np.roll(ax, -1), np.roll(ay, -1)
    crosses = (ay > y) != (by > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = ax + (y - ay) * (bx - ax) / (by - ay)
    return np.sum(crosses & (x < xint), axis=1) % 2 == 1


def signed_area(poly: np.ndarray) -> float:
    """The signed area of a polygon (N, 2) [m^2]: positive when counter-clockwise."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points p (N, 2) to segments a-b (M, 2) -> (N, M)."""
    ab = b - a
    ap = p[:, None, :] - a[None]
    t = np.clip(np.sum(ap * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1), 1e-18), 0, 1)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=-1)
