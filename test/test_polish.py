"""The polishing rule (ecahd_core.polish): J descended over the free points of a path."""
import numpy as np
import pytest
import torch

from ecahd_core.collision import check_collision
from ecahd_core.cost import CostConfig, trajectory_cost
from ecahd_core.errors import EcahdError
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import builtin_map
from ecahd_core.polish import PolishConfig, polish_paths

GRID = builtin_map("maze2d-large")
CC = CostConfig()
CMAP = CC.make_costmap(GRID)
FP = make_footprint("circle")
# maze2d-large: the corridor y in [1, 2] is free for x in [1, 3]; its centre line is y = 1.5
OFF_CENTRE = torch.tensor([[[1.5, 1.5], [1.9, 1.38], [2.3, 1.38], [2.5, 1.5]]])


def collision_cost(paths):
    return trajectory_cost(paths, paths[:, -1], torch.as_tensor(FP.points, dtype=torch.float32),
                           CMAP, **CC.cost_kwargs()).collision_cost


def test_polish_centres_an_off_centre_path_and_keeps_fixed_points():
    fixed = torch.tensor([True, False, False, True])
    assert not check_collision(OFF_CENTRE[0].numpy(), FP, GRID).collision_free
    out, cost = polish_paths(OFF_CENTRE, fixed, CMAP, FP.points, CC, PolishConfig(steps=40))
    assert torch.equal(out[0, fixed], OFF_CENTRE[0, fixed])
    assert float(cost[0]) < 0.5 * float(collision_cost(OFF_CENTRE)[0])
    assert torch.allclose(cost, collision_cost(out))
    assert check_collision(out[0].numpy().astype(np.float64), FP, GRID).collision_free


def test_polish_never_makes_a_path_worse_and_leaves_clear_paths_alone():
    # exactly centred: 0.1 m to each wall, more than the 0.03 m clearance, so left alone
    clear = torch.tensor([[[1.5, 1.5], [2.0, 1.5], [2.5, 1.5], [2.5, 1.5]]])
    batch = torch.cat([clear, OFF_CENTRE])
    out, cost = polish_paths(batch, torch.tensor([True, False, False, True]), CMAP, FP.points, CC,
                             PolishConfig(clearance=0.03))
    assert torch.equal(out[0], batch[0]) and not torch.equal(out[1], batch[1])
    assert (cost <= collision_cost(batch) + 1e-6).all()
    # zero steps: the input back, with its cost
    out0, cost0 = polish_paths(OFF_CENTRE, torch.tensor([True, False, False, True]), CMAP,
                               FP.points, CC, PolishConfig(steps=0))
    assert torch.equal(out0, OFF_CENTRE) and torch.allclose(cost0, collision_cost(OFF_CENTRE))


@pytest.mark.parametrize("kwargs,name", [({"steps": -1}, "steps"), ({"step_size": 0.0}, "step_size"),
                                         ({"clearance": -0.1}, "clearance"),
                                         ({"patience": -2}, "patience")])
def test_polish_config_names_bad_values(kwargs, name):
    with pytest.raises(EcahdError, match=name):
        PolishConfig(**kwargs)


def test_polish_rejects_bad_shapes():
    with pytest.raises(EcahdError, match=r"\(B, P, 2\)"):
        polish_paths(torch.zeros(4, 2), torch.zeros(4, dtype=torch.bool), CMAP, FP.points, CC)


@pytest.mark.parametrize("across", [True, False])
def test_polish_moves_points_across_the_path_only(across):
    """A straight local plan along the corridor y = 5.5 of maze2d-large (x in [2, 6] walled
    on both sides: 0.1 m to spare for the circle), J above the threshold everywhere. Moving
    points only across the path, polishing keeps their order along it (a local plan that
    doubled back swung the closed-loop robot round); free to move along it, J's descent
    pulls an interior point back (the earlier behaviour, ``across=False``)."""
    a, b = np.array([3.0, 5.47]), np.array([3.45, 5.49])
    path = torch.tensor(np.linspace(a, b, 4)[None], dtype=torch.float32)
    fixed = torch.tensor([True, False, False, True])
    out, _ = polish_paths(path, fixed, CMAP, FP.points, CC, PolishConfig(across=across))
    d = (b - a) / np.linalg.norm(b - a)
    s = (out[0].numpy().astype(np.float64) - a) @ d  # progress along the segment [m]
    back = float(np.max(np.maximum.accumulate(s) - s))
    if across:
        assert back < 0.01 and np.all(np.diff(s) > 0)
    else:
        assert back > 0.05


def test_patience_stops_a_path_whose_cost_no_longer_falls(monkeypatch):
    """The corridor x in [1, 3], y in [1, 2] of maze2d-large leaves the circle 0.1 m a side,
    so a clearance of 0.3 m is never reached and every step would run: with ``patience`` a
    path stops once ``patience`` steps in a row lowered its best J by less than 1%, at a cost
    within 1% of what all the steps reach."""
    import ecahd_core.cost as cost_module

    calls = []
    real = cost_module.trajectory_cost

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(cost_module, "trajectory_cost", counting)
    fixed = torch.tensor([True, False, False, True])
    _, full = polish_paths(OFF_CENTRE, fixed, CMAP, FP.points, CC,
                           PolishConfig(steps=200, clearance=0.3))
    assert len(calls) == 201
    calls.clear()
    _, early = polish_paths(OFF_CENTRE, fixed, CMAP, FP.points, CC,
                            PolishConfig(steps=200, clearance=0.3, patience=3))
    assert len(calls) < 60
    assert float(early[0]) <= 1.01 * float(full[0]) + 1e-6


def test_patience_by_the_map_is_on_for_wide_margins_only():
    from ecahd_core.polish import WIDE_MARGIN, WIDE_MARGIN_PATIENCE

    by_map = PolishConfig()
    assert by_map.patience_for(0.1) == 0  # maze2d's cost map: every step
    assert by_map.patience_for(WIDE_MARGIN) == WIDE_MARGIN_PATIENCE == 3  # buildings
    assert PolishConfig(patience=0).patience_for(0.5) == 0
    assert PolishConfig(patience=5).patience_for(0.1) == 5
