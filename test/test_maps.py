"""Maps: built-in mazes, Nav2 YAML round trip, OccupancyGrid layout, bad input."""
import numpy as np
import pytest

from ecahd_core.errors import MapError, PlanningError
from ecahd_core.maps import (FREE, OCCUPIED, UNKNOWN, GridMap, builtin_map, builtin_map_names,
                             from_occupancy_grid, load_map, load_nav2_yaml, save_nav2_yaml,
                             signed_distance, to_occupancy_grid)


def test_builtin_names():
    assert builtin_map_names() == ["maze2d-large", "maze2d-medium", "maze2d-umaze"]


def test_maze2d_large_layout_and_frame():
    m = builtin_map("maze2d-large", resolution=0.1)
    # 12 columns x 9 rows of 1 m cells -> 120 x 90 cells at 0.1 m, origin at the lower-left.
    assert (m.width, m.height) == (120, 90)
    assert m.bounds == (0.0, 0.0, 12.0, 9.0)
    # The border is wall; the layout's bottom line "#OO#OOO#OGO#" is y in [1, 2]:
    # x in [1, 3] open, x in [3, 4] wall.
    assert not m.is_free([0.5, 4.5])
    assert m.is_free([1.5, 1.5]) and m.is_free([2.5, 1.5])
    assert not m.is_free([3.5, 1.5])
    # top open line "#OOOO#OOOOO#" is y in [7, 8]: x in [5, 6] is wall
    assert m.is_free([4.5, 7.5]) and not m.is_free([5.5, 7.5])


def test_resolution_must_divide_cell():
    with pytest.raises(MapError, match="whole number"):
        builtin_map("maze2d-umaze", resolution=0.3)
    with pytest.raises(MapError, match="unknown built-in map"):
        builtin_map("maze2d-huge")


def test_world_cell_round_trip():
    m = builtin_map("maze2d-medium", resolution=0.25)
    rows, cols = np.meshgrid(np.arange(m.height), np.arange(m.width), indexing="ij")
    xy = m.cell_to_world(rows, cols)
    r2, c2 = m.world_to_cell(xy)
    assert np.array_equal(r2, rows) and np.array_equal(c2, cols)


def test_validate_point_errors():
    m = builtin_map("maze2d-umaze")
    assert np.allclose(m.validate_point([3.5, 1.5]), [3.5, 1.5])
    with pytest.raises(PlanningError, match="non-finite"):
        m.validate_point([np.nan, 1.0], "goal")
    with pytest.raises(PlanningError, match="outside the map"):
        m.validate_point([50.0, 1.0], "goal")
    with pytest.raises(PlanningError, match="inside an obstacle"):
        m.validate_point([0.5, 0.5], "start")
    with pytest.raises(PlanningError, match=r"\(x, y\) pair"):
        m.validate_point([1.0, 2.0, 3.0])


@pytest.mark.parametrize("fmt", ["pgm", "png"])
def test_nav2_yaml_round_trip(tmp_path, fmt):
    data = np.full((6, 8), FREE, dtype=np.int8)
    data[0, :] = OCCUPIED
    data[3, 2:5] = OCCUPIED
    data[5, 7] = UNKNOWN
    m = GridMap(data=data, resolution=0.05, origin=(-1.0, 2.5), name="room")
    path = save_nav2_yaml(m, tmp_path / "room.yaml", image_format=fmt)
    back = load_nav2_yaml(path)
    assert np.array_equal(back.data, data)
    assert back.resolution == pytest.approx(0.05)
    assert back.origin == (-1.0, 2.5)
    # an unknown cell counts as occupied by default, and not when asked
    assert back.occupied[5, 7]
    assert not load_nav2_yaml(path, unknown_is_occupied=False).occupied[5, 7]


