"""Expert data for the Sparse (SD), Dense (DD) and Full-sequence (FD) diffusion models
(paper Sec. IV-A: "A* trajectories between random point pairs, sampled into 10 sparse waypoints
for SD and 2 dense local points between each pair for DD").

One expert path = the smoothed A* path (``astar.py``) between a random start S and goal G in the
clearance-free space, kept if its length is >= ``min_distance``. Each path is resampled by arc
length into

- ``sparse``      (N, P^g, 2): P^g = 10 waypoints, S first and G last (SD training);
- ``sparse_h{h}`` (N, h, 2) for h = 2..P^g: what Algorithm 1 asks SD for after the robot has
  advanced P^g - h waypoints, i.e. the rest of the path from sparse waypoint P^g - h to G in
  h points;
- ``dense``       (N * (P^g - 1), P^l, 2): the path between sparse waypoints k and k + 1 in
  P^l = 4 points (2 interior points), row i * (P^g - 1) + k for pair i (DD training);
- ``full``        (N, 100, 2): the whole path in 100 points (the FD / Diffuser baseline).

Because the sparse waypoints are evenly spaced by arc length, ``sparse_h{h}`` equals
``sparse[:, P^g - h:]``; it is stored so that training code reads each horizon by name. On
building maps the sparse views may follow the "corners" rule instead (``waypoints`` in
:func:`generate_dataset`, :func:`corner_waypoints`: the path's corners kept among the P^g
waypoints, so no straight leg between two of them cuts a corner); ``sparse_h{h}`` is then the
same suffix of ``sparse``, and the dense view stays the arc-length one.

Two experts (``expert``): "exact" plans every pair with :class:`~ecahd_core.astar.AStarPlanner`
on the fine grid, drawing the pairs one after the other from one random generator (the shipped
maze2d-large data); "coarse" plans with :class:`~ecahd_core.astar.CoarseAStarPlanner` (same
guarantees; paths 0.0-0.4 % longer on average, at worst 6 %, measured in its docstring) and draws attempt i from its own generator
seeded (seed, i), both points in the largest region of the clearance-free space, so that the
attempts can run in worker processes and the data do not depend on how many. "auto" (the
default) is exact for maps of at most ``EXACT_MAX_CELLS`` cells and coarse above.

Files are versioned ``.npz`` archives (``DATASET_VERSION``) that also hold the map and every
generation parameter; they are written byte-for-byte reproducibly, so the same map, seed and
parameters give the same :func:`file_sha256` (recorded in checkpoints).

Units: metres in the map frame; trajectories are float32.
"""
from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import pickle
import time
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ecahd_core.astar import (COARSE_ABOVE_CELLS, COARSE_BLOCK_SIZE, SDF_TOLERANCE, AStarPlanner,
                              CoarseAStarPlanner, clearance_for_footprint, path_length,
                              sample_free_point)
from ecahd_core.errors import DatasetError, PlanningError, TrajectoryError
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap

log = logging.getLogger(__name__)

DATASET_VERSION = 1
DATASET_KIND = "ecahd-expert-dataset"
DTYPE = np.float32  # trajectories, starts, goals, lengths
_ENDPOINT_TRIES = 100  # jittered draws per start / goal before falling back to a cell centre
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)  # fixed member timestamps: reproducible files
EXPERTS = ("auto", "exact", "coarse")
EXACT_MAX_CELLS = COARSE_ABOVE_CELLS  # expert "auto": exact A* up to this many cells, coarse above
_CHUNKSIZE = 8  # attempts per task sent to a worker process


# ------------------------------------------------------------------------------ resampling
def cumulative_arclength(path) -> np.ndarray:
    """(N, 2) path [m] -> (N,) arc length [m] at each vertex, starting at 0."""
    pts = _as_path(path)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(seg)])


def points_at_arclength(path, s) -> np.ndarray:
    """Points of a polyline at arc lengths ``s`` [m] from its start (clamped to [0, length]).

    path: (N, 2) [m], s: (M,) [m] -> (M, 2) float64 [m]. A zero-length path gives copies of its
    first point.
    """
    pts = _as_path(path)
    cum = cumulative_arclength(pts)
    s = np.asarray(s, dtype=np.float64)
    if cum[-1] <= 0.0:
        return np.repeat(pts[:1], len(s), axis=0)
    step = np.concatenate([[True], np.diff(cum) > 0])  # drop repeated vertices: interp needs increasing x
    cum, pts = cum[step], pts[step]
    return np.stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])], axis=1)


def resample_by_arclength(path, n: int) -> np.ndarray:
    """``n`` points evenly spaced by arc length along a polyline.

    path: (N, 2) [m] -> (n, 2) float64 [m], n >= 2; the first and last points are exactly the
    path's end points. A zero-length path gives n copies of its point.
    """
    if int(n) != n or n < 2:
        raise TrajectoryError(f"resampling needs n >= 2 points, got {n!r}")
    pts = _as_path(path)
    total = cumulative_arclength(pts)[-1]
    out = points_at_arclength(pts, np.linspace(0.0, total, int(n)))
    out[0], out[-1] = pts[0], pts[-1]
    return out


