"""Demonstrations from bags (``ecahd_core.demonstrations``, ``ecahd dataset --from-bags``):
hand-made pose streams with each cut and drop reason, the coverage of a known path, the
dataset in the A* expert's format, bags written with rosbags alone through the command, and
bad input as one line with exit code 2."""
import math

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from ecahd_core.dataset import ExpertDataset
from ecahd_core.demonstrations import (DemoConfig, PoseStream, check_map_matches, coverage,
                                       cut_demonstrations, demonstrations_dataset, loops)
from ecahd_core.errors import DatasetError
from ecahd_core.footprint import make_footprint
from ecahd_core.maps import GridMap, builtin_map, save_nav2_yaml
from ecahd_ros.cli import main
from test_eval_bag_no_rclpy import TS, T, _header, _pose, _tf

CIRCLE = make_footprint("circle")  # radius 0.4 m
HZ = 20.0


def _grid() -> GridMap:
    """20 x 10 m at 0.1 m: a one-cell wall frame and a 1 x 2 m block at x 9.5..10.5,
    y 4..6."""
    data = np.zeros((100, 200), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    data[40:60, 95:105] = 100
    return GridMap(data=data, resolution=0.1, name="block")


def drive(points, *, t0: float = 0.0, speed: float = 1.0, hz: float = HZ) -> list:
    """Rows (t, x, y, yaw) at ``hz`` along a polyline at ``speed`` [m/s], the heading that of
    the point 0.3 m ahead (it turns smoothly into each corner, never on the spot)."""
    from ecahd_core.dataset import cumulative_arclength, points_at_arclength

    pts = np.asarray(points, dtype=np.float64)
    total = cumulative_arclength(pts)[-1]
    s = np.arange(0.0, total + 1e-9, speed / hz)
    xy = points_at_arclength(pts, s)
    ahead = points_at_arclength(pts, s + 0.3)
    d = ahead - xy
    yaw = np.arctan2(d[:, 1], d[:, 0])
    yaw[-1] = yaw[-2]
    return [(t0 + i / hz, x, y, a) for i, ((x, y), a) in enumerate(zip(xy, yaw))]


def still(row, seconds: float, *, turn: float = 0.0, hz: float = HZ) -> list:
    """Rows after ``row`` (t, x, y, yaw): ``seconds`` in place, turning by ``turn`` [rad]."""
    t, x, y, yaw = row
    n = int(round(seconds * hz))
    return [(t + k / hz, x, y, yaw + turn * k / n) for k in range(1, n + 1)]


def _cut(rows, config=DemoConfig()):
    return cut_demonstrations(PoseStream.from_records(rows, "test"), _grid(), CIRCLE, config)


def _assert_ends(result, expected) -> None:
    """Each kept demonstration's (start, goal) as expected, to the stop radius (0.1 m): a
    demonstration starts at its stop's last still pose, at most 0.1 m from where the robot
    stood."""
    got = np.array([(p.xy[0], p.xy[-1]) for p in result.kept])
    np.testing.assert_allclose(got, np.array(expected, dtype=float), atol=0.1 + 1e-9, rtol=0)


# ------------------------------------------------------------------------ cuts and drops
def test_a_stop_cuts_the_drive_in_two_and_a_short_pause_does_not():
    a = drive([(1, 2), (8, 2)])  # 7 m at 1 m/s
    for pause, stops, kept in ((3.0, 1, 2), (1.0, 0, 1)):  # stop_time 2 s
        rows = a + still(a[-1], pause)
        rows += drive([(8, 2), (15, 2)], t0=rows[-1][0] + 1 / HZ)[1:]
        result = _cut(rows)
        assert result.counts["stop"] == stops and len(result.kept) == kept
        assert sum(result.counts.values()) == stops
    # after the 3 s stop: one demonstration up to where the robot stopped, one from there
    result = _cut(a + still(a[-1], 3.0) + drive([(8, 2), (15, 2)], t0=a[-1][0] + 3.05)[1:])
    _assert_ends(result, [((1, 2), (8, 2)), ((8, 2), (15, 2))])
    # stopping, then setting off in another direction is a turn in place, not a stop
    result = _cut(a + still(a[-1], 3.0) + drive([(8, 2), (8, 8)], t0=a[-1][0] + 3.05)[1:])
    assert (result.counts["stop"], result.counts["turn_in_place"]) == (0, 1)


def test_a_turn_in_place_cuts_however_brief():
    a = drive([(1, 2), (8, 2)])
    rows = a + still(a[-1], 0.5, turn=math.pi / 2)  # 90 deg in 0.5 s: no stop, a turn
    rows += drive([(8, 2), (8, 8)], t0=rows[-1][0] + 1 / HZ)[1:]
    result = _cut(rows)
    assert result.counts["turn_in_place"] == 1 and result.counts["stop"] == 0
    assert len(result.kept) == 2
    # the corner driven round (the heading turns on the move): one demonstration
    assert len(_cut(drive([(1, 2), (8, 2), (8, 8)])).kept) == 1


def test_a_pose_gap_and_a_teleport_cut():
    a = drive([(1, 2), (8, 2)])
    b = drive([(8, 2.5), (8, 8)], t0=a[-1][0] + 1.0)  # 1 s without a pose (max_gap 0.5 s)
    result = _cut(a + b)
    assert result.counts["pose_gap"] == 1 and result.counts["teleport"] == 0
    assert len(result.kept) == 2
    # 0.05 s later 1.5 m away: more than 2 m/s x 0.05 s + 0.25 m = 0.35 m
    c = drive([(8, 3.5), (8, 8)], t0=a[-1][0] + 0.05)
    result = _cut(a + c)
    assert result.counts["teleport"] == 1 and result.counts["pose_gap"] == 0
    _assert_ends(result, [((1, 2), (8, 2)), ((8, 3.5), (8, 8))])


def test_a_stretch_through_a_wall_is_cut_out_and_counted():
    # along y = 5 through the block (x 9.5..10.5): the robot (r 0.4) touches it from
    # x = 9.1 to 10.9; the free pieces 1 .. ~9.1 and ~10.9 .. 18 stay
    result = _cut(drive([(1, 5), (18, 5)]))
    assert result.counts["collision"] == 1
    assert [p.reason for p in result.dropped] == ["collision"]
    (a0, a1), (b0, b1) = [(p.xy[0], p.xy[-1]) for p in result.kept]
    assert tuple(a0) == (1.0, 5.0) and 9.0 <= a1[0] <= 9.1 and 10.9 <= b0[0] <= 11.0
    hit = result.dropped[0].xy
    assert hit[:, 0].min() <= 9.1 and hit[:, 0].max() >= 10.9


def test_too_short_and_looping_are_dropped_and_corners_and_u_turns_are_not():
    result = _cut(drive([(1, 2), (3.5, 2)]))  # 2.5 m < 3 m
    assert result.counts["too_short"] == 1 and not result.kept
    # up a 6 m dead end and back 0.3 m to the side: back within the robot's 0.4 m of where it
    # was after 12 m; the same 1 m to the side (two passes either side of a wall) stays
    result = _cut(drive([(2, 2), (8, 2), (8, 2.3), (2, 2.3)]))
    assert result.counts["looping"] == 1 and not result.kept
    assert len(_cut(drive([(2, 2), (8, 2), (8, 3), (2, 3)])).kept) == 1
    th = np.linspace(0, 2 * np.pi, 200)
    assert loops(np.c_[5 + 1.5 * np.cos(th), 5 + 1.5 * np.sin(th)], radius=0.4)  # a circle
    # a U-turn of radius 1 m: the legs are 2 m apart
    half = np.linspace(-np.pi / 2, np.pi / 2, 50)
    u = np.concatenate([[[0, -1]], np.c_[5 + np.cos(half), np.sin(half)], [[0, 1]]])
    assert not loops(u + [2, 5], radius=0.4)
    assert not loops(np.array([[1, 2], [8, 2], [8, 8]]), radius=0.4)  # a corner
    # a circle of 0.4 m radius (2.5 m round) is no longer than the 3 m of loop_length
    assert not loops(np.c_[5 + 0.4 * np.cos(th), 5 + 0.4 * np.sin(th)], radius=0.4)


def test_coverage_of_a_line_on_an_open_map():
    # 5 x 5 m free at 0.1 m, a line through the cell centres of row 25 across the map: the
    # cells whose centre is within 1 m are rows 15..35 (21 of 50), all 50 columns
    grid = GridMap(data=np.zeros((50, 50), dtype=np.int8), resolution=0.1)
    share, covered = coverage(grid, [np.array([[0.05, 2.55], [4.95, 2.55]])], radius=1.0)
    assert share == pytest.approx(21 / 50)
    assert covered[15:36].all() and not covered[:15].any() and not covered[36:].any()


def test_poses_in_walls_for_most_of_the_run_refuse_the_map():
    rows = drive([(1, 5), (18, 5)])
    stream = PoseStream.from_records(rows, "bag")
    assert check_map_matches(stream, _grid(), CIRCLE) < 0.2  # only the block
    shifted = PoseStream.from_records([(t, x, y - 4.8, a) for t, x, y, a in rows], "bag")
    with pytest.raises(DatasetError, match=r"bag: 100% of its \d+ poses put robot 'circle' "
                                           r"in a wall of map 'block'"):
        check_map_matches(shifted, _grid(), CIRCLE)


def test_the_dataset_has_the_expert_views_and_round_trips(tmp_path):
    a = drive([(1, 2), (8, 2)])
    rows = a + still(a[-1], 3.0) + drive([(8, 2), (14, 2), (14, 8)], t0=a[-1][0] + 3.05)[1:]
    result = _cut(rows)
    ds = demonstrations_dataset(result, _grid(), waypoints="arclength", sources=["b"])
    assert ds.num_pairs == 2 and ds.sparse.shape == (2, 10, 2)
    assert ds.dense.shape == (18, 4, 2) and ds.full.shape == (2, 100, 2)
    np.testing.assert_allclose(ds.starts, [[1, 2], [8, 2]], atol=0.1)  # where it set off
    np.testing.assert_allclose(ds.goals, [[8, 2], [14, 8]], atol=1e-6)  # where it stopped
    np.testing.assert_allclose(ds.lengths, [7, 12], atol=0.1)
    assert ds.params["counts"]["stop"] == 1 and ds.params["bags"] == ["b"]
    loaded = ExpertDataset.load(ds.save(tmp_path / "d.npz"))
    np.testing.assert_array_equal(loaded.sparse, ds.sparse)
    assert loaded.params["demonstrations"] == 2
    with pytest.raises(DatasetError, match="no demonstration was kept"):
        demonstrations_dataset(_cut(drive([(1, 2), (3, 2)])), _grid())


# ------------------------------------------------------------------------------- bags
def _odom(t: float, x: float, y: float, yaw: float, frame: str = "map"):
    vec = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/Twist"](linear=vec(x=0.0, y=0.0, z=0.0),
                                         angular=vec(x=0.0, y=0.0, z=0.0))
    return T["nav_msgs/msg/Odometry"](
        header=_header(t, frame), child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=_pose(x, y, yaw),
                                                       covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))


