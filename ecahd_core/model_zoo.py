"""The trained models: training recipes (one place for each default), the data each model learns
from, the identity recorded in a checkpoint, and loading a model for a map and robot.

Shipped models live in ``ecahd_core/models/<map>_<kind>.pt`` (inference-only checkpoints) and
are reproduced from scratch by ``ecahd train-all --map <map>`` (seeded). Models trained for your
own map may live elsewhere: every folder named in the environment variable ``ECAHD_MODELS``
(separated by ``:``) is searched before the package's folder (:func:`model_search_path`).

Kinds (paper Sec. III-B, IV-A):
- ``sd``  Sparse Diffusion: global paths of 2..P^g = 10 waypoints, start and goal inpainted.
- ``dd``  Dense Diffusion: local segments of P^l = 4 points between two sparse waypoints.
- ``fd``  Full-sequence Diffusion (Diffuser-style baseline): 100 points start to goal, a
         temporal U-Net predicting x_0 (Diffuser's TemporalUnet, scaled for a CPU).
"""
from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from ecahd_core.errors import CheckpointError

log = logging.getLogger(__name__)

MODELS_DIR = Path(__file__).resolve().parent / "models"
MODELS_ENV = "ECAHD_MODELS"
KINDS = ("sd", "dd", "fd")
GENERAL = "general"  # SD's model named so: the shipped generalist (issue 40)
GENERAL_FILES = {"sd": "general_sd.pt", "dd": "general_dd.pt"}  # on the model search path
DEFAULT_DENSE_POINTS = 4  # P^l of the paper's DD (2 interior points); a DD checkpoint says its own


@dataclass(frozen=True, kw_only=True)
class ModelRecipe:
    """Architecture and training budget of one model kind.

    Attributes:
        architecture: "transformer" (Fig. 2a; SD, DD) or "temporal_unet" (Diffuser's temporal
            U-Net; the FD baseline), as :class:`~ecahd_core.diffusion.DenoiserConfig`.
        d_model, n_layers, n_heads: Transformer size (transformer only).
        unet_channels, unet_kernel_size: U-Net size (temporal_unet only).
            A size left None takes :class:`~ecahd_core.diffusion.DenoiserConfig`'s default.
        prediction: the network's target, "epsilon" (the paper's noise prediction) or "sample"
            (x_0, as Diffuser on maze2d).
        steps, batch_size, warmup_steps: optimiser budget.
        lr: AdamW learning rate (the paper's 1e-4; other AdamW settings as
            :class:`~ecahd_core.diffusion.TrainConfig`).
        ema_decay: EMA of the sampling weights.
        sample_steps: DDIM steps used when sampling (recorded in the checkpoint; K = 100
            training steps).
        fourier_period: [m] the finest period of the waypoint embedding's Fourier features on
            a building's map (:func:`fourier_bands`; None: none, the paper's embedding).
        batch_horizon: the trajectory length ``batch_size`` was sized for (None: any). A model
            trained on longer trajectories gets a proportionally smaller batch, so a step
            costs about the same (a DD of more than 4 points, ``ecahd dataset --dense-points
            N``; see :meth:`batch_for`).
    """

    architecture: str = "transformer"
    d_model: int | None = None
    n_layers: int | None = None
    n_heads: int | None = None
    unet_channels: tuple[int, ...] | None = None
    unet_kernel_size: int | None = None
    prediction: str = "epsilon"
    steps: int
    batch_size: int
    warmup_steps: int
    lr: float = 1e-4
    ema_decay: float = 0.999
    sample_steps: int = 10
    batch_horizon: int | None = None
    fourier_period: float | None = None

    def batch_for(self, max_horizon: int) -> int:
        """The batch size for trajectories of up to ``max_horizon`` points: ``batch_size``, or
        for a ``batch_horizon`` recipe the same number of tokens per step (each trajectory is
        P + 1 tokens, the +1 the diffusion step's), at least 32."""
        if self.batch_horizon is None or max_horizon <= self.batch_horizon:
            return self.batch_size
        return max(32, round(self.batch_size * (self.batch_horizon + 1) / (max_horizon + 1)))

    def denoiser_config(self, max_horizon: int, grid=None):
        """The :class:`~ecahd_core.diffusion.DenoiserConfig` for trajectories of up to
        ``max_horizon`` points on ``grid`` (None: no Fourier features)."""
        from ecahd_core.diffusion import DenoiserConfig

        sizes = ("d_model", "n_layers", "n_heads") if self.architecture == "transformer" \
            else ("unet_channels", "unet_kernel_size")
        given = {name: getattr(self, name) for name in sizes if getattr(self, name) is not None}
        if grid is not None and self.fourier_period is not None:
            given["fourier_bands"] = fourier_bands(grid, self.fourier_period)
        return DenoiserConfig(max_horizon=max_horizon, architecture=self.architecture,
                              prediction=self.prediction, **given)


