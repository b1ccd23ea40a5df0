"""The segment-frame DD (ecahd_core.general.segment_dd): the frame maps each segment's ends to
(0, 0) and (1, 0) both ways, J's gradient goes through it by the chain rule, and a (briefly
trained) checkpoint refines segments on any map through DenseStage, ends exact; load_dd tells it
from a per-map DD."""
import numpy as np
import pytest
import torch

from ecahd_core.general.segment_dd import (SEGMENT_NORMALIZER, SegmentNormalizer,
                                           SegmentSampler, build_segment_data,
                                           to_segment_frame, train_segment_dd)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def test_segment_frame_of_hand_made_segments():
    paths = np.array([[[1.0, 1.0], [1.0, 2.0], [1.0, 3.0]],  # north, length 2
                      [[0.0, 0.0], [1.0, 1.0], [2.0, 0.0]]])  # east with a bump to the left
    u = to_segment_frame(paths)
    np.testing.assert_allclose(u[0], [[0, 0], [0.5, 0], [1, 0]], atol=1e-12)
    np.testing.assert_allclose(u[1], [[0, 0], [0.5, 0.5], [1, 0]], atol=1e-12)


def test_segment_normalizer_round_trip_ends_and_chain_rule():
    torch.manual_seed(0)
    a = torch.randn(4, 2, dtype=torch.float64) * 5
    b = torch.randn(4, 2, dtype=torch.float64) * 5
    b[3] = a[3]  # a zero-length segment keeps a frame
    n = SegmentNormalizer(a, b, SEGMENT_NORMALIZER)
    x = torch.randn(4, 6, 2, dtype=torch.float64)
    torch.testing.assert_close(n.unnormalize(n.normalize(x)), x)
    ends = n.normalize(torch.stack([a, b], dim=1))
    want = SEGMENT_NORMALIZER.normalize(torch.tensor([[0.0, 0.0], [1.0, 0.0]],
                                                     dtype=torch.float64))
    torch.testing.assert_close(ends[:3], want.expand(3, 2, 2), rtol=0, atol=1e-5)
    # dJ/dz by the chain rule == autograd through unnormalize, for J = sum(w . p)
    w = torch.randn(4, 6, 2, dtype=torch.float64)
    z = torch.randn(4, 6, 2, dtype=torch.float64, requires_grad=True)
    (n.unnormalize(z) * w).sum().backward()
    torch.testing.assert_close(n.grad_to_normalized(w), z.grad)


@pytest.fixture(scope="module")
def tiny_segment_dd(tmp_path_factory):
    data = build_segment_data(1, seed=5, pairs_per_map=10, progress=False)
    assert data.segments.shape[1:] == (4, 2) and len(data.segments) > 0
    u = data.segments
    np.testing.assert_allclose(u[:, 0], 0.0, atol=1e-6)
    np.testing.assert_allclose(u[:, -1], np.tile([1.0, 0.0], (len(u), 1)), atol=1e-5)
    path = tmp_path_factory.mktemp("segdd") / "general_dd.pt"
    from ecahd_core.model_zoo import recipe

    train_segment_dd(path, data, recipe("dd"), steps=20, progress=False)
    return path


def test_a_segment_frame_dd_refines_segments_on_any_map(tiny_segment_dd):
    from ecahd_core.cost import CollisionCost
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import builtin_map
    from ecahd_core.model_zoo import load_dd
    from ecahd_core.planning.dense import DenseConfig, DenseStage

    grid = builtin_map("maze2d-large")
    robot = make_footprint("circle")
    ckpt = load_dd(grid, path=tiny_segment_dd)
    assert ckpt.meta["frame"] == "segment"
    assert load_dd(grid).meta.get("frame") is None  # the map's own DD
    cost = CollisionCost.build(grid, robot)
    stage = DenseStage(ckpt, costmap=cost.costmap, footprint_points=cost.footprint_points,
                       cost_config=cost.config, dense=DenseConfig())
    assert isinstance(stage.dd, SegmentSampler)
    a = torch.tensor([[1.5, 1.5], [6.5, 5.5]])
    b = torch.tensor([[2.5, 2.5], [7.5, 5.5]])
    seg, c = stage.refine(a, b, generator=torch.Generator().manual_seed(0))
    assert seg.shape == (2, 4, 2) and torch.isfinite(c).all()
    torch.testing.assert_close(seg[:, 0], a, rtol=0, atol=1e-5)
    torch.testing.assert_close(seg[:, -1], b, rtol=0, atol=1e-5)