def write_drive_bag(path, rows, *, frame: str = "map", topic: str = "/odom",
                    storage=StoragePlugin.MCAP, tf_odom: bool = False) -> None:
    """A bag of odometry rows (t, x, y, yaw) in ``frame``; tf_odom: map -> odom (the
    identity) on /tf every 0.5 s."""
    msgs = [(t, topic, "nav_msgs/msg/Odometry", _odom(t, x, y, a, frame)) for t, x, y, a in rows]
    if tf_odom:
        msgs += [(t, "/tf", "tf2_msgs/msg/TFMessage", _tf(t, "map", "odom", (0.0, 0.0, 0.0)))
                 for t in np.arange(0.0, rows[-1][0] + 0.5, 0.5)]
    with Writer(path, version=8 if storage == StoragePlugin.SQLITE3 else 9,
                storage_plugin=storage) as writer:
        conns = {}
        for t, name, msgtype, msg in sorted(msgs, key=lambda m: m[0]):
            if name not in conns:
                conns[name] = writer.add_connection(name, msgtype, typestore=TS)
            writer.write(conns[name], int(round(t * 1e9)) + 1, TS.serialize_cdr(msg, msgtype))


def _routes() -> list:
    """Three drives separated by 3 s stops: 7 m east, 6 m east + 6 m north round a corner,
    and 1.3 m north (too short)."""
    a = drive([(1, 2), (8, 2)])
    rows = a + still(a[-1], 3.0)
    rows += drive([(8, 2), (14, 2), (14, 8)], t0=rows[-1][0] + 1 / HZ)[1:]
    rows += still(rows[-1], 3.0)
    rows += drive([(14, 8), (14, 9.3)], t0=rows[-1][0] + 1 / HZ)[1:]
    return rows