def fourier_bands(grid, period: float) -> int:
    """F, the Fourier bands of a waypoint embedding on ``grid`` whose finest period is at least
    ``period`` [m]: the map-bounds normaliser sends a half-extent s [m] to 1, so band k has a
    period of 2 s / 2^k m and F = floor(log2(2 s / period)) + 1 (one band per octave from the
    map's size down). 0 on maps of at most ``astar.COARSE_ABOVE_CELLS`` cells (maze2d-large:
    the paper's embedding, and its tables' models)."""
    from ecahd_core.astar import COARSE_ABOVE_CELLS

    if grid.width * grid.height <= COARSE_ABOVE_CELLS:
        return 0
    x0, y0, x1, y1 = grid.bounds
    half = 0.5 * max(x1 - x0, y1 - y0)
    return max(0, int(math.floor(math.log2(2.0 * half / period))) + 1)


# Sized so that all three train on a 2-core CPU in about 25 minutes (docs/RESULTS.md) and
# sample within the latency targets of `ecahd bench sampling`. FD is the Diffuser-style
# baseline: Diffuser's temporal U-Net predicting x_0 (its maze2d setting), EMA 0.995 (its
# value), lr 1e-3 because the CPU budget allows only ~3000 steps. Chosen on 48 problems of
# another seed than the benchmark's, 10 DDIM steps, eta 0: eps prediction at 2000 steps gave
# 4.4 x the A* length with lr 1e-3, 19.3 x with 1e-4 and 5.9 x with 3e-3 (circle); at 3000 steps
# x_0 prediction left 11% of the path in collision (1.2 x A*) against 29% (2.3 x) for eps
# (quadruped).
# [m] the finest period of SD's Fourier features on a building's map (ModelRecipe.fourier_period)
FOURIER_PERIOD = 0.5
RECIPES: dict[str, ModelRecipe] = {
    "sd": ModelRecipe(d_model=128, n_layers=4, n_heads=4, steps=12000, batch_size=256,
                      warmup_steps=500, fourier_period=FOURIER_PERIOD),
    "dd": ModelRecipe(d_model=96, n_layers=2, n_heads=4, steps=4000, batch_size=256,
                      warmup_steps=300, batch_horizon=DEFAULT_DENSE_POINTS),
    "fd": ModelRecipe(architecture="temporal_unet", unet_channels=(32, 64, 128),
                      unet_kernel_size=5, prediction="sample", steps=3300, batch_size=64,
                      warmup_steps=250, lr=1e-3, ema_decay=0.995),
}


def recipe(kind: str) -> ModelRecipe:
    if kind not in RECIPES:
        raise CheckpointError(f"unknown model kind {kind!r}; allowed: {list(KINDS)}")
    return RECIPES[kind]


def training_arrays(kind: str, dataset) -> dict[int, np.ndarray]:
    """The expert trajectories a model learns from: {horizon: (N, h, 2) [m]}.

    SD learns every horizon 2..P^g that Algorithm 1's shrinking horizon asks for, from two views
    of each expert path: the remaining path after the robot advanced (``sparse_h``, evenly spaced
    suffixes) and the whole path resampled to h points (other spacings, same start-goal
    distribution; with the "corners" waypoint rule the whole path's h corner waypoints of its
    100-point view, :func:`~ecahd_core.dataset.corner_waypoints`). DD learns the P^l-point
    local segments, FD the 100-point sequences.
    """
    from ecahd_core.dataset import resample_by_arclength

    if kind == "sd":
        from ecahd_core.dataset import corner_waypoints, waypoint_rule

        pick = corner_waypoints if waypoint_rule(dataset) == "corners" else resample_by_arclength
        arrays = {}
        for h, suffix in sorted(dataset.sparse_h.items()):
            whole = np.stack([pick(p, h) for p in dataset.full]).astype(np.float32)
            arrays[int(h)] = np.concatenate([suffix, whole]).astype(np.float32)
        return arrays
    if kind == "dd":
        return {int(dataset.dense.shape[1]): dataset.dense.astype(np.float32)}
    if kind == "fd":
        return {int(dataset.full.shape[1]): dataset.full.astype(np.float32)}
    raise CheckpointError(f"unknown model kind {kind!r}; allowed: {list(KINDS)}")