def test_nav2_yaml_negate_and_thresholds(tmp_path):
    import cv2
    # Pixel p: occupancy probability (255 - p) / 255 with negate 0 -> 0 is occupied (1.0),
    # 254 free (0.004), 128 -> 0.498 lies between free_thresh 0.25 and occupied_thresh 0.65: unknown.
    img = np.array([[0, 254, 128]], dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "m.pgm"), img)
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n"
                                     "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    assert load_nav2_yaml(tmp_path / "m.yaml").data.tolist() == [[OCCUPIED, FREE, UNKNOWN]]
    # negate 1: probability p / 255 -> 0 free, 254 occupied
    (tmp_path / "n.yaml").write_text("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n"
                                     "negate: 1\noccupied_thresh: 0.65\nfree_thresh: 0.25\n")
    assert load_nav2_yaml(tmp_path / "n.yaml").data.tolist() == [[FREE, OCCUPIED, UNKNOWN]]


@pytest.mark.parametrize("text, match", [
    ("image: [unclosed", "not valid YAML"),
    ("- just\n- a list\n", "mapping"),
    ("image: x.pgm\norigin: [0, 0, 0]\n", "resolution"),
    ("image: x.pgm\nresolution: fast\norigin: [0, 0, 0]\n", "malformed"),
    ("image: missing.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n", "missing or unreadable"),
    ("image: x.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nmode: fancy\n", "mode"),
    ("image: x.pgm\nresolution: 0.1\norigin: [0, 0, 0.3]\n", "rotated"),
])
def test_malformed_yaml(tmp_path, text, match):
    (tmp_path / "bad.yaml").write_text(text)
    with pytest.raises(MapError, match=match):
        load_nav2_yaml(tmp_path / "bad.yaml")


def test_malformed_image(tmp_path):
    (tmp_path / "x.pgm").write_bytes(b"this is not an image")
    (tmp_path / "m.yaml").write_text("image: x.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n")
    with pytest.raises(MapError, match="missing or unreadable"):
        load_nav2_yaml(tmp_path / "m.yaml")
    with pytest.raises(MapError, match="does not exist"):
        load_nav2_yaml(tmp_path / "nope.yaml")


def test_load_map_dispatch(tmp_path):
    assert load_map("maze2d-umaze").name == "maze2d-umaze"
    save_nav2_yaml(builtin_map("maze2d-umaze"), tmp_path / "u.yaml")
    assert np.array_equal(load_map(str(tmp_path / "u.yaml")).occupied,
                          builtin_map("maze2d-umaze").occupied)
    with pytest.raises(MapError, match="neither"):
        load_map("not-a-map")


def test_occupancy_grid_layout_round_trip():
    m = builtin_map("maze2d-umaze", resolution=0.5)
    msg = to_occupancy_grid(m)
    assert msg.data.shape == (m.width * m.height,)
    # row-major from the origin: element 0 is the lower-left cell, element W is one row up
    assert msg.data[0] == m.data[0, 0] and msg.data[m.width] == m.data[1, 0]
    back = from_occupancy_grid(msg.data, msg.width, msg.height, msg.resolution, msg.origin_xy)
    assert np.array_equal(back.data, m.data)
    assert back.fingerprint() == m.fingerprint()


def test_occupancy_grid_bad_sizes():
    with pytest.raises(MapError, match="data has 5 cells"):
        from_occupancy_grid([0] * 5, 2, 3, 0.1, (0, 0))
    with pytest.raises(MapError, match="-1..100"):
        from_occupancy_grid([0, 101, 0, 0], 2, 2, 0.1, (0, 0))
    with pytest.raises(MapError, match="positive"):
        from_occupancy_grid([], 0, 0, 0.1, (0, 0))


def test_gridmap_rejects_bad_fields():
    with pytest.raises(MapError, match="resolution"):
        GridMap(data=np.zeros((2, 2), np.int8), resolution=0.0)
    with pytest.raises(MapError, match="2-D"):
        GridMap(data=np.zeros(4, np.int8), resolution=0.1)
    with pytest.raises(MapError, match="finite"):
        GridMap(data=np.zeros((2, 2), np.int8), resolution=0.1, origin=(np.nan, 0))
    with pytest.raises(MapError, match="4001 x 4000 cells is over the size limit"):
        GridMap(data=np.zeros((4000, 4001), np.int8), resolution=0.05)


