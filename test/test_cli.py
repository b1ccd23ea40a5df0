"""The `ecahd` command: plan writes a figure and a well-formed record; bad input exits 2 naming
the problem; map export round-trips."""
import json

import numpy as np
import pytest

from ecahd_core.maps import builtin_map, load_nav2_yaml
from ecahd_ros.cli import main


def test_plan_astar_writes_png_and_json(tmp_path):
    png, rec = tmp_path / "p.png", tmp_path / "p.json"
    assert main(["plan", "--method", "astar", "--map", "maze2d-large", "--robot", "humanoid",
                 "--start", "1.5", "1.5",
                 "--goal", "10.5", "7.5", "--png", str(png), "--json", str(rec)]) == 0
    assert png.stat().st_size > 10_000
    r = json.loads(rec.read_text())
    for key in ("waypoints", "trajectory", "robot", "method", "success", "collision_free",
                "timings_ms", "dd_calls"):
        assert key in r
    assert len(r["waypoints"]) == 10 and r["robot"] == "humanoid" and r["method"] == "astar"
    traj = np.array(r["trajectory"])
    assert np.allclose(traj[0], [1.5, 1.5]) and np.allclose(traj[-1], [10.5, 7.5])
    assert r["success"] and r["collision_free"] and r["timings_ms"]["total"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("flags, polished", [([], True),
                                             (["--polish-steps", "0", "--no-keep-better",
                                               "--selection", "shortest_reaching"], False)])
def test_plan_ecahd_with_our_rules_or_the_papers(tmp_path, flags, polished):
    rec = tmp_path / "p.json"
    assert main(["plan", "--method", "ecahd", "--map", "maze2d-large", "--robot", "circle",
                 "--start", "1.5", "1.5", "--goal", "10.5", "7.5", "--json", str(rec),
                 *flags]) == 0
    r = json.loads(rec.read_text())
    assert np.allclose(r["trajectory"][-1], [10.5, 7.5], atol=1e-5)
    # the circle robot's local plans all trigger DD; only our rules polish them
    assert (r["timings_ms"]["polish"] > 0) == polished


@pytest.mark.parametrize("goal, message", [
    (["0.5", "0.5"], "inside an obstacle"),
    (["50", "1"], "outside the map"),
    (["nan", "1"], "non-finite"),
])
def test_plan_bad_goal_exits_2_with_message(tmp_path, capsys, goal, message):
    code = main(["plan", "--goal", *goal, "--png", str(tmp_path / "x.png")])
    assert code == 2
    err = capsys.readouterr().err
    assert "goal" in err and message in err


def test_plan_bad_robot_and_map(tmp_path, capsys):
    assert main(["plan", "--robot", "tank", "--png", str(tmp_path / "x.png")]) == 2
    assert "unknown robot footprint 'tank'" in capsys.readouterr().err
    assert main(["plan", "--map", str(tmp_path / "none.yaml"), "--png", str(tmp_path / "x.png")]) == 2
    assert "does not exist" in capsys.readouterr().err


@pytest.mark.parametrize("argv, want", [([], 1), (["--threads", "2"], 2)])
def test_plan_sets_its_torch_threads_before_planning(tmp_path, monkeypatch, argv, want):
    """``ecahd plan`` runs with 1 torch thread unless told otherwise: with torch's default
    (every core) it took 3-6x its quiet time beside a 2-thread training job on 2 cores."""
    import ecahd_core.commands.plan as plan_command

    seen = []

    def record(n):
        seen.append(n)
        raise KeyboardInterrupt  # stop before the models load: the threads are set first

    monkeypatch.setattr(plan_command, "set_torch_threads", record)
    assert main(["plan", "--png", str(tmp_path / "x.png"), *argv]) == 130
    assert seen == [want]


def test_map_export(tmp_path):
    out = tmp_path / "large.yaml"
    assert main(["map", "maze2d-large", "--export", str(out), "--png", str(tmp_path / "m.png")]) == 0
    assert np.array_equal(load_nav2_yaml(out).occupied, builtin_map("maze2d-large").occupied)
    assert (tmp_path / "m.png").is_file()


def test_shipped_nav2_map_matches_builtin():
    from pathlib import Path
    shipped = Path(__file__).resolve().parents[1] / "config" / "maps" / "maze2d-large.yaml"
    assert np.array_equal(load_nav2_yaml(shipped).occupied, builtin_map("maze2d-large").occupied)


@pytest.mark.slow
@pytest.mark.parametrize("replan", ["once", "every_waypoint"])
def test_plan_ecahd_replan_policies_and_the_safety_net_record(tmp_path, replan):
    rec = tmp_path / "p.json"
    assert main(["plan", "--method", "ecahd", "--robot", "quadruped", "--replan", replan,
                 "--json", str(rec), "--png", str(tmp_path / "p.png")]) == 0
    r = json.loads(rec.read_text())
    assert r["replan"] == replan and r["safety_net"] is True
    assert r["rule"] in ("none", "retry", "resample", "fallback")
    # plans are drawn again only after the retries failed, and the first free one is kept
    assert (r["resampled_plans"] > 0) == (r["rule"] in ("resample", "fallback"))
    assert r["collision_free"] is True  # the net never hands out a colliding plan
    assert isinstance(r["collision_free_before_net"], bool)
    assert r["collision_free_before_net"] == (r["rule"] == "none")
    assert isinstance(r["fallback_stretches"], list) and r["timings_ms"]["safety_net"] > 0
    assert 0 <= r["exact_rule_segments"] <= len(r["waypoints"]) and "exact" in r["timings_ms"]


def test_plan_ecahd_with_warm_started_replans(tmp_path, capsys):
    rec = tmp_path / "p.json"
    args = ["plan", "--method", "ecahd", "--robot", "humanoid", "--json", str(rec),
            "--png", str(tmp_path / "p.png")]
    assert main(args + ["--warm-fraction", "0.3"]) == 0
    r = json.loads(rec.read_text())
    assert r["warm_fraction"] == 0.3 and r["collision_free"] is True
    assert np.allclose(r["trajectory"][-1], [10.5, 7.5], atol=1e-5)
    assert main(args + ["--warm-fraction", "1.5"]) == 2
    assert "warm_fraction" in capsys.readouterr().err


@pytest.mark.slow
def test_plan_sd_through_walls_is_repaired_by_the_fallback(tmp_path):
    # SD alone, its waypoints joined by straight lines, clips a wall near the start for the
    # circle robot (seed 0); the net splices A* in over that stretch
    rec = tmp_path / "p.json"
    args = ["plan", "--method", "sd", "--robot", "circle", "--json", str(rec),
            "--png", str(tmp_path / "p.png")]
    assert main(args + ["--no-safety-net"]) == 0
    off = json.loads(rec.read_text())
    assert off["rule"] == "off" and not off["collision_free"]
    assert main(args) == 0
    r = json.loads(rec.read_text())
    assert r["rule"] == "fallback" and not r["collision_free_before_net"] and r["collision_free"]
    traj = np.array(r["trajectory"])
    for a, b in r["fallback_stretches"]:
        assert 0 <= a < b < len(traj)
    assert np.allclose(traj[0], [1.5, 1.5]) and np.allclose(traj[-1], [10.5, 7.5])


@pytest.mark.slow
def test_plan_places_sd_waypoints_out_of_walls_when_asked(tmp_path):
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import load_map
    from ecahd_core.placement import WaypointPlacer

    rec = tmp_path / "p.json"
    args = ["plan", "--method", "sd", "--robot", "circle", "--no-safety-net", "--json", str(rec),
            "--png", str(tmp_path / "p.png")]
    assert main(args) == 0  # maze2d-large is small: placement off by default
    assert json.loads(rec.read_text())["waypoints_placed"] == 0
    assert main(args + ["--place-reach", "1.0"]) == 0
    r = json.loads(rec.read_text())
    wp = np.array(r["waypoints"])
    judge = WaypointPlacer(load_map("maze2d-large"), make_footprint("circle"))
    assert r["waypoints_placed"] >= 0 and not judge.blocked(wp).any()
    assert main(args + ["--place-reach", "-1"]) == 2  # a clear error, exit code 2


@pytest.mark.slow
def test_plan_without_a_safe_plan_exits_2_and_still_writes_the_record(tmp_path, capsys):
    # goal (1.5, 1.1) in maze2d-large's first cell: free, but 0.1 m from the wall below, so the
    # 0.4 m circle collides there whatever the path, and A* (clearance 0.4 m) cannot end there
    rec, png = tmp_path / "p.json", tmp_path / "p.png"
    code = main(["plan", "--method", "sd", "--robot", "circle", "--start", "1.5", "3.5",
                 "--goal", "1.5", "1.1", "--json", str(rec), "--png", str(png)])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no safe plan" in err[0]
    r = json.loads(rec.read_text())
    assert r["rule"] == "unsafe" and not r["collision_free"] and r["unsafe_reason"]
    assert png.stat().st_size > 10_000


def test_set_torch_threads_sets_opencvs_pool_too():
    """The inference thread count holds for OpenCV's pool as well (the placer's cv2.remap)."""
    import cv2
    import torch

    from ecahd_core.threads import set_torch_threads

    before = torch.get_num_threads(), cv2.getNumThreads()
    try:
        cv2.setNumThreads(2)
        assert set_torch_threads(1) == 1
        assert cv2.getNumThreads() == 1 and torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before[0])
        cv2.setNumThreads(before[1])