def model_meta(kind: str, dataset) -> dict[str, Any]:
    """Identity recorded in a checkpoint and checked when it is loaded (plus the DDIM step
    count to sample it with, and for SD the expert's waypoint spacing,
    :func:`~ecahd_core.dataset.expert_spacing`, which sets the re-plan spacing on buildings)."""
    from ecahd_core.dataset import expert_spacing

    spacing = {"expert_spacing": round(expert_spacing(dataset), 4)} if kind == "sd" else {}
    return {**spacing,
        "sample_steps": int(recipe(kind).sample_steps),
        "map_name": dataset.map_name,
        "map_fingerprint": dataset.map_fingerprint,
        "robot": dataset.params.get("footprint_spec"),
        "clearance": float(dataset.params.get("clearance")),
        "dataset_sha256": dataset.sha256,
        "dataset_pairs": int(dataset.num_pairs),
        "seed": int(dataset.params.get("seed", 0)),
    }


def model_search_path() -> list[Path]:
    """Folders searched for ``<map>_<kind>.pt``, first match wins: those named in
    ``$ECAHD_MODELS`` (``:``-separated, in order), then the package's own folder."""
    import os

    extra = [Path(d).expanduser() for d in os.environ.get(MODELS_ENV, "").split(os.pathsep) if d]
    return extra + [MODELS_DIR]


def shipped_path(map_name: str, kind: str) -> Path:
    """Where the model of ``kind`` for ``map_name`` is found on :func:`model_search_path`
    (the package's own folder when no folder has it)."""
    name = f"{map_name}_{kind}.pt"
    for folder in model_search_path():
        if (folder / name).is_file():
            return folder / name
    return MODELS_DIR / name


def check_model(kind: str, map_name: str, *, path: str | Path | None = None, footprint=None,
                horizon: int | None = None) -> Path:
    """A node's start-up check of its model, before any map arrives: the checkpoint exists, is
    readable, is of ``kind``, for ``map_name``, fits the robot and the horizon. Returns the
    path. The map's fingerprint is checked later by :func:`load_model`, on the received grid.
    Raises CheckpointError naming the problem. A generalist (``path`` "general" or a file of
    one, SD or DD) plans on any map: only its file and SD's horizon are checked."""
    path = _own_general(kind, map_name) if path is None else path
    if path is not None and kind in GENERAL_FILES:
        general = read_general(kind, path)
        if general is not None:
            _check_fit(general, general.source, None, horizon if kind == "sd" else None)
            return Path(general.source)
    grid = SimpleNamespace(name=map_name, fingerprint=None)
    if path is None:
        path = shipped_path(map_name, kind)
        if not path.is_file():
            _check_shipped(kind, map_name, path)
    _check_fit(_read_checkpoint(kind, grid, path, fingerprint=False), path, footprint, horizon)
    return path


def load_model(kind: str, grid, *, path: str | Path | None = None, footprint=None,
               horizon: int | None = None, device: str = "cpu"):
    """Load a checkpoint for ``grid`` and check it fits the request.

    Args:
        kind: "sd", "dd" or "fd".
        grid: the GridMap the model will plan on (its name and fingerprint must match).
        path: a checkpoint file; default: the shipped model for ``grid.name``.
        footprint: the robot; its circumscribed radius must not exceed the clearance the
            expert data was planned with.
        horizon: a trajectory length the caller will sample; must be one the model learnt.
    Returns:
        the :class:`~ecahd_core.diffusion.training.Checkpoint` (``.build_model()``,
        ``.build_scheduler()``, ``.normalizer``).
    Raises:
        CheckpointError naming the mismatch.
    """
    if kind not in KINDS:
        raise CheckpointError(f"unknown model kind {kind!r}; allowed: {list(KINDS)}")
    if path is None:
        path = shipped_path(grid.name, kind)
        if not path.is_file():
            _check_shipped(kind, grid.name, path)
    ckpt = _read_checkpoint(kind, grid, path, device=device)
    _check_fit(ckpt, path, footprint, horizon)
    return ckpt


