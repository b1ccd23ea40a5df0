"""Figures (matplotlib, Agg backend): the map, paths, footprint sweeps and collisions.

Colours follow the paper's Fig. 3: sparse waypoints as red dots, dense refined paths in purple,
footprints where it matters as outlines, collisions in red.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ecahd_core.footprint import Footprint
from ecahd_core.maps import GridMap


def pyplot():
    """matplotlib.pyplot on the Agg backend (PNG files, no display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def draw_map(ax, grid: GridMap) -> None:
    """Obstacles dark grey, unknown light grey, free white; axes in metres (map frame)."""
    xmin, ymin, xmax, ymax = grid.bounds
    img = np.ones(grid.data.shape + (3,))
    img[grid.data < 0] = 0.8
    img[grid.occupied & (grid.data >= 0)] = 0.25
    ax.imshow(img, origin="lower", extent=(xmin, xmax, ymin, ymax), interpolation="nearest")
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def draw_footprints(ax, footprint: Footprint, poses: np.ndarray, *, color: str = "tab:blue",
                    alpha: float = 0.25, linewidth: float = 0.8) -> None:
    """Outline the footprint at poses: (N, 3) x, y, heading."""
    from matplotlib.collections import PolyCollection

    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    outlines = footprint.transformed(poses[:, :2], poses[:, 2], which="polygon")  # (N, V, 2)
    ax.add_collection(PolyCollection(list(outlines), facecolors="none", edgecolors=color,
                                     alpha=alpha, linewidths=linewidth))


@dataclass
class PlanFigure:
    """Everything one plan figure shows."""

    grid: GridMap
    footprint: Footprint
    title: str = ""
    start: np.ndarray | None = None
    goal: np.ndarray | None = None
    trajectory: np.ndarray | None = None  # (N, 2) executed / planned path [m]
    waypoints: np.ndarray | None = None  # (K, 2) sparse waypoints [m]
    sweep_poses: np.ndarray | None = None  # (M, 3) poses whose footprint outline is drawn
    colliding_poses: np.ndarray | None = None  # (C, 3) poses in collision (drawn in red)
    extra_paths: list[np.ndarray] = field(default_factory=list)  # e.g. rejected candidates
    legend: bool = True

    def draw(self, ax) -> None:
        draw_map(ax, self.grid)
        for p in self.extra_paths:
            ax.plot(p[:, 0], p[:, 1], color="0.6", lw=0.8, alpha=0.6)
        if self.sweep_poses is not None and len(self.sweep_poses):
            draw_footprints(ax, self.footprint, self.sweep_poses, color="tab:blue", alpha=0.35)
        if self.trajectory is not None:
            ax.plot(self.trajectory[:, 0], self.trajectory[:, 1], color="tab:purple", lw=1.6,
                    label="path")
        if self.waypoints is not None:
            ax.plot(self.waypoints[:, 0], self.waypoints[:, 1], "o", color="tab:red", ms=4,
                    label="waypoints")
        if self.colliding_poses is not None and len(self.colliding_poses):
            draw_footprints(ax, self.footprint, self.colliding_poses, color="red", alpha=0.9,
                            linewidth=1.2)
            ax.plot(self.colliding_poses[:, 0], self.colliding_poses[:, 1], "x", color="red",
                    ms=5, label="collision")
        if self.start is not None:
            ax.plot(*self.start, marker="s", color="tab:green", ms=8, label="start")
        if self.goal is not None:
            ax.plot(*self.goal, marker="*", color="gold", mec="k", ms=14, label="goal")
        if self.title:
            ax.set_title(self.title, fontsize=9)
        if self.legend:
            ax.legend(loc="best", fontsize=7, framealpha=0.8)


def save_figures(figures: list[PlanFigure], path: str | Path, *, cols: int = 1,
                 panel_size: float = 6.0, dpi: int = 110) -> Path:
    """Draw panels in a grid and save a PNG; returns the path."""
    plt = pyplot()
    n = len(figures)
    cols = max(1, min(cols, n))
    rows = (n + cols - 1) // cols
    aspect = 1.0
    if n:
        xmin, ymin, xmax, ymax = figures[0].grid.bounds
        aspect = (ymax - ymin) / max(xmax - xmin, 1e-9)
    fig, axes = plt.subplots(rows, cols, figsize=(panel_size * cols, panel_size * aspect * rows + 0.6),
                             squeeze=False)
    for i, (ax, f) in enumerate(zip(axes.flat, figures)):
        f.legend = f.legend and i == 0  # one legend per figure is enough
        f.draw(ax)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
