"""Robot footprints: presets, Nav2 strings, sample points R."""
import numpy as np
import pytest

from ecahd_core.errors import FootprintError
from ecahd_core.footprint import (make_footprint, parse_nav2_footprint, point_in_polygon,
                                  polygon_footprint)


def test_circle_preset():
    fp = make_footprint("circle")
    assert fp.is_circle and fp.radius == pytest.approx(0.4)
    d = np.linalg.norm(fp.points, axis=1)
    assert d.max() == pytest.approx(0.4) and d.min() == 0.0  # rim and centre are sampled
    assert np.all(d <= 0.4 + 1e-12)


@pytest.mark.parametrize("name, length, width", [("quadruped", 0.65, 0.30), ("humanoid", 0.25, 0.50)])
def test_box_presets(name, length, width):
    fp = make_footprint(name)
    span = fp.points.max(axis=0) - fp.points.min(axis=0)
    assert span == pytest.approx([length, width])  # x along the heading, y across it
    assert fp.circumscribed_radius == pytest.approx(np.hypot(length, width) / 2)
    assert fp.inscribed_radius == pytest.approx(min(length, width) / 2)
    assert point_in_polygon(fp.points * 0.999, fp.polygon).all()


def test_density_parameter():
    coarse = make_footprint("quadruped", spacing=0.2)
    fine = make_footprint("quadruped", spacing=0.05)
    assert len(fine.points) > 3 * len(coarse.points)


def test_nav2_polygon_string_and_padding():
    fp = make_footprint("[[0.3, 0.2], [-0.3, 0.2], [-0.3, -0.2], [0.3, -0.2]]", padding=0.1)
    assert fp.points.max(axis=0) == pytest.approx([0.4, 0.3])
    assert fp.name == "polygon"
    # a clockwise polygon is reoriented counter-clockwise
    cw = polygon_footprint([[0.3, -0.2], [-0.3, -0.2], [-0.3, 0.2], [0.3, 0.2]])
    x, y = cw.polygon[:, 0], cw.polygon[:, 1]
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0


@pytest.mark.parametrize("text", ["[[0, 0], [1, 0]]", "[[0, 0], [1, x], [0, 1]]", "not a list",
                                  "[[0, 0], [1, 0], [2, 0]]", "[[1, 1], [2, 1], [2, 2]]",
                                  "[[0, .nan], [1, 0], [0, 1]]"])
def test_malformed_polygons(text):
    with pytest.raises(FootprintError):
        make_footprint(text)


def test_unknown_preset_lists_choices():
    with pytest.raises(FootprintError, match="circle.*humanoid.*quadruped"):
        make_footprint("hexapod")
    with pytest.raises(FootprintError):
        make_footprint("circle", spacing=0.0)
    with pytest.raises(FootprintError):
        make_footprint("quadruped", radius=0.3)


def test_transformed_rotates_about_centre():
    fp = make_footprint("quadruped")
    placed = fp.transformed(np.array([2.0, 3.0]), np.array(np.pi / 2), which="polygon")
    # rotated by 90 degrees, the long axis (0.65 m) lies along y
    span = placed.max(axis=0) - placed.min(axis=0)
    assert span == pytest.approx([0.30, 0.65])
    assert placed.mean(axis=0) == pytest.approx([2.0, 3.0])


def test_parse_nav2():
    assert parse_nav2_footprint("[[1, 2], [3, 4], [5, 7]]").shape == (3, 2)