def test_no_free_cell():
    m = GridMap(data=np.full((3, 3), OCCUPIED, np.int8), resolution=0.1)
    with pytest.raises(MapError, match="no free cell"):
        m.require_free_space()


def test_signed_distance_values():
    # One row of 5 cells at 1 m: [wall, free, free, free, wall]. Free centres lie 0.5, 1.5, 0.5 m
    # from the nearest wall edge along x; everything off the map is wall too, so with a single row
    # the edges above and below are 0.5 m away: distances 0.5, 0.5, 0.5. Wall cells are 0.5 m deep
    # at most (0.5 m from their own free neighbour's edge): sdf = -0.5.
    m = GridMap(data=np.array([[100, 0, 0, 0, 100]], np.int8), resolution=1.0)
    assert np.allclose(signed_distance(m), [[-0.5, 0.5, 0.5, 0.5, -0.5]])
    big = GridMap(data=np.zeros((7, 7), np.int8), resolution=0.5)
    sdf = signed_distance(big)
    assert sdf[3, 3] == pytest.approx(3.5 * 0.5)  # centre cell: 3.5 cells from the map edge


def test_crop_keeps_the_lattice_and_clips_to_the_map():
    data = np.zeros((40, 60), dtype=np.int8)
    data[10, 20] = 100
    grid = GridMap(data, 0.1, (1.0, 2.0), name="c")
    box = grid.crop(2.95, 2.55, 3.55, 3.25)  # cells cols 19..25, rows 5..12
    assert box.origin == pytest.approx((2.9, 2.5)) and box.data.shape == (8, 7)
    assert box.occupied[5, 1] and box.occupied.sum() == 1  # cell (10, 20) of the map
    assert grid.crop(-10, -10, 100, 100) is grid  # covers the map: the map itself
    clipped = grid.crop(0.0, 0.0, 1.45, 2.25)
    assert clipped.origin == pytest.approx((1.0, 2.0)) and clipped.data.shape == (3, 5)
    with pytest.raises(MapError, match="off the map"):
        grid.crop(50, 50, 60, 60)


def test_changed_share_of_an_update_and_another_extent_named():
    """An update of the same site (same cells, resolution, origin): the share of cells whose
    obstacle state changed; a map of another extent: MapError naming both."""
    from ecahd_core.footprint import make_footprint
    from ecahd_core.sensing import ObstacleMemory

    site = builtin_map("maze2d-large")
    data = site.data.copy()
    data[50:60, 35:40] = 100  # 50 free cells walled
    data[0, 0] = 0  # one wall cell opened
    updated = GridMap(data, site.resolution, site.origin, name="update")
    assert site.changed_share(site) == 0.0
    assert updated.changed_share(site) == site.changed_share(updated) == 51 / data.size
    with pytest.raises(MapError, match="not an update of 'maze2d-large'"):
        site.changed_share(builtin_map("maze2d-medium"))
    moved = GridMap(site.data, site.resolution, (0.5, 0.0), name="moved")
    with pytest.raises(MapError, match=r"\(0.5, 0.0\)"):
        site.changed_share(moved)
    # the memory keeps the new walls for good: only those (not the opened cell)
    memory = ObstacleMemory(updated, persistence=1.0)
    assert memory.learnt_from(site) == 50
    assert memory.mask(now=1e6).sum() == 50
    robot = make_footprint("circle")
    assert memory.crosses(np.array([[2.5, 5.5], [4.5, 5.5]]), robot, now=1e6)
    assert not memory.crosses(np.array([[1.5, 1.5], [2.5, 1.5]]), robot, now=1e6)