@pytest.fixture
def site(tmp_path):
    return save_nav2_yaml(_grid(), tmp_path / "site.yaml")


def test_bags_through_the_command(tmp_path, site, capsys):
    rows = _routes()
    write_drive_bag(tmp_path / "mcap", rows)
    # the same driving from a robot: odometry in odom, placed in map by /tf; in SQLite3
    write_drive_bag(tmp_path / "sqlite", rows, frame="odom", tf_odom=True,
                    storage=StoragePlugin.SQLITE3)
    out, png = tmp_path / "demos.npz", tmp_path / "coverage.png"
    assert main(["dataset", "--from-bags", str(tmp_path / "mcap"), str(tmp_path / "sqlite"),
                 "--map", str(site), "--out", str(out), "--png", str(png),
                 "--waypoints", "arclength"]) == 0
    text = capsys.readouterr().out
    assert text.count(f"{len(rows)} poses from /odom") == 2
    assert "kept 4 demonstrations" in text and "4 stop" in text and "2 too short" in text
    ds = ExpertDataset.load(out)
    assert ds.num_pairs == 4 and ds.params["counts"]["too_short"] == 2
    np.testing.assert_allclose(ds.starts[:2], [[1, 2], [8, 2]], atol=0.1)
    np.testing.assert_allclose(ds.starts[2:], ds.starts[:2], atol=1e-5)  # the same driving
    assert 0 < ds.params["coverage"] < 1 and f"{100 * ds.params['coverage']:.1f}%" in text
    assert png.stat().st_size > 10_000 and not list(tmp_path.glob("*.tmp"))