def split_by_arclength(path, k: int) -> list[np.ndarray]:
    """Cut a polyline into ``k`` pieces of equal arc length.

    path: (N, 2) [m] -> k arrays (n_i, 2) float64 [m]; each piece holds the path's vertices
    strictly inside it, piece i ends exactly where piece i + 1 starts, the first starts at the
    path's first point and the last ends at its last point.
    """
    if int(k) != k or k < 1:
        raise TrajectoryError(f"splitting needs k >= 1 pieces, got {k!r}")
    pts = _as_path(path)
    cum = cumulative_arclength(pts)
    cuts = points_at_arclength(pts, np.linspace(0.0, cum[-1], int(k) + 1))  # (k + 1, 2)
    cuts[0], cuts[-1] = pts[0], pts[-1]
    s_cut = np.linspace(0.0, cum[-1], int(k) + 1)
    pieces = []
    for i in range(int(k)):
        inner = pts[(cum > s_cut[i]) & (cum < s_cut[i + 1])]
        pieces.append(np.concatenate([cuts[i:i + 1], inner, cuts[i + 1:i + 2]]))
    return pieces


def corner_waypoints(path, n: int, *, tolerance: float = 1e-3) -> np.ndarray:
    """``n`` waypoints of a polyline that keep its corners (the "corners" waypoint rule, ours).

    The polyline's vertices where it turns (an interior vertex farther than ``tolerance`` [m]
    from the chord of its two neighbours) are kept; the remaining n - (corners + 2) points
    split the legs, each extra point going to the leg whose pieces are longest, evenly along
    it. So consecutive waypoints are joined by the path's own straight legs: where the path is
    collision-free, so is every straight leg between two waypoints (with evenly spaced
    waypoints a leg cuts each corner of the path it spans). A path with more corners than
    n - 2 loses those that deviate least from their neighbours' chord first.

    path: (N, 2) [m] -> (n, 2) float64 [m], n >= 2; first and last points are the path's.
    """
    if int(n) != n or n < 2:
        raise TrajectoryError(f"corner waypoints need n >= 2 points, got {n!r}")
    pts = _as_path(path)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9])
    v = pts[keep]
    if len(v) == 1:
        return np.repeat(v, int(n), axis=0)
    v = v[np.concatenate([[True], _chord_deviation(v) > tolerance, [True]])]
    while len(v) > n:  # more corners than waypoints: drop the flattest
        v = np.delete(v, 1 + int(np.argmin(_chord_deviation(v))), axis=0)
    legs = np.linalg.norm(np.diff(v, axis=0), axis=1)  # (L,)
    pieces = np.ones(len(legs), dtype=np.int64)
    for _ in range(int(n) - len(v)):
        pieces[np.argmax(legs / pieces)] += 1
    out = [v[:1]]
    for j, m in enumerate(pieces):
        f = np.arange(1, m + 1, dtype=np.float64)[:, None] / m
        out.append(v[j] + f * (v[j + 1] - v[j]))
    out = np.concatenate(out)
    out[0], out[-1] = pts[0], pts[-1]
    return out


def _chord_deviation(v: np.ndarray) -> np.ndarray:
    """(N, 2) vertices -> (N - 2,) distance [m] of each interior vertex from the segment joining
    its two neighbours."""
    a, b, c = v[:-2], v[1:-1], v[2:]
    ac = c - a
    t = np.clip(np.einsum("ij,ij->i", b - a, ac) / np.maximum(np.einsum("ij,ij->i", ac, ac),
                                                               1e-18), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * ac - b, axis=1)


WAYPOINT_RULES = ("arclength", "corners")
# [m] the "auto" rule's threshold on the expert's median waypoint spacing: maze2d-large's p95
# spacing (median 0.84 m), the range the paper's rule is shown to work in. Measured
# (docs/RESULTS.md): on a 30 x 15 m depot (median 1.19 m) the two rules tie, 99.5% vs 97.9% of
# 192 plans collision-free alone; on a 30 x 50 m warehouse (2.61 m) corners take ECAHD alone
# from 75.0% to 84.9%.
CORNERS_ABOVE_SPACING = 1.5


def chunk_count(length: float, sparse_horizon: int, max_spacing: float | None) -> int:
    """How many equal pieces a path of ``length`` [m] is cut into so that its P^g sparse
    waypoints lie at most ``max_spacing`` [m] apart along it (1 if ``max_spacing`` is None)."""
    if max_spacing is None:
        return 1
    return max(1, math.ceil(length / ((sparse_horizon - 1) * max_spacing) - 1e-9))


