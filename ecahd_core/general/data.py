"""The generalist dataset (issue 40): many generated buildings x A* expert problems per building,
stored as what the map-conditioned SD model reads (``views.py``) and learns (waypoints in the
view's coordinates), in shards that are built one after the other and resumed.

Maps: map j (0 <= j < ``maps``) is the ``MapKind`` j mod 3 (warehouse, office, depot in turn),
width and height each drawn from ``sizes`` [m] by the generator seeded (seed, j), at
``resolution``, map seed ``MAP_SEED_STRIDE`` * seed + j (``mapgen.generate_map``). So a dataset of
seed s uses map seeds s * 10^6 .. s * 10^6 + maps - 1: held-out benchmarks take another s.

Problems: ``dataset.generate_dataset`` on each map, as ``ecahd train-all`` makes a per-map
model's data (the robot's clearance, paths >= ``min_distance``, the "auto" waypoint rule: corners
where the expert's median waypoint spacing exceeds 1.5 m; exact A* on small maps, the coarse
expert above; seeded with the map seed; one process). Each expert path gives two samples:

- the whole problem: S, G and its P^g sparse waypoints;
- one shorter horizon h drawn from 3..P^g - 1 (the generator seeded (seed, j, 1)): what
  Algorithm 1 asks SD for after the robot has advanced P^g - h waypoints (``sparse_h[h]``),
  with its own views (its start is waypoint P^g - h).

Each sample's views are made for its own start and goal (``views.make_views``); its waypoints
are stored in that view's coordinates. A sample whose waypoints leave the view (an expert
detour beyond the margin) or whose view would exceed ``max_side`` is dropped and counted
(``maps_json``: ``dropped_outside``, ``dropped_far``).

Shard ``shard-{k:05d}.npz`` holds maps k * maps_per_shard .. (k + 1) * maps_per_shard - 1
(N samples):

    global_view   (N, C, S, S) uint8: channel "any" 0/1, channel "fraction" x 255 (exact,
                  ``views.FRACTION_LEVELS``)
    local_views   (N, 2, C, S_l, S_l) uint8, the same encoding (start, goal)
    waypoints     (N, P^g, 2) float32 view coordinates, rows >= horizon NaN
    horizon       (N,) int16, the sample's P (2..P^g)
    centre        (N, 2) float64 [m], half_side (N,) float64 [m]: the view's frame
    map_index     (N,) int32, j
    maps_json     one record per map (kind, size, seed, fingerprint, expert counts, drops, time)
    config_json   the :class:`GeneralDataConfig`; version

A shard is written to a temporary name and renamed, so a killed run leaves whole shards only;
``build`` skips every shard already there with the same config and refuses a directory built
with another config (``manifest.json``).

Throughput (measured 2026-12-06 on this 2-core machine, 1 process, other work running;
defaults: 200 pairs per map, sides 10-60 m at 0.05 m/cell): 12 maps in 17 s, 1.4 s per map
(0.7-2.8 s: map 0.05 s, expert paths ~ 5-10 ms per pair, views ~ 0.2 ms per sample, compression),
400 samples per map, none dropped with the "map" view extent, 300 bytes per sample compressed.
So 1000 maps (400 000 samples) take about 25 min and 120 MB.
"""
from __future__ import annotations

import json
import logging
import math
import os
import time
import zipfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ecahd_core.dataset import generate_dataset
from ecahd_core.errors import DatasetError
from ecahd_core.general.views import (FRACTION_LEVELS, MapViews, OccupancyIntegral, ViewConfig,
                                      ViewFrame, make_views, view_side)
from ecahd_core.mapgen import MapGenConfig, MapKind, generate_map

log = logging.getLogger(__name__)

GENERAL_DATA_VERSION = 1
GENERAL_DATA_KIND = "ecahd-general-dataset"
MAP_SEED_STRIDE = 1_000_000  # map seed of map j in a dataset of seed s: s * stride + j
MANIFEST = "manifest.json"
SHARD_GLOB = "shard-*.npz"
_OUTSIDE_TOL = 1e-9  # waypoints may touch the view's edge
SHARD_ARRAYS = ("global_view", "local_views", "waypoints", "horizon", "centre", "half_side",
                "map_index")  # the per-sample arrays of a shard