def general_path(kind: str = "sd") -> Path:
    """Where the generalist of ``kind`` ("sd": the map-conditioned SD; "dd": the segment-frame
    DD) is found on :func:`model_search_path` (the package's own folder when no folder has
    it)."""
    name = GENERAL_FILES[kind]
    for folder in model_search_path():
        if (folder / name).is_file():
            return folder / name
    return MODELS_DIR / name


def _general_file(kind: str) -> Path:
    path = general_path(kind)
    if not path.is_file():
        how = "ecahd train-general --ship FILE" if kind == "sd" else "ecahd train-general-dd"
        raise CheckpointError(f"no generalist {kind.upper()} ({GENERAL_FILES[kind]} in none of "
                              f"{[str(d) for d in model_search_path()]}); train one with "
                              f"`{how}`")
    return path


def _own_general(kind: str, map_name: str) -> Path | None:
    """The generalist that serves ``map_name`` when no model is named: the map's shipped model
    of ``kind`` when it is a generalist fine-tuned on the map (``ecahd train-general --map ...
    --from general --ship <map>_sd.pt``); the shipped generalist when the map has no model of
    its own; else None (the map's own per-map model, or the error naming what is missing)."""
    if kind not in GENERAL_FILES:
        return None
    path = shipped_path(map_name, kind)
    if path.is_file():
        return path if read_general(kind, path) is not None else None
    general = general_path(kind)
    if general.is_file():
        log.info("no %s model of map %r: the generalist %s plans on it", kind.upper(),
                 map_name, general)
        return general
    return None


def _file_stamp(path: Path) -> tuple:
    """(modification time [ns], size) of a file, or () when it cannot be read (the read then
    names the problem)."""
    try:
        st = path.stat()
    except OSError:
        return ()
    return (st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=4)
def _read_cached(path: str, stamp: tuple, device: str):
    """A checkpoint file's plain data, read once per (file, version): a node that takes a new
    map reads its generalist from memory, not from disk (100-200 ms for a 6-23 MB file on a
    busy 2-core machine). Nobody mutates the payload (checkpoints are frozen)."""
    from ecahd_core.diffusion.training import read_checkpoint_file

    return read_checkpoint_file(path, map_location=device)


def read_general(kind: str, path: str | Path, *, device: str = "cpu"):
    """The generalist of ``kind`` that ``path`` names ("general": the shipped one, or a file of
    one), or None when ``path`` is a per-map checkpoint. "sd": the map-conditioned SD
    (``general.GeneralCheckpoint``); "dd": the segment-frame DD (a DD checkpoint whose meta
    says so, ``general.segment_dd``). Raises CheckpointError naming the file when it is
    missing, unreadable or of another kind."""
    from ecahd_core.diffusion.training import Checkpoint
    from ecahd_core.general.checkpoint import GENERAL_CHECKPOINT_FORMAT, GeneralCheckpoint
    from ecahd_core.general.segment_dd import is_segment_frame

    path = _general_file(kind) if str(path) == GENERAL else Path(path)
    payload = _read_cached(str(path), _file_stamp(path), device)
    if kind == "sd":
        if isinstance(payload, dict) and payload.get("format") == GENERAL_CHECKPOINT_FORMAT:
            return GeneralCheckpoint.from_dict(payload, source=path)
        return None
    if kind == "dd" and isinstance(payload, dict) and payload.get("kind") == "dd" \
            and is_segment_frame(SimpleNamespace(meta=payload.get("meta") or {})):
        return Checkpoint.from_dict(payload, source=path)
    return None


def is_general(kind: str, path: str | Path | None, map_name: str | None = None) -> bool:
    """Whether ``path`` (a node's ``sd_model`` / ``dd_model``; empty: the shipped model of
    ``map_name``) names a generalist of ``kind``, which plans on any map
    (:func:`read_general`)."""
    if not path:
        return map_name is not None and _own_general(kind, map_name) is not None
    return kind in GENERAL_FILES and read_general(kind, path) is not None