def _as_path(path) -> np.ndarray:
    pts = np.asarray(path, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 1:
        raise TrajectoryError(f"a path must have shape (N, 2) with N >= 1, got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise TrajectoryError("path has NaN or inf coordinates")
    return pts


# -------------------------------------------------------------------------- one expert path
@dataclass(frozen=True)
class ExpertSample:
    """The training views of one expert path (float64, metres).

    Attributes:
        sparse: (P^g, 2) waypoints (evenly spaced by arc length, or by the corners rule), start
            first, goal last.
        sparse_h: {h: (h, 2)} for h = 2..P^g, the path from sparse waypoint P^g - h to the goal.
        dense: (P^g - 1, P^l, 2), segment k runs between arc-length waypoints k and k + 1
            (``sparse``'s under the paper's rule).
        full: (F, 2) the whole path.
        length: path length [m].
        path: (N, 2) the expert polyline itself (kept in memory, not written to files).
    """

    sparse: np.ndarray
    sparse_h: dict[int, np.ndarray]
    dense: np.ndarray
    full: np.ndarray
    length: float
    path: np.ndarray | None = None


def expert_sample(path, *, sparse_horizon: int = 10, dense_points: int = 4,
                  full_points: int = 100, waypoints: str = "arclength") -> ExpertSample:
    """Resample one (N, 2) expert path [m] into its sparse, shorter-horizon, dense and full views.

    ``waypoints`` is the rule of the sparse views: "arclength" (the paper's: evenly spaced by
    arc length) or "corners" (:func:`corner_waypoints`, ours; ``sparse_h[h]`` is then
    ``sparse[P^g - h:]``). The dense view is the arc-length one under both rules: DD learns the
    paper's local segments."""
    if waypoints not in WAYPOINT_RULES:
        raise DatasetError(f"waypoints must be one of {list(WAYPOINT_RULES)}, got {waypoints!r}")
    pts = _as_path(path)
    Pg, Pl = sparse_horizon, dense_points
    total = float(cumulative_arclength(pts)[-1])
    s = np.linspace(0.0, total, Pg)  # arc length of the sparse waypoints [m]
    sparse = resample_by_arclength(pts, Pg)  # (Pg, 2)

    sparse_h = {}
    for h in range(2, Pg + 1):
        k = Pg - h  # waypoints already reached
        rest = points_at_arclength(pts, np.linspace(s[k], total, h))  # (h, 2)
        rest[0], rest[-1] = sparse[k], sparse[-1]
        sparse_h[h] = rest

    dense = np.stack([points_at_arclength(pts, np.linspace(s[k], s[k + 1], Pl))
                      for k in range(Pg - 1)])  # (Pg - 1, Pl, 2)
    dense[:, 0], dense[:, -1] = sparse[:-1], sparse[1:]

    full = resample_by_arclength(pts, full_points)  # (F, 2)
    sample = ExpertSample(sparse=sparse, sparse_h=sparse_h, dense=dense, full=full, length=total,
                          path=pts)
    return with_corner_waypoints(sample) if waypoints == "corners" else sample


def with_corner_waypoints(sample: ExpertSample) -> ExpertSample:
    """The same expert sample with its sparse views by the corners rule (from ``sample.path``)."""
    if sample.path is None:
        raise DatasetError("this expert sample does not hold its path")
    Pg = len(sample.sparse)
    sparse = corner_waypoints(sample.path, Pg)
    return replace(sample, sparse=sparse,
                   sparse_h={h: sparse[Pg - h:].copy() for h in range(2, Pg + 1)})


# --------------------------------------------------------------------------------- dataset
@dataclass(eq=False)
class ExpertDataset:
    """A set of N expert paths in all training views, with the map and parameters that made it.

    Attributes:
        sparse: (N, P^g, 2) float32 [m].
        sparse_h: {h: (N, h, 2)} float32 [m] for h = 2..P^g.
        dense: (N * (P^g - 1), P^l, 2) float32 [m]; row i * (P^g - 1) + k is pair i, segment k.
        full: (N, F, 2) float32 [m].
        starts, goals: (N, 2) float32 [m].
        lengths: (N,) float32 path lengths [m].
        map_data: (H, W) int8 occupancy (OccupancyGrid values, row 0 at the lowest y).
        map_resolution: [m/cell].
        map_origin: (x, y) [m] of the map's lower-left corner.
        map_name, map_fingerprint: the map's identity (``GridMap.fingerprint``).
        params: generation parameters (seed, footprint_spec, padding, clearance, min_distance,
            horizons, attempts and rejections, map flags); JSON-serialisable.
        sha256: the file's SHA-256 once saved or loaded, else None.
    """

    sparse: np.ndarray
    sparse_h: dict[int, np.ndarray]
    dense: np.ndarray
    full: np.ndarray
    starts: np.ndarray
    goals: np.ndarray
    lengths: np.ndarray
    map_data: np.ndarray
    map_resolution: float
    map_origin: tuple[float, float]
    map_name: str
    map_fingerprint: str
    params: dict = field(default_factory=dict)
    sha256: str | None = None

    @property
    def num_pairs(self) -> int:
        return int(self.sparse.shape[0])

    @property
    def sparse_horizon(self) -> int:
        """P^g."""
        return int(self.sparse.shape[1])

    @property
    def dense_points(self) -> int:
        """P^l."""
        return int(self.dense.shape[1])

    def grid(self) -> GridMap:
        """The map the paths were planned on."""
        flags = self.params.get("map", {})
        return GridMap(data=self.map_data, resolution=self.map_resolution,
                       origin=tuple(self.map_origin), name=self.map_name,
                       frame_id=flags.get("frame_id", "map"),
                       unknown_is_occupied=flags.get("unknown_is_occupied", True),
                       occupied_threshold=flags.get("occupied_threshold", 65))

    # ----------------------------------------------------------------------------- files
    def _arrays(self) -> dict[str, np.ndarray]:
        params = dict(self.params, kind=DATASET_KIND, version=DATASET_VERSION)
        arrays = {
            "version": np.asarray(DATASET_VERSION, dtype=np.int64),
            "params_json": np.asarray(json.dumps(params, sort_keys=True)),
            "sparse": self.sparse,
            **{f"sparse_h{h}": self.sparse_h[h] for h in sorted(self.sparse_h)},
            "dense": self.dense,
            "full": self.full,
            "starts": self.starts,
            "goals": self.goals,
            "lengths": self.lengths,
            "map_data": self.map_data,
            "map_resolution": np.asarray(self.map_resolution, dtype=np.float64),
            "map_origin": np.asarray(self.map_origin, dtype=np.float64),
            "map_name": np.asarray(self.map_name),
            "map_fingerprint": np.asarray(self.map_fingerprint),
        }
        return {k: np.asarray(v) for k, v in arrays.items()}

    def save(self, path: str | os.PathLike) -> Path:
        """Write a compressed, versioned ``.npz`` at exactly ``path`` (atomically, by rename)
        and set :attr:`sha256`. Returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            for key, arr in self._arrays().items():
                info = zipfile.ZipInfo(key + ".npy", date_time=_ZIP_DATE)
                info.compress_type = zipfile.ZIP_DEFLATED
                with zf.open(info, "w") as member:
                    np.lib.format.write_array(member, arr, allow_pickle=False)
        os.replace(tmp, path)
        self.sha256 = file_sha256(path)
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> "ExpertDataset":
        """Read a file written by :meth:`save`; raises DatasetError naming the problem (missing
        file, not an .npz, not an expert dataset, another format version, inconsistent arrays)."""
        path = Path(path)
        if not path.is_file():
            raise DatasetError(f"dataset file {str(path)!r} does not exist")
        try:
            npz = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, pickle.UnpicklingError) as exc:
            raise DatasetError(f"dataset file {str(path)!r} is not an .npz archive: {exc}") from exc
        if not isinstance(npz, np.lib.npyio.NpzFile):
            raise DatasetError(f"dataset file {str(path)!r} is a single .npy array, "
                               "not an .npz expert dataset")
        try:
            with npz:
                arrays = _read_dataset_arrays(npz, path)
        except DatasetError:
            raise
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise DatasetError(f"dataset file {str(path)!r} is corrupt: {exc}") from exc
        dataset = cls(**arrays)
        _check_consistent(dataset, path)
        dataset.sha256 = file_sha256(path)
        return dataset


def mix_datasets(demos: ExpertDataset, expert: ExpertDataset, share: float, *,
                 seed: int = 0) -> ExpertDataset:
    """Demonstrations (``ecahd dataset --from-bags``) and A* expert data of the same map mixed
    so that ``share`` (0 < share < 1) of the pairs are demonstrations: as many pairs as the two
    allow at that share (the larger side subsampled without replacement, seeded), demonstrations
    first. Demonstrations rarely cover every start/goal pair; the expert fills the gaps.
    Raises DatasetError when the maps, P^g, P^l or the full points differ."""
    if not 0.0 < share < 1.0:
        raise DatasetError(f"the demonstrations' share must be in (0, 1), got {share}")
    if demos.map_fingerprint != expert.map_fingerprint:
        raise DatasetError(f"the demonstrations are on map {demos.map_name!r} "
                           f"({demos.map_fingerprint}), the expert data on {expert.map_name!r} "
                           f"({expert.map_fingerprint}): mix data of one map")
    shapes = [(d.sparse_horizon, d.dense_points, d.full.shape[1]) for d in (demos, expert)]
    if shapes[0] != shapes[1]:
        raise DatasetError(f"(P^g, P^l, full points) differ: demonstrations {shapes[0]}, "
                           f"expert {shapes[1]}")
    total = min(demos.num_pairs / share, expert.num_pairs / (1.0 - share))
    n_demo = max(1, min(demos.num_pairs, int(round(share * total))))
    n_expert = max(1, min(expert.num_pairs, int(round(total)) - n_demo))
    rng = np.random.default_rng(seed)
    picks = [np.sort(rng.choice(d.num_pairs, size=n, replace=False))
             for d, n in ((demos, n_demo), (expert, n_expert))]
    Pg = demos.sparse_horizon

    def cat(get):
        return np.concatenate([get(d, i) for d, i in zip((demos, expert), picks)])

    def dense_rows(d, i):  # pair i's P^g - 1 segments
        return d.dense.reshape(d.num_pairs, Pg - 1, *d.dense.shape[1:])[i] \
            .reshape(-1, *d.dense.shape[1:])

    params = dict(expert.params, mixed={
        "share": float(share), "seed": int(seed), "demonstrations": n_demo,
        "expert": n_expert, "demonstrations_sha256": demos.sha256,
        "expert_sha256": expert.sha256, "demonstrations_params": demos.params})
    return ExpertDataset(
        sparse=cat(lambda d, i: d.sparse[i]),
        sparse_h={h: cat(lambda d, i, h=h: d.sparse_h[h][i]) for h in expert.sparse_h},
        dense=cat(dense_rows), full=cat(lambda d, i: d.full[i]),
        starts=cat(lambda d, i: d.starts[i]), goals=cat(lambda d, i: d.goals[i]),
        lengths=cat(lambda d, i: d.lengths[i]), map_data=expert.map_data,
        map_resolution=expert.map_resolution, map_origin=expert.map_origin,
        map_name=expert.map_name, map_fingerprint=expert.map_fingerprint, params=params)


def _read_dataset_arrays(npz, path: Path) -> dict:
    """The constructor arguments of ExpertDataset from an open NpzFile, checking kind/version."""
    where = repr(str(path))
    names = set(npz.files)
    if "version" not in names or "params_json" not in names:
        raise DatasetError(f"{where} is an .npz file but not an ECAHD expert dataset "
                           "(it has no 'version' and 'params_json' entries)")
    stored = npz["version"]
    if stored.shape != () or not np.issubdtype(stored.dtype, np.integer):
        raise DatasetError(f"{where}: its 'version' entry must be one integer, got "
                           f"{stored.dtype} of shape {stored.shape}")
    version = int(stored)
    if version != DATASET_VERSION:
        raise DatasetError(f"{where} is expert dataset format version {version}, but this "
                           f"ecahd_core reads version {DATASET_VERSION}; regenerate it with "
                           "`ecahd dataset`")
    try:
        params = json.loads(str(npz["params_json"]))
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{where}: its 'params_json' entry is not valid JSON: {exc}") from exc
    if not isinstance(params, dict) or params.get("kind") != DATASET_KIND:
        raise DatasetError(f"{where} is not an ECAHD expert dataset (kind "
                           f"{params.get('kind') if isinstance(params, dict) else None!r})")
    horizon = int(params.get("sparse_horizon", 0))
    required = ["sparse", "dense", "full", "starts", "goals", "lengths", "map_data",
                "map_resolution", "map_origin", "map_name", "map_fingerprint"]
    required += [f"sparse_h{h}" for h in range(2, horizon + 1)]
    missing = [name for name in required if name not in names]
    if missing:
        raise DatasetError(f"{where} lacks the entries {missing}")
    return dict(
        sparse=npz["sparse"], dense=npz["dense"], full=npz["full"],
        sparse_h={h: npz[f"sparse_h{h}"] for h in range(2, horizon + 1)},
        starts=npz["starts"], goals=npz["goals"], lengths=npz["lengths"],
        map_data=npz["map_data"], map_resolution=float(npz["map_resolution"]),
        map_origin=tuple(float(v) for v in npz["map_origin"]),
        map_name=str(npz["map_name"]), map_fingerprint=str(npz["map_fingerprint"]),
        params=params,
    )


def _check_consistent(ds: ExpertDataset, path: Path) -> None:
    """Raise DatasetError if the arrays disagree with each other or with the parameters."""
    where = repr(str(path))
    N, Pg = ds.num_pairs, int(ds.params["sparse_horizon"])
    expected = {
        "sparse": (N, Pg, 2),
        "dense": (N * (Pg - 1), int(ds.params["dense_points"]), 2),
        "full": (N, int(ds.params["full_points"]), 2),
        "starts": (N, 2),
        "goals": (N, 2),
        "lengths": (N,),
        **{f"sparse_h{h}": (N, h, 2) for h in range(2, Pg + 1)},
    }
    actual = {"sparse": ds.sparse, "dense": ds.dense, "full": ds.full, "starts": ds.starts,
              "goals": ds.goals, "lengths": ds.lengths,
              **{f"sparse_h{h}": a for h, a in ds.sparse_h.items()}}
    for name, shape in expected.items():
        if actual[name].shape != shape:
            raise DatasetError(f"{where}: {name} has shape {actual[name].shape}, expected {shape}")
    try:
        grid = ds.grid()
    except ValueError as exc:
        raise DatasetError(f"{where}: the stored map is invalid: {exc}") from exc
    if grid.fingerprint() != ds.map_fingerprint:
        raise DatasetError(f"{where}: the stored map's fingerprint {grid.fingerprint()} does not "
                           f"match the recorded {ds.map_fingerprint} (file edited or corrupt)")


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's content (the dataset identity recorded in checkpoints)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except FileNotFoundError as exc:
        raise DatasetError(f"file {str(path)!r} does not exist") from exc
    return h.hexdigest()


# ------------------------------------------------------------------------------ generation
def generate_dataset(grid: GridMap, *, pairs: int, seed: int, footprint_spec: str = "circle",
                     padding: float = 0.0, min_distance: float = 3.0, sparse_horizon: int = 10,
                     dense_points: int = 4, full_points: int = 100, progress: bool = True,
                     max_attempts: int | None = None, expert: str = "auto",
                     workers: int | None = None,
                     coarse_block_size: float = COARSE_BLOCK_SIZE,
                     max_spacing: float | None = None,
                     waypoints: str = "auto") -> ExpertDataset:
    """Plan ``pairs`` expert paths between seeded random start/goal pairs (paper Sec. IV-A).

    Starts and goals are drawn uniformly from the clearance-free space (clearance = the
    footprint's circumscribed radius + ``padding`` [m]) and must themselves be at least the
    clearance away from every obstacle. A pair is rejected, and another drawn, if A* finds no
    path or the smoothed path is shorter than ``min_distance`` [m]. The result always holds
    exactly ``pairs`` paths; ``params`` records the attempts and the rejections.

    ``expert`` chooses the planner and the draws (module docstring): "exact", "coarse" (blocks of
    about ``coarse_block_size`` [m]; ``workers`` processes, default one per CPU, results
    independent of their number) or "auto" (exact for at most ``EXACT_MAX_CELLS`` map cells).
    The exact expert always runs in this process.

    ``max_spacing`` [m] (default None: off) bounds the arc length between consecutive sparse
    waypoints: a path longer than (P^g - 1) * max_spacing is cut into the fewest equal pieces
    (:func:`chunk_count`, :func:`split_by_arclength`) that meet it, and every piece is one
    sample, its ends the sample's start and goal (so one attempt may give several samples; the
    last attempt's extra pieces are dropped). It keeps the waypoint spacing of a large map's
    data within what SD learnt on maze2d-large (0.4-1.9 m) at the price of shorter plans.

    ``waypoints`` is the sparse views' rule (:func:`expert_sample`): "arclength" (the paper's),
    "corners" (:func:`corner_waypoints`) or "auto": decided once all paths are planned, by
    :func:`waypoint_rule_for` on their median waypoint spacing (corners where the paper's legs
    would be longer than ``CORNERS_ABOVE_SPACING``).

    Raises:
        DatasetError: bad parameters, no clearance-free space, or fewer than ``pairs`` kept
            paths after ``max_attempts`` (default 20 * pairs + 100) draws.
    """
    _check_positive_int("pairs", pairs, 1)
    _check_positive_int("sparse_horizon", sparse_horizon, 2)
    _check_positive_int("dense_points", dense_points, 2)
    _check_positive_int("full_points", full_points, 2)
    if not (math.isfinite(min_distance) and min_distance >= 0):
        raise DatasetError(f"min_distance must be a finite number >= 0 m, got {min_distance!r}")
    if expert not in EXPERTS:
        raise DatasetError(f"expert must be one of {list(EXPERTS)}, got {expert!r}")
    if workers is not None:
        _check_positive_int("workers", workers, 1)
    if not (isinstance(coarse_block_size, (int, float)) and math.isfinite(coarse_block_size)
            and coarse_block_size > 0):
        raise DatasetError(f"coarse_block_size must be a finite number > 0 m, "
                           f"got {coarse_block_size!r}")
    if max_spacing is not None and not (isinstance(max_spacing, (int, float))
                                        and math.isfinite(max_spacing) and max_spacing > 0):
        raise DatasetError(f"max_spacing must be None or a finite number > 0 m, "
                           f"got {max_spacing!r}")
    if waypoints != "auto" and waypoints not in WAYPOINT_RULES:
        raise DatasetError(f"waypoints must be 'auto' or one of {list(WAYPOINT_RULES)}, "
                           f"got {waypoints!r}")
    if max_attempts is None:
        max_attempts = 20 * pairs + 100
    if expert == "auto":
        expert = "exact" if grid.height * grid.width <= EXACT_MAX_CELLS else "coarse"

    footprint = make_footprint(footprint_spec)
    clearance = clearance_for_footprint(footprint, padding=padding)
    t0 = time.perf_counter()
    planner = AStarPlanner(grid, clearance, smooth=True)
    if not planner.mask.any():
        raise DatasetError(f"no cell of map {grid.name!r} is {clearance:.3f} m away from the "
                           f"obstacles, the clearance robot {footprint.name!r} needs")
    views = dict(sparse_horizon=sparse_horizon, dense_points=dense_points, full_points=full_points,
                 max_spacing=max_spacing,
                 waypoints="arclength" if waypoints == "auto" else waypoints)
    run = _ExpertRun(pairs=pairs, max_attempts=max_attempts, min_distance=min_distance,
                     grid=grid, progress=progress)
    extra = {}
    if expert == "exact":
        run.exact(planner, np.random.default_rng(seed), views)
    else:
        coarse = CoarseAStarPlanner.for_resolution(planner, coarse_block_size)
        workers = workers or os.cpu_count() or 1
        log.info("coarse expert on %s: %d x %d cells, blocks of %d cells, %d graph nodes, "
                 "built in %.1f s; %d worker(s)", grid.name, grid.height, grid.width,
                 coarse.block, coarse.num_nodes, time.perf_counter() - t0, workers)
        run.coarse(coarse, seed, views, workers)
        extra = {"expert_block": coarse.block,
                 "sampling": "attempt i seeded (seed, i), largest clearance-free region"}
    if max_spacing is not None:
        extra.update(max_spacing=float(max_spacing), split_paths=run.split_paths)
    samples = run.samples
    if waypoints == "auto":
        lengths = [x.length for x in samples]
        waypoints = waypoint_rule_for(lengths, sparse_horizon)
        if waypoints == "corners":
            samples = [with_corner_waypoints(x) for x in samples]
        log.info("waypoint rule %s: the expert's median waypoint spacing is %.2f m (corners "
                 "above %.1f m)", waypoints, median_spacing(lengths, sparse_horizon),
                 CORNERS_ABOVE_SPACING)
    elapsed = time.perf_counter() - t0
    log.info("kept %d expert paths in %d attempts (%d too short, %d unreachable) in %.1f s",
             pairs, run.attempts, run.rejected_short, run.rejected_unreachable, elapsed)

    from ecahd_core import __version__

    params = {
        "kind": DATASET_KIND,
        "version": DATASET_VERSION,
        "seed": int(seed),
        "footprint_spec": footprint_spec,
        "footprint": footprint.name,
        "padding": float(padding),
        "clearance": clearance,
        "min_distance": float(min_distance),
        "pairs": int(pairs),
        "sparse_horizon": int(sparse_horizon),
        "dense_points": int(dense_points),
        "full_points": int(full_points),
        **({"waypoints": waypoints} if waypoints != "arclength" else {}),
        "attempts": run.attempts,
        "rejected_short": run.rejected_short,
        "rejected_unreachable": run.rejected_unreachable,
        "expert": "astar+shortcut" if expert == "exact" else "coarse-astar+shortcut",
        **extra,
        "ecahd_version": __version__,
        "map": {"frame_id": grid.frame_id, "unknown_is_occupied": grid.unknown_is_occupied,
                "occupied_threshold": grid.occupied_threshold},
    }
    starts, goals = run.starts, run.goals
    return ExpertDataset(
        sparse=np.stack([s.sparse for s in samples]).astype(DTYPE),
        sparse_h={h: np.stack([s.sparse_h[h] for s in samples]).astype(DTYPE)
                  for h in range(2, sparse_horizon + 1)},
        dense=np.concatenate([s.dense for s in samples]).astype(DTYPE),
        full=np.stack([s.full for s in samples]).astype(DTYPE),
        starts=np.stack(starts).astype(DTYPE),
        goals=np.stack(goals).astype(DTYPE),
        lengths=np.array([s.length for s in samples], dtype=DTYPE),
        map_data=np.array(grid.data, dtype=np.int8),
        map_resolution=grid.resolution,
        map_origin=grid.origin,
        map_name=grid.name,
        map_fingerprint=grid.fingerprint(),
        params=params,
    )


class _ExpertRun:
    """The attempts of one :func:`generate_dataset` call: kept samples in attempt order, counts
    of the rejections, the progress bar."""

    def __init__(self, *, pairs: int, max_attempts: int, min_distance: float, grid: GridMap,
                 progress: bool) -> None:
        self.pairs, self.max_attempts, self.min_distance = pairs, max_attempts, min_distance
        self.grid, self.progress = grid, progress
        self.samples: list[ExpertSample] = []
        self.starts: list[np.ndarray] = []
        self.goals: list[np.ndarray] = []
        self.attempts = self.rejected_short = self.rejected_unreachable = 0
        self.split_paths = 0  # paths cut into pieces (max_spacing)

    def _bar(self, what: str):
        from tqdm import tqdm

        return tqdm(total=self.pairs, disable=not self.progress, unit="pair",
                    desc=f"{what} expert paths on {self.grid.name}")

    def _check_attempts(self) -> None:
        if self.attempts >= self.max_attempts:
            raise DatasetError(
                f"kept only {len(self.samples)} of {self.pairs} pairs after {self.attempts} "
                f"attempts on map {self.grid.name!r} ({self.rejected_short} paths shorter than "
                f"{self.min_distance} m, {self.rejected_unreachable} unreachable goals); "
                "lower min_distance")

    def _record(self, outcome, bar) -> None:
        """Count one attempt's outcome: ("ok", [(start, goal, sample), ...]) (one per piece of
        the path), ("short",) or ("unreachable",)."""
        self.attempts += 1
        if outcome[0] == "unreachable":
            self.rejected_unreachable += 1
        elif outcome[0] == "short":
            self.rejected_short += 1
        else:
            pieces = outcome[1]
            self.split_paths += len(pieces) > 1
            for start, goal, sample in pieces[:self.pairs - len(self.samples)]:
                self.samples.append(sample)
                self.starts.append(start)
                self.goals.append(goal)
                bar.update(1)

    def exact(self, planner: AStarPlanner, rng: np.random.Generator, views: dict) -> None:
        """Fine-grid A*, pairs drawn one after the other from ``rng`` (the shipped data)."""
        with self._bar("A*") as bar:
            while len(self.samples) < self.pairs:
                self._check_attempts()
                start = sample_endpoint(rng, planner)
                goal = sample_endpoint(rng, planner)
                self._record(_plan_attempt(planner, start, goal, self.min_distance, views), bar)

    def coarse(self, coarse: CoarseAStarPlanner, seed: int, views: dict, workers: int) -> None:
        """Coarse A*, attempt i drawn from its own seed, in ``workers`` processes (results taken
        in attempt order)."""
        fine = coarse.fine
        comp = fine.components
        region = comp == np.bincount(comp[comp > 0]).argmax()  # largest clearance-free region
        rows, cols = np.nonzero(region)
        task = (coarse, (rows, cols), int(seed), self.min_distance, views)
        with self._bar(f"coarse A* ({workers} worker{'s' if workers > 1 else ''})") as bar:
            if workers == 1:
                outcomes = (_coarse_attempt(task, i) for i in range(self.max_attempts))
                self._consume(outcomes, bar)
                return
            import multiprocessing

            global _TASK
            _TASK = task  # inherited by the forked workers, not pickled
            ctx = multiprocessing.get_context("fork")
            try:
                with ctx.Pool(workers) as pool:
                    self._consume(pool.imap(_coarse_attempt_forked, range(self.max_attempts),
                                            chunksize=_CHUNKSIZE), bar)
                    pool.terminate()  # attempts computed beyond the last kept pair are dropped
            finally:
                _TASK = None

    def _consume(self, outcomes, bar) -> None:
        for outcome in outcomes:
            self._record(outcome, bar)
            if len(self.samples) >= self.pairs:
                return
        self._check_attempts()  # the attempts ran out


_TASK = None  # the coarse run's (planner, region cells, seed, min_distance, views) for workers


def _coarse_attempt_forked(index: int):
    return _coarse_attempt(_TASK, index)


def _coarse_attempt(task, index: int):
    """Attempt ``index`` of a coarse run: start and goal from the generator seeded (seed, index)."""
    coarse, cells, seed, min_distance, views = task
    rng = np.random.default_rng([seed, index])
    start = _sample_in_cells(rng, coarse.fine, cells)
    goal = _sample_in_cells(rng, coarse.fine, cells)
    return _plan_attempt(coarse, start, goal, min_distance, views)


def _plan_attempt(planner, start: np.ndarray, goal: np.ndarray, min_distance: float,
                  views: dict):
    """Plan one pair: ("ok", [(start, goal, ExpertSample), ...]) (the path's pieces, see
    ``max_spacing`` in :func:`generate_dataset`), ("short",) or ("unreachable",)."""
    try:
        path = planner.plan(start, goal)
    except PlanningError:
        return ("unreachable",)
    length = path_length(path)
    if length < min_distance:
        return ("short",)
    views = dict(views)
    k = chunk_count(length, views["sparse_horizon"], views.pop("max_spacing"))
    if k == 1:
        return ("ok", [(start, goal, expert_sample(path, **views))])
    return ("ok", [(piece[0], piece[-1], expert_sample(piece, **views))
                   for piece in split_by_arclength(path, k)])


def _sample_in_cells(rng: np.random.Generator, planner: AStarPlanner, cells) -> np.ndarray:
    """:func:`sample_endpoint` over the given traversable cells (rows, cols) (K,) only."""
    rows, cols = cells
    res = planner.grid.resolution
    for _ in range(_ENDPOINT_TRIES):
        k = rng.integers(0, len(rows))
        centre = planner.grid.cell_to_world(rows[k], cols[k])
        point = centre + 0.98 * (rng.random(2) - 0.5) * res
        if planner.point_clearance(point) >= planner.clearance - SDF_TOLERANCE:
            return point
    return planner.grid.cell_to_world(rows[k], cols[k])  # centres always have the clearance


def sample_endpoint(rng: np.random.Generator, planner: AStarPlanner) -> np.ndarray:
    """A random point [m] in a traversable cell whose own exact clearance is enough (a point
    jittered inside a cell can be closer to an obstacle corner than the cell's centre)."""
    for _ in range(_ENDPOINT_TRIES):
        point = sample_free_point(rng, planner.mask, planner.grid)
        if planner.point_clearance(point) >= planner.clearance - SDF_TOLERANCE:
            return point
    return sample_free_point(rng, planner.mask, planner.grid, jitter=False)  # centres always are


def waypoint_rule_for(lengths, sparse_horizon: int) -> str:
    """The "auto" waypoint rule for expert paths of these ``lengths`` (N,) [m]: "corners" when
    their median waypoint spacing, median length / (P^g - 1), exceeds ``CORNERS_ABOVE_SPACING``,
    else "arclength" (the paper's)."""
    return "corners" if median_spacing(lengths, sparse_horizon) > CORNERS_ABOVE_SPACING \
        else "arclength"


def median_spacing(lengths, sparse_horizon: int) -> float:
    """[m] median waypoint spacing of P^g waypoints on paths of these ``lengths`` (N,) [m]:
    median length / (P^g - 1)."""
    return float(np.median(np.asarray(lengths, dtype=np.float64))) / (sparse_horizon - 1)


def expert_spacing(dataset: "ExpertDataset") -> float:
    """[m] the median waypoint spacing of a dataset's expert paths with its P^g waypoints
    (:func:`median_spacing` of the lengths of its ``full`` views): how far apart the waypoints
    SD learnt lie."""
    full = np.asarray(dataset.full, dtype=np.float64)
    lengths = np.linalg.norm(np.diff(full, axis=1), axis=-1).sum(axis=1)
    return median_spacing(lengths, int(dataset.params["sparse_horizon"]))


def waypoint_rule(dataset: "ExpertDataset") -> str:
    """The sparse views' rule a dataset was written with ("arclength" when not recorded)."""
    return str(dataset.params.get("waypoints", "arclength"))


def _check_positive_int(name: str, value, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise DatasetError(f"{name} must be an integer >= {minimum}, got {value!r}")