@dataclass(frozen=True, kw_only=True)
class GeneralDataConfig:
    """What :func:`build` makes (module docstring); one place defines each default.

    Attributes:
        maps: number of generated maps.
        maps_per_shard: maps per shard file (the unit of resuming).
        pairs_per_map: expert paths per map (two samples each).
        sizes: [m] the map sides drawn (each of width and height).
        resolution: [m/cell] of the generated maps.
        seed: the dataset's seed (map seeds ``MAP_SEED_STRIDE`` * seed + j).
        robot: footprint spec whose clearance the expert keeps (``footprint.make_footprint``).
        min_distance: [m] shortest expert path kept.
        sparse_horizon: P^g.
        waypoints: the sparse waypoints' rule ("auto", "arclength", "corners").
        view: the views' sizes.
    """

    maps: int = 1000
    maps_per_shard: int = 10
    pairs_per_map: int = 200
    sizes: tuple[float, ...] = (10.0, 16.0, 24.0, 36.0, 48.0, 60.0)
    resolution: float = 0.05
    seed: int = 0
    robot: str = "circle"
    min_distance: float = 3.0
    sparse_horizon: int = 10
    waypoints: str = "auto"
    view: ViewConfig = field(default_factory=ViewConfig)

    def __post_init__(self) -> None:
        for name, least in (("maps", 1), ("maps_per_shard", 1), ("pairs_per_map", 1),
                            ("sparse_horizon", 3), ("seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < least:
                raise DatasetError(f"GeneralDataConfig.{name} must be an integer >= {least}, "
                                   f"got {value!r}")
            object.__setattr__(self, name, int(value))
        if isinstance(self.view, dict):
            object.__setattr__(self, "view", ViewConfig(**self.view))
        sizes = tuple(float(s) for s in self.sizes)
        if not sizes or not all(math.isfinite(s) and s > 0 for s in sizes):
            raise DatasetError(f"GeneralDataConfig.sizes must be positive sides [m], "
                               f"got {self.sizes!r}")
        object.__setattr__(self, "sizes", sizes)
        if not (math.isfinite(self.min_distance) and self.min_distance >= 0):
            raise DatasetError(f"GeneralDataConfig.min_distance must be >= 0 m, "
                               f"got {self.min_distance!r}")

    @property
    def shards(self) -> int:
        return -(-self.maps // self.maps_per_shard)

    def to_json(self) -> str:
        return json.dumps(asdict(self), sort_keys=True)

    def map_config(self, j: int) -> MapGenConfig:
        """Map j's generator config (module docstring)."""
        rng = np.random.default_rng([self.seed, j])
        width, height = (float(v) for v in rng.choice(self.sizes, size=2))
        return MapGenConfig(kind=list(MapKind)[j % len(MapKind)], width=width, height=height,
                            resolution=self.resolution, seed=MAP_SEED_STRIDE * self.seed + j)


@dataclass(frozen=True)
class BuildReport:
    """What :func:`build` did.

    Attributes:
        directory: where the shards are.
        shards_written, shards_skipped: shards made by this call / found finished.
        samples: samples in the shards written by this call.
        seconds: wall time of this call.
    """

    directory: Path
    shards_written: int
    shards_skipped: int
    samples: int
    seconds: float


def shard_path(directory: Path, k: int) -> Path:
    return Path(directory) / f"shard-{k:05d}.npz"


def build(directory: str | os.PathLike, config: GeneralDataConfig | None = None, *,
          progress: bool = True, max_shards: int | None = None) -> BuildReport:
    """Build (or resume) the dataset of ``config`` in ``directory``.

    Shards already there (same config) are skipped; the rest are made in order, each written
    atomically. ``max_shards``: stop after writing this many (build in slices). A tqdm bar over
    the maps shows the rate and the ETA.

    Raises:
        DatasetError: the directory holds a dataset of another config.
    """
    config = config or GeneralDataConfig()
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    manifest = directory / MANIFEST
    if manifest.exists():
        stored = json.loads(manifest.read_text()).get("config")
        if json.dumps(stored, sort_keys=True) != config.to_json():
            raise DatasetError(f"{str(directory)!r} holds a generalist dataset of another "
                               f"config ({manifest}); build in another directory")
    else:
        manifest.write_text(json.dumps({"kind": GENERAL_DATA_KIND,
                                        "version": GENERAL_DATA_VERSION,
                                        "config": json.loads(config.to_json())}, indent=1))
    done = [k for k in range(config.shards) if shard_path(directory, k).exists()]
    todo = [k for k in range(config.shards) if k not in set(done)]
    if max_shards is not None:
        todo = todo[:max_shards]
    from tqdm import tqdm

    t0 = time.perf_counter()
    samples = 0
    maps_done = sum(len(_shard_maps(config, k)) for k in done)
    with tqdm(total=config.maps, initial=maps_done, unit="map", disable=not progress,
              desc="generalist data") as bar:
        for k in todo:
            parts, records = [], []
            for j in _shard_maps(config, k):
                part, record = map_samples(config, j)
                parts.append(part)
                records.append(record)
                bar.update(1)
                bar.set_postfix(samples=samples + sum(len(p["horizon"]) for p in parts))
            arrays = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
            samples += len(arrays["horizon"])
            _write_shard(shard_path(directory, k), arrays, records, config)
    return BuildReport(directory=directory, shards_written=len(todo), shards_skipped=len(done),
                       samples=samples, seconds=time.perf_counter() - t0)


def build_for_map(directory: str | os.PathLike, grid, *, pairs: int = 400, seed: int = 0,
                  expert=None) -> BuildReport:
    """The generalist data of one given map (``grid``, e.g. a user's building: fine-tuning,
    ``ecahd train-general --map``): ``pairs`` expert paths, one shard, written atomically;
    an existing shard of the same map, settings and source is kept.

    ``expert``: an :class:`~ecahd_core.dataset.ExpertDataset` of this map to learn instead of
    the A* expert's paths (``ecahd dataset``'s file: demonstrations cut from the robot's bags,
    ``--from-bags``, or their ``--mix`` with the A* expert); ``pairs`` is then its size.

    Raises:
        DatasetError: ``expert`` is of another map (fingerprint) or has another P^g; the
            directory holds data of another map, settings or source."""
    if expert is not None:
        if expert.map_fingerprint != grid.fingerprint():
            raise DatasetError(f"the dataset is of map {expert.map_name!r} "
                               f"({expert.map_fingerprint}), not of {grid.name!r} "
                               f"({grid.fingerprint()})")
        pairs = expert.num_pairs
    config = GeneralDataConfig(maps=1, maps_per_shard=1, pairs_per_map=pairs, seed=seed)
    if expert is not None and expert.sparse_horizon != config.sparse_horizon:
        raise DatasetError(f"the dataset's paths have {expert.sparse_horizon} sparse waypoints; "
                           f"the generalist learns {config.sparse_horizon}")
    source = "astar" if expert is None else (expert.sha256 or "given")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    path = shard_path(directory, 0)
    t0 = time.perf_counter()
    if path.exists():
        shard = next(iter_shards(directory))
        record = shard.maps[0]
        if shard.config.to_json() == config.to_json() and \
                record.get("fingerprint") == grid.fingerprint() and \
                record.get("source", "astar") == source:
            return BuildReport(directory=directory, shards_written=0, shards_skipped=1,
                               samples=0, seconds=time.perf_counter() - t0)
        raise DatasetError(f"{str(directory)!r} holds generalist data of another map, "
                           f"settings or source; build in another directory")
    arrays, record = map_samples(config, 0, grid=grid, expert=expert)
    if not len(arrays["horizon"]):
        raise DatasetError(f"map {grid.name!r}: no expert problem could be made "
                           f"({record.get('error', 'every view too wide')})")
    record["source"] = source
    _write_shard(path, arrays, [record], config)
    return BuildReport(directory=directory, shards_written=1, shards_skipped=0,
                       samples=len(arrays["horizon"]), seconds=time.perf_counter() - t0)


def _shard_maps(config: GeneralDataConfig, k: int) -> range:
    return range(k * config.maps_per_shard, min((k + 1) * config.maps_per_shard, config.maps))


def map_samples(config: GeneralDataConfig, j: int, grid=None, expert=None
                ) -> tuple[dict[str, np.ndarray], dict]:
    """Map j's samples (the shard arrays of the module docstring, N rows) and its record;
    ``grid``: a given map (a user's, for fine-tuning) instead of generated map j, its expert
    seeded with ``config.seed``; ``expert``: that map's paths as an ExpertDataset (checked by
    the caller) instead of the A* expert's."""
    t0 = time.perf_counter()
    if grid is None:
        map_config = config.map_config(j)
        grid = generate_map(map_config)
        seed = map_config.seed
        record = {"index": j, "name": map_config.name, "kind": map_config.kind.value,
                  "width": map_config.width, "height": map_config.height,
                  "resolution": map_config.resolution, "seed": seed,
                  "fingerprint": grid.fingerprint()}
    else:
        x0, y0, x1, y1 = grid.bounds
        seed = config.seed
        record = {"index": j, "name": grid.name, "kind": "given", "width": x1 - x0,
                  "height": y1 - y0, "resolution": grid.resolution, "seed": seed,
                  "fingerprint": grid.fingerprint()}
    P = config.sparse_horizon
    try:
        expert = expert if expert is not None else generate_dataset(
            grid, pairs=config.pairs_per_map, seed=seed, footprint_spec=config.robot,
            min_distance=config.min_distance, sparse_horizon=P, waypoints=config.waypoints,
            progress=False, workers=1)
    except DatasetError as exc:  # a map without enough expert paths: recorded, not fatal
        log.warning("map %s: no expert data: %s", record["name"], exc)
        record.update(error=str(exc), samples=0, seconds=time.perf_counter() - t0)
        return _empty(config), record
    params = expert.params
    record.update(waypoints=params.get("waypoints", "arclength"),
                  expert=("mix" if "mixed" in params  # ecahd dataset --mix
                          else params.get("source", params.get("expert", "given"))),
                  attempts=params.get("attempts"),
                  pairs=expert.num_pairs)
    N = expert.num_pairs
    rng = np.random.default_rng([config.seed, j, 1])
    h_short = rng.integers(3, P, size=N)  # (N,) in 3..P-1
    trajs = np.full((2 * N, P, 2), np.nan)  # whole problems, then the shorter horizons [m]
    trajs[:N] = expert.sparse
    for i, h in enumerate(h_short):
        trajs[N + i, :h] = expert.sparse_h[int(h)][i]
    horizon = np.concatenate([np.full(N, P), h_short])  # (2N,)
    starts = trajs[:, 0]
    goals = trajs[np.arange(2 * N), horizon - 1]
    integral = OccupancyIntegral.from_grid(grid)
    far = view_side(starts, goals, config.view) > config.view.max_side  # either extent
    keep = ~far
    views = make_views(integral, starts[keep], goals[keep], config.view)
    uv = views.frame.to_view(trajs[keep])  # (K, P, 2), NaN rows stay NaN
    with np.errstate(invalid="ignore"):
        inside = ~(np.abs(uv) > 1.0 + _OUTSIDE_TOL).any(axis=(1, 2))
    record.update(dropped_far=int(far.sum()), dropped_outside=int((~inside).sum()))
    sel = np.flatnonzero(keep)[inside]
    arrays = {
        "global_view": _quantise(views.global_view[inside]),
        "local_views": _quantise(views.local_views[inside]),
        "waypoints": uv[inside].astype(np.float32),
        "horizon": horizon[sel].astype(np.int16),
        "centre": views.frame.centre[inside],
        "half_side": views.frame.half_side[inside],
        "map_index": np.full(len(sel), j, dtype=np.int32),
    }
    record.update(samples=len(sel), seconds=round(time.perf_counter() - t0, 3))
    return arrays, record


def _empty(config: GeneralDataConfig) -> dict[str, np.ndarray]:
    v, P = config.view, config.sparse_horizon
    C, S, Sl = v.channels, v.global_size, v.local_size
    return {"global_view": np.zeros((0, C, S, S), np.uint8),
            "local_views": np.zeros((0, 2, C, Sl, Sl), np.uint8),
            "waypoints": np.zeros((0, P, 2), np.float32), "horizon": np.zeros(0, np.int16),
            "centre": np.zeros((0, 2)), "half_side": np.zeros(0),
            "map_index": np.zeros(0, np.int32)}


def _quantise(view: np.ndarray) -> np.ndarray:
    """Views in [0, 1] (multiples of 1 / FRACTION_LEVELS) -> uint8, exactly."""
    return np.rint(view * FRACTION_LEVELS).astype(np.uint8)


def dequantise(view: np.ndarray) -> np.ndarray:
    """uint8 views of a shard -> float32 in [0, 1], as ``views.make_views`` made them."""
    return view.astype(np.float32) / FRACTION_LEVELS


def _write_shard(path: Path, arrays: dict[str, np.ndarray], records: list[dict],
                 config: GeneralDataConfig) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, version=np.asarray(GENERAL_DATA_VERSION),
                            config_json=np.asarray(config.to_json()),
                            maps_json=np.asarray(json.dumps(records)), **arrays)
    os.replace(tmp, path)


@dataclass(eq=False)
class GeneralDataset:
    """The shards of a directory, loaded (arrays as in the module docstring, concatenated).

    Attributes:
        global_view, local_views: uint8 (:func:`dequantise` for the model).
        waypoints: (N, P^g, 2) float32 view coordinates (NaN beyond ``horizon``).
        horizon: (N,) int16; centre (N, 2), half_side (N,) [m]; map_index (N,) int32.
        maps: the per-map records; config: the builder's config.
    """

    global_view: np.ndarray
    local_views: np.ndarray
    waypoints: np.ndarray
    horizon: np.ndarray
    centre: np.ndarray
    half_side: np.ndarray
    map_index: np.ndarray
    maps: list[dict]
    config: GeneralDataConfig

    def __len__(self) -> int:
        return int(self.horizon.shape[0])

    def views(self, index) -> MapViews:
        """The views of samples ``index`` (an index array or slice) as ``make_views`` gives
        them."""
        return MapViews(global_view=dequantise(self.global_view[index]),
                        local_views=dequantise(self.local_views[index]),
                        frame=ViewFrame(self.centre[index], self.half_side[index]))

    @classmethod
    def load(cls, directory: str | os.PathLike) -> "GeneralDataset":
        """All finished shards of ``directory``; DatasetError naming a bad or foreign file."""
        parts, maps, config = [], [], None
        for shard in iter_shards(directory):
            parts.append(shard.arrays)
            maps += shard.maps
            config = shard.config
        return cls(**{name: np.concatenate([p[name] for p in parts]) for name in SHARD_ARRAYS},
                   maps=maps, config=config)


@dataclass(frozen=True)
class Shard:
    """One shard file as :func:`iter_shards` reads it.

    Attributes:
        path: the file.
        arrays: ``SHARD_ARRAYS`` (module docstring), N rows each.
        maps: its per-map records.
        config: the builder's config (the same for every shard of a directory).
    """

    path: Path
    arrays: dict[str, np.ndarray]
    maps: list[dict]
    config: GeneralDataConfig


def iter_shards(directory: str | os.PathLike):
    """The finished shards of ``directory`` one at a time, in order (a large dataset need not
    be held whole: ``general.train`` keeps its global views once per distinct view).

    Raises:
        DatasetError: no shards, or one naming a corrupt file, another version or another
            config than the first shard's.
    """
    directory = Path(directory)
    paths = sorted(directory.glob(SHARD_GLOB))
    if not paths:
        raise DatasetError(f"{str(directory)!r} holds no generalist shards ({SHARD_GLOB})")
    config_json, config = None, None
    for path in paths:
        try:
            with np.load(path, allow_pickle=False) as npz:
                if int(npz["version"]) != GENERAL_DATA_VERSION:
                    raise DatasetError(f"{str(path)!r} is generalist data version "
                                       f"{int(npz['version'])}; this code reads "
                                       f"{GENERAL_DATA_VERSION}")
                cj = str(npz["config_json"])
                if config_json is not None and cj != config_json:
                    raise DatasetError(f"{str(path)!r} was built with another config than "
                                       f"{str(paths[0])!r}")
                if config_json is None:
                    d = json.loads(cj)
                    config = GeneralDataConfig(**{**d, "sizes": tuple(d["sizes"])})
                config_json = cj
                maps = json.loads(str(npz["maps_json"]))
                arrays = {name: npz[name] for name in SHARD_ARRAYS}
        except DatasetError:
            raise
        except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile) as exc:
            raise DatasetError(f"generalist shard {str(path)!r} is corrupt: {exc}") from exc
        yield Shard(path=path, arrays=arrays, maps=maps, config=config)
