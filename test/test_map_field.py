"""SD with local map features (``DenoiserConfig.map_field_shape``, ours): the clearance field,
what each waypoint token reads from it, and that a trained model carries its field."""
import math

import numpy as np
import pytest
import torch

from ecahd_core.diffusion.denoiser import (LEG_SAMPLES, LOCAL_FEATURES, RING_DIRECTIONS,
                                           RING_RADII, DenoiserConfig, TransformerDenoiser)
from ecahd_core.diffusion.normalizer import Normalizer
from ecahd_core.diffusion.sampler import sample
from ecahd_core.diffusion.training import TrainConfig, load_checkpoint, train
from ecahd_core.maps import GridMap
from ecahd_core.model_zoo import FIELD_CLIP, clearance_field, field_config

# a 6 m x 4 m map at 0.03 m/cell: a wall x in [2.4, 3.0] m over the lower 3 m
RES = 0.03
H, W = round(4.0 / RES), round(6.0 / RES)


def wall_map() -> GridMap:
    data = np.zeros((H, W), dtype=np.int8)
    data[: round(3.0 / RES), round(2.4 / RES): round(3.0 / RES)] = 100
    return GridMap(data=data, resolution=RES, name="wall")


def tiny(grid: GridMap, max_horizon: int = 6):
    normalizer = Normalizer.from_bounds(*grid.bounds)
    config = DenoiserConfig(max_horizon=max_horizon, d_model=32, n_layers=2, n_heads=4,
                            ff_mult=2)
    config, field = field_config(config, grid, normalizer)
    return config, field, normalizer


def test_clearance_field_is_the_clipped_distance_on_coarser_cells():
    grid = wall_map()
    field = clearance_field(grid)
    # 0.03 m cells averaged to about 0.1 m: 4 m x 6 m -> 40 x 60
    assert field.shape == (40, 60) and field.dtype == np.float32
    assert field.min() == 0.0 and field.max() == 1.0
    assert np.all(field[:25, 25:29] == 0.0)  # inside the wall (x 2.5-2.9 m, y < 2.5 m)
    # x 1.2-1.3 m, y 1.5-1.6 m: over 1.1 m from the wall and the map's edges, past the clip
    assert field[15, 12] == pytest.approx(1.0)
    # 0.45 m left of the wall's face: the clipped distance, divided by the clip
    assert field[15, 19] == pytest.approx(0.45 / FIELD_CLIP, abs=0.06)
    # a grid coarser than the field's cells is used as it is
    coarse = GridMap(data=np.zeros((20, 30), dtype=np.int8), resolution=0.2, name="coarse")
    assert clearance_field(coarse).shape == (20, 30)


def test_each_token_reads_the_field_at_its_point_on_its_rings_and_along_its_leg():
    grid = wall_map()
    config, field, normalizer = tiny(grid)
    model = TransformerDenoiser(config)
    model.set_map_field(field)
    # a path from (1, 1.5) across the wall to (5, 1.5), then up to (5, 3.5)
    metres = torch.tensor([[[1.0, 1.5], [5.0, 1.5], [5.0, 3.5]]])
    feats = model.local_features(normalizer.normalize(metres))
    assert feats.shape == (1, 3, LOCAL_FEATURES)
    rings = 1 + len(RING_RADII) * RING_DIRECTIONS
    point, ring, leg = feats[0, :, 0], feats[0, :, 1:rings], feats[0, :, rings:]
    # the first two points are 1 m from the map's edges, the last 0.5 m from its top
    assert torch.all(point[:2] > 0.9) and point[2] == pytest.approx(0.5, abs=0.06)
    assert leg.shape == (3, LEG_SAMPLES)
    assert leg[0].min() == 0.0  # the first leg crosses the wall ...
    assert leg[1].min() > 0.4  # ... the second does not (x = 5 m, 1 m from the right edge)
    assert torch.all(leg[2] == 0.0)  # the last point has no leg
    # the ring of 1 m round (5, 3.5) reaches off the map's top edge (y = 4 m): 0 there
    up = 1 + RING_DIRECTIONS + RING_DIRECTIONS // 4  # radius 1 m, direction +y
    assert ring[2, up - 1] == 0.0
    # far off the map (a noisy sample early in the schedule) everything reads 0
    far = model.local_features(torch.full((1, 2, 2), 5.0))
    assert torch.all(far == 0.0)


def test_field_settings_are_validated_and_old_configs_stay_as_they_were():
    base = DenoiserConfig(max_horizon=6)
    assert "map_field_shape" not in base.to_dict()  # checkpoints without it do not change
    with pytest.raises(ValueError, match="go together"):
        DenoiserConfig(max_horizon=6, map_field_shape=(4, 4))
    with pytest.raises(ValueError, match="transformer"):
        DenoiserConfig(max_horizon=6, architecture="temporal_unet", map_field_shape=(4, 4),
                       map_field_reach=(1.0, 1.0))
    with pytest.raises(ValueError, match="positive"):
        DenoiserConfig(max_horizon=6, map_field_shape=(4, 4), map_field_reach=(1.0, math.nan))
    config = DenoiserConfig(max_horizon=6, map_field_shape=[4, 5], map_field_reach=[0.5, 1.0])
    assert DenoiserConfig.from_dict(config.to_dict()) == config
    model = TransformerDenoiser(config)
    with pytest.raises(ValueError, match="shape"):
        model.set_map_field(np.zeros((5, 4)))
    with pytest.raises(ValueError, match="without map_field_shape"):
        TransformerDenoiser(base).set_map_field(np.zeros((4, 5)))


def test_a_trained_model_carries_its_field_into_the_checkpoint(tmp_path):
    grid = wall_map()
    config, field, normalizer = tiny(grid)
    rng = np.random.default_rng(0)
    arrays = {4: rng.uniform(0.5, 3.5, (64, 4, 2)).astype(np.float32)}
    cfg = TrainConfig(steps=3, batch_size=16, warmup_steps=0, seed=0)
    with pytest.raises(ValueError, match="map_field"):
        train(config, arrays, normalizer, cfg, kind="sd", out_path=tmp_path / "x.pt",
              progress=False)
    result = train(config, arrays, normalizer, cfg, kind="sd", out_path=tmp_path / "sd.pt",
                   progress=False, map_field=field)
    ckpt = load_checkpoint(result.path)
    assert ckpt.model_config.map_field_shape == field.shape
    model = ckpt.build_model()
    assert np.array_equal(model.map_field[0, 0].numpy(), field)
    start, goal = torch.tensor([[0.5, 0.5]]), torch.tensor([[5.5, 0.5]])
    kw = dict(batch=1, horizon=4, conditions={0: start, -1: goal}, num_steps=5, eta=0.5)
    ref = sample(result.ema_model, ckpt.build_scheduler(), normalizer,
                 generator=torch.Generator().manual_seed(1), **kw).trajectories
    got = sample(model, ckpt.build_scheduler(), normalizer,
                 generator=torch.Generator().manual_seed(1), **kw).trajectories
    assert torch.equal(ref, got)