def load_sd(grid, *, path: str | Path | None = None, footprint=None,
            horizon: int | None = None, device: str = "cpu"):
    """SD's checkpoint for ``grid``: the map's own model (:func:`load_model`) or the generalist,
    which plans on any map (``general.GeneralCheckpoint``, for ``SparseDiffusion``).

    Args:
        path: None: the map's shipped model, else the shipped generalist (:func:`_own_general`);
            ``GENERAL`` ("general"): the shipped generalist (:func:`general_path`); a file: that
            checkpoint, per-map or generalist by its format.
        footprint, horizon, device: as :func:`load_model`. The generalist learnt one robot's
            clearance (its data's ``robot``) and plans for any footprint: J's selection, the
            placer, DD and the exact checker judge the footprint itself.
    Raises:
        CheckpointError naming the file and the problem.
    """
    path = _own_general("sd", grid.name) if path is None else path
    general = None if path is None else read_general("sd", path, device=device)
    if general is None:
        return load_model("sd", grid, path=path, footprint=footprint, horizon=horizon,
                          device=device)
    _check_fit(general, general.source, None, horizon)
    return general


def load_dd(grid, *, path: str | Path | None = None, footprint=None, device: str = "cpu"):
    """DD's checkpoint for ``grid``: the map's own (:func:`load_model`) or the segment-frame
    generalist (``general.segment_dd``), which refines segments on any map.

    Args:
        path: None: the map's shipped DD, else the shipped generalist; ``GENERAL``: the
            shipped generalist (:func:`general_path`); a file: that checkpoint, per-map or
            segment-frame by its meta.
    Raises:
        CheckpointError naming the file and the problem.
    """
    path = _own_general("dd", grid.name) if path is None else path
    general = None if path is None else read_general("dd", path, device=device)
    if general is None:
        return load_model("dd", grid, path=path, footprint=footprint, device=device)
    return general


def learnt_map(site, grid) -> tuple:
    """The map a per-map model is checked against when ``grid`` arrives: ``grid`` itself when
    it is the site's first map (``site`` None) or the same map, else ``site`` (the map the
    models were loaded for) when ``grid`` is an update of it (same cells, resolution and
    origin: a SLAM update, an edited map). Returns (that map, share of cells changed);
    MapError when ``grid`` covers another extent (a per-map model cannot plan there).

    An update keeps the models of the site: J, DD's guidance, the exact checker and the
    safety net work on the new map, and the walls SD never learnt are detoured
    (``OnlinePlanner.set_map(learnt=...)``)."""
    if site is None or grid.fingerprint() == site.fingerprint():
        return grid, 0.0
    return site, site.changed_share(grid)


def _check_shipped(kind: str, map_name: str, path) -> None:
    folders = model_search_path()
    known = sorted({p.stem for d in folders if d.is_dir() for p in d.glob("*.pt")})
    raise CheckpointError(
        f"no {kind!r} model for map {map_name!r} ({path.name} in none of "
        f"{[str(d) for d in folders]}; found: {known}); train one with `ecahd train-all --map "
        f"...` and put its --out-dir on ${MODELS_ENV}")


def _read_checkpoint(kind: str, grid, path, *, fingerprint: bool = True, device: str = "cpu"):
    from ecahd_core.diffusion.training import load_checkpoint

    expect = {"kind": kind, "map_name": grid.name}
    if fingerprint:
        expect["map_fingerprint"] = grid.fingerprint()
    return load_checkpoint(path, expect=expect, map_location=device)


def _check_fit(ckpt, path, footprint, horizon) -> None:
    if footprint is not None:
        clearance = float(ckpt.meta.get("clearance", 0.0))
        if footprint.circumscribed_radius > clearance + 1e-6:
            raise CheckpointError(
                f"checkpoint '{path}' was trained on expert paths with {clearance:.3f} m "
                f"clearance (robot {ckpt.meta.get('robot')!r}); robot {footprint.name!r} needs "
                f"{footprint.circumscribed_radius:.3f} m: train a model for this robot")
    if horizon is not None and int(horizon) not in ckpt.horizons:
        raise CheckpointError(f"checkpoint '{path}' was trained for "
                              f"horizons {list(ckpt.horizons)}, not {horizon}")


def dense_points(checkpoint) -> int:
    """P^l, the points of a local plan a DD checkpoint learnt (the longest of its horizons)."""
    return int(max(checkpoint.horizons))


def sample_steps(checkpoint) -> int:
    """The DDIM step count a checkpoint is meant to be sampled with."""
    return int(checkpoint.meta.get("sample_steps", RECIPES[checkpoint.kind].sample_steps))