def test_a_truncated_bag_yields_what_it_can(tmp_path, site, capsys):
    rows = _routes()
    write_drive_bag(tmp_path / "bag", rows)
    (mcap,) = (tmp_path / "bag").glob("*.mcap")
    data = mcap.read_bytes()
    mcap.write_bytes(data[:int(0.7 * len(data))])  # the recorder died: no summary, no footer
    (tmp_path / "bag" / "metadata.yaml").unlink()
    out = tmp_path / "d.npz"
    assert main(["dataset", "--from-bags", str(tmp_path / "bag"), "--map", str(site),
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "damaged:" in text and "cut off" in text and "byte(s) of a cut-off tail" in text
    poses = int(text.split(" poses from")[0].rsplit(" ", 1)[-1])
    assert 0.5 * len(rows) < poses < len(rows)
    assert ExpertDataset.load(out).params["damaged_bags"]


def _no_pose_topic(tmp_path):
    with Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=TS)
        writer.write(conn, 1, TS.serialize_cdr(T["std_msgs/msg/String"](data="hi"),
                                               "std_msgs/msg/String"))
    return "has no pose topic (no message on /odom, /tf or /tf_static)"


def _unknown_frame(tmp_path):
    write_drive_bag(tmp_path / "bag", _routes(), frame="odom")  # no tf to place it
    return "no odometry pose could be placed in 'map' (frames ['odom']"


def _wrong_map(tmp_path):
    write_drive_bag(tmp_path / "bag", [(t, x, y - 1.95, a) for t, x, y, a in _routes()])
    return "poses put robot 'circle' in a wall of map 'site': the map does not match the bag"


def _corrupt(tmp_path):
    write_drive_bag(tmp_path / "bag", _routes())
    (mcap,) = (tmp_path / "bag").glob("*.mcap")
    mcap.write_bytes(b"\x00" * 4096)
    return "not an MCAP file"


@pytest.mark.parametrize("make", [_no_pose_topic, _unknown_frame, _wrong_map, _corrupt],
                         ids=["no_pose_topic", "unknown_frame", "wrong_map", "corrupt"])
def test_bad_input_is_one_line_and_exit_code_2(tmp_path, site, capsys, make):
    message = make(tmp_path)
    out = tmp_path / "d.npz"
    assert main(["dataset", "--from-bags", str(tmp_path / "bag"), "--map", str(site),
                 "--out", str(out), "--png", str(tmp_path / "c.png")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("ecahd dataset: error: ")
    assert message in err[0]
    assert {p.name for p in tmp_path.iterdir()} == {"bag", "site.yaml", "site.pgm"}  # no output


def test_the_expert_data_still_needs_out(capsys):
    assert main(["dataset", "--map", "maze2d-umaze", "--pairs", "1"]) == 2
    assert "--out FILE is required" in capsys.readouterr().err


def test_a_bag_copy_reads_the_same(tmp_path):
    """scan_bag on an intact MCAP bag hands on every message (the index agrees)."""
    from ecahd_core.bag_io import bag_topics, scan_bag

    write_drive_bag(tmp_path / "bag", _routes(), tf_odom=True)
    got: dict = {}
    scan = scan_bag(tmp_path / "bag", lambda t: True,
                    lambda topic, t, m: got.__setitem__(topic, got.get(topic, 0) + 1))
    assert got == bag_topics(tmp_path / "bag") and not scan.damaged


def test_demonstrations_mixed_with_expert_data_at_a_share(tmp_path, site, capsys):
    """``ecahd dataset --mix DEMOS EXPERT --share S``: as many pairs as the two allow at that
    share, the demonstrations' rows whole (their segments with them); another map is refused."""
    from ecahd_core.dataset import generate_dataset

    rows = _routes()
    write_drive_bag(tmp_path / "mcap", rows)
    demos = tmp_path / "demos.npz"
    assert main(["dataset", "--from-bags", str(tmp_path / "mcap"), "--map", str(site),
                 "--out", str(demos), "--waypoints", "arclength"]) == 0
    expert = generate_dataset(_grid(), pairs=6, seed=1, progress=False,
                              waypoints="arclength").save(tmp_path / "expert.npz")
    out = tmp_path / "mixed.npz"
    assert main(["dataset", "--mix", str(demos), str(expert), "--share", "0.5",
                 "--out", str(out)]) == 0
    d, e, m = (ExpertDataset.load(p) for p in (demos, expert, out))
    assert d.num_pairs == 2  # one bag of the driving above
    assert m.num_pairs == 4 and m.params["mixed"]["demonstrations"] == 2  # min(2/0.5, 6/0.5)
    np.testing.assert_array_equal(m.sparse[:2], d.sparse)
    np.testing.assert_array_equal(m.dense[:18], d.dense)  # 2 pairs x 9 segments
    assert all(any(np.array_equal(row, x) for x in e.sparse) for row in m.sparse[2:])
    assert "2 demonstrations of 2 + 2 expert paths of 6" in capsys.readouterr().out
    other = generate_dataset(builtin_map("maze2d-umaze"), pairs=2, seed=1, progress=False) \
        .save(tmp_path / "other.npz")
    assert main(["dataset", "--mix", str(demos), str(other), "--out", str(out)]) == 2
    assert "mix data of one map" in capsys.readouterr().err


def test_lanes_command_fits_the_demonstrations_of_a_dataset(tmp_path, capsys):
    """`ecahd lanes`: a field of the dataset's demonstrations on the dataset's map, a figure;
    A* expert data is refused in one line."""
    from ecahd_core.lanes import LaneField

    a = drive([(1, 2), (8, 2)])
    rows = a + still(a[-1], 3.0) + drive([(8, 2), (14, 2), (14, 8)], t0=a[-1][0] + 3.05)[1:]
    ds = demonstrations_dataset(_cut(rows), _grid(), waypoints="arclength", sources=["b"])
    data = ds.save(tmp_path / "d.npz")
    out, png = tmp_path / "lanes.npz", tmp_path / "lanes.png"
    assert main(["lanes", "--data", str(data), "--out", str(out), "--png", str(png)]) == 0
    assert "2 demonstrations, 19 m" in capsys.readouterr().out
    field = LaneField.load(out)
    field.check_map(_grid())
    assert field.value(np.array([4.0, 2.0]), 0.0) > 0.5  # driven east along y = 2
    assert field.value(np.array([4.0, 2.0]), np.pi) < 0.05
    assert png.stat().st_size > 10_000
    expert = ExpertDataset.load(data)
    expert.params.pop("source")
    expert.save(tmp_path / "a.npz")
    assert main(["lanes", "--data", str(tmp_path / "a.npz"), "--out", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err
    assert "holds no demonstrations" in err and err.count("\n") == 1
    assert not (tmp_path / "x.npz").exists()
