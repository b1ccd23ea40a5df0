"""`ecahd bench planning --problems 4` with the shipped models: well-formed JSON and markdown."""
import json

import numpy as np
import pytest

from ecahd_core.errors import EcahdError
from ecahd_ros.cli import main

KEYS = {"method", "guidance", "robot", "success", "success_final", "collision_free",
        "collision_rate", "length_ratio", "time_ms_mean", "time_ms_median", "time_ms_p95",
        "dd_ratio"}


@pytest.mark.slow
def test_bench_planning_small(tmp_path):
    js, md, png = tmp_path / "p.json", tmp_path / "p.md", tmp_path / "p.png"
    assert main(["bench", "planning", "--problems", "2", "--robots", "quadruped", "--no-progress",
                 "--json", str(js), "--md", str(md), "--png", str(png)]) == 0
    r = json.loads(js.read_text())
    # FD, SD, HD x {without, with guidance} + A*
    assert len(r["cells"]) == 7 and len(r["ablation"]) == 6
    for cell in r["cells"] + r["ablation"]:
        assert KEYS <= set(cell)
        assert 0 <= cell["collision_free"] <= 100 and cell["time_ms_mean"] > 0
    astar = next(c for c in r["cells"] if c["method"] == "astar")
    # the reference A* keeps the problems' 0.4 m clearance; the quadruped's A* needs less
    assert astar["collision_free"] == 100.0 and 0.8 < astar["length_ratio"] <= 1.0 + 1e-9
    text = md.read_text()
    assert "HD ✓ (ECAHD)" in text and "Table II" in text and "/ 89.1" in text
    assert png.stat().st_size > 10_000


def test_bench_planning_figure_on_a_nav2_yaml_map(tmp_path):
    """--png reloads the map from the path given, not by its name (a YAML's name is its stem)."""
    yaml_path, png = tmp_path / "small_depot.yaml", tmp_path / "p.png"
    assert main(["map", "generate", "--kind", "depot", "--size", "12", "8", "--resolution", "0.05",
                 "--seed", "3", "--out", str(yaml_path)]) == 0
    assert main(["bench", "planning", "--map", str(yaml_path), "--problems", "2", "--methods",
                 "astar", "--robots", "circle", "--no-ablation", "--no-progress",
                 "--png", str(png)]) == 0
    assert png.stat().st_size > 10_000


def test_bench_defaults_follow_the_planner():
    # the bench module avoids importing torch at parser-build time, so it restates two defaults
    from ecahd_core.bench.planning import PlanningBenchSettings
    from ecahd_core.planning.dense import DenseConfig
    from ecahd_core.planning.sparse import SparseConfig

    assert PlanningBenchSettings().guidance_weight == DenseConfig().guidance_weight
    assert PlanningBenchSettings().guidance_space == DenseConfig().guidance_space
    assert PlanningBenchSettings().c_th == DenseConfig().c_th
    assert PlanningBenchSettings().leg_batches == SparseConfig().leg_batches


@pytest.mark.slow
def test_safety_net_is_reported_beside_hd_and_leaves_its_numbers_alone():
    from ecahd_core.bench.planning import (PlanningBenchSettings, format_markdown,
                                           run_planning_benchmark)

    runs = {}
    for net in (False, True):
        runs[net] = run_planning_benchmark(PlanningBenchSettings(
            problems=2, robots=("circle",), methods=("hd",), ablation=False, replan="once",
            safety_net=net),
            progress=False)
    for off, on in zip(runs[False].cells, runs[True].cells):
        a, b = off.to_dict(), on.to_dict()
        for key in ("success", "success_free", "collision_free", "collision_rate",
                    "length_ratio", "dd_ratio"):
            assert a[key] == b[key], key  # the net draws from its own generator
        assert a["net_collision_free"] is None
        assert b["net_collision_free"] == 100.0 - b["net_unsafe_rate"]
        assert b["net_collision_free"] >= b["collision_free"]
        assert b["net_time_ms_mean"] >= b["time_ms_mean"]
        assert 0 <= b["net_fallback_rate"] <= 100 and 0 <= b["net_retry_rate"] <= 100
        assert 0 <= b["net_resample_rate"] <= 100
        assert b["net_retry_rate"] + b["net_resample_rate"] + b["net_fallback_rate"] \
            + b["net_unsafe_rate"] == pytest.approx(100.0 - b["collision_free"])
        assert b["first_leg_rate"] == 0.0  # replan once: every leg is SD's first plan's
        assert b["backtrack_rate"] == 0.0  # replan once (and maze2d-large): never backtracks
        assert b["subgoal_rate"] == 0.0  # replan once: no re-plan loop
    text = format_markdown(runs[True])
    assert "safety net" in text and "resample %" in text and "fallback %" in text
    assert "first leg %" in text and "backtrack %" in text and "subgoal %" in text
    assert "safety net" not in format_markdown(runs[False])


def test_warm_fraction_reaches_hd_and_is_reported():
    from ecahd_core.bench.planning import (PlanningBenchSettings, format_markdown,
                                           run_planning_benchmark)

    r = run_planning_benchmark(PlanningBenchSettings(
        problems=1, robots=("quadruped",), methods=("hd",), ablation=False, safety_net=False,
        warm_fraction=0.3), progress=False)
    assert r.context["warm_fraction"] == 0.3 and len(r.cells) == 2
    assert "warm-started at 0.3 of the schedule" in format_markdown(r)
    # by the map: warm on building maps (where placement acts), from noise on maze2d-large
    assert PlanningBenchSettings().warm_fraction == -1.0
    r = run_planning_benchmark(PlanningBenchSettings(
        problems=1, robots=("quadruped",), methods=("hd",), ablation=False, safety_net=False,
        guidance="on"), progress=False)
    assert "warm-started by the map" in format_markdown(r)


@pytest.mark.parametrize("guidance, want", [("on", [True]), ("off", [False])])
def test_guidance_on_or_off_runs_only_those_cells(guidance, want):
    from ecahd_core.bench.planning import (PlanningBenchSettings, format_markdown,
                                           run_planning_benchmark)

    r = run_planning_benchmark(PlanningBenchSettings(
        problems=1, robots=("circle",), methods=("hd", "astar"), ablation=False,
        safety_net=False, replan="once", guidance=guidance), progress=False)
    assert [c.guidance for c in r.cells if c.method == "hd"] == want
    assert [c.method for c in r.cells].count("astar") == 1
    assert ("HD ✓ (ECAHD)" in format_markdown(r)) == want[0]
    with pytest.raises(EcahdError, match="guidance must be one of"):
        run_planning_benchmark(PlanningBenchSettings(guidance="maybe"), progress=False)


def test_replan_spacing_is_reported_per_robot_when_the_models_differ():
    from ecahd_core.bench.planning import _spacing_text

    assert _spacing_text(3.0) == "3 m"
    assert _spacing_text({"circle": 6.5, "quadruped": None}) == "robot (circle 6.5 m, quadruped off)"


@pytest.mark.slow
def test_per_problem_seeds_reseed_each_problem_and_report_each_problem():
    from ecahd_core.bench.planning import (PlanningBenchSettings, format_markdown,
                                           run_planning_benchmark)

    def run(per_problem):
        return run_planning_benchmark(PlanningBenchSettings(
            problems=2, robots=("circle",), methods=("sd",), ablation=False, guidance="off",
            per_problem_seeds=per_problem), progress=False)

    stream, seeded = run(False), run(True)
    a, b = stream.examples[("sd", False, "circle")], seeded.examples[("sd", False, "circle")]
    np.testing.assert_array_equal(a[0], b[0])  # problem 0's seed: (0, 0) -> the stream's start
    assert not np.array_equal(a[1], b[1])  # problem 1 sampled from its own seed
    cell = seeded.cells[0]
    assert len(cell.free_by_problem) == len(cell.time_ms_by_problem) == 2
    assert 100 * np.mean(cell.free_by_problem) == cell.collision_free
    assert "each problem its own" in format_markdown(seeded)
    assert "each problem its own" not in format_markdown(stream)


def test_bench_general_rows_per_family_and_robot():
    """``ecahd bench general`` with each map's own models on maze2d-large: one row per family and
    robot with the per-problem verdicts aggregated; the JSON keeps every cell."""
    from ecahd_core.bench.general import (GeneralBenchSettings, format_table, rows,
                                          run_general_benchmark)

    result = run_general_benchmark(GeneralBenchSettings(
        maps=("maze2d-large",), problems=2, robots=("circle",), sd_model=None, dd_model=None),
        progress=False)
    (row,) = rows(result)
    assert row["family"] == "maze2d-large" and row["problems"] == 2
    cell = result.cells[0]
    assert row["alone"] == 100 * np.mean(cell["free_by_problem"])
    assert row["net"] == 100 * np.mean(cell["net_free_by_problem"])
    assert len(cell["length_ratio_by_problem"]) == 2 and row["length_median"] > 0.9
    assert len(cell["room_by_problem"]) == 2
    assert row["room_median"] == np.median(cell["room_by_problem"]) and row["room_p5"] > 0
    assert "| maze2d-large | circle | 1 | 2 |" in format_table(result)


def test_bench_general_sd_steps_reach_the_sampler(monkeypatch):
    """``--sd-steps N``: SD samples with N DDIM steps (the table says so)."""
    from ecahd_core.bench.general import GeneralBenchSettings, format_table, run_general_benchmark
    from ecahd_core.planning import sparse

    seen = []
    original = sparse.SparseDiffusion.__init__

    def spy(self, checkpoint, config=None, **kwargs):
        seen.append(config.num_steps)
        original(self, checkpoint, config, **kwargs)

    monkeypatch.setattr(sparse.SparseDiffusion, "__init__", spy)
    result = run_general_benchmark(GeneralBenchSettings(
        maps=("maze2d-large",), problems=1, robots=("circle",), sd_model=None, dd_model=None,
        sd_steps=4), progress=False)
    assert seen and set(seen) == {4}
    assert "SD 4 DDIM steps" in format_table(result)


def test_least_room_is_the_narrowest_gap_along_the_legs_not_only_at_the_points():
    """A path whose two points lie 0.5 m from the nearest wall (the map's edge) but whose leg
    passes the end of a wall 0.3 m away: the room is read along the leg, exactly (0.3 m less the
    robot's radius, to the 1 cm sampling)."""
    from ecahd_core.bench.planning import least_room
    from ecahd_core.footprint import make_footprint
    from ecahd_core.maps import GridMap

    occ = np.zeros((60, 60), dtype=np.int8)  # 3 x 3 m at 0.05 m, origin (0, 0)
    occ[40:, 29:31] = 100  # a wall from the top down to y = 2.0 m, x in [1.45, 1.55]
    grid = GridMap(data=occ, resolution=0.05)
    fp = make_footprint("circle")
    path = np.array([[0.5, 1.7], [2.5, 1.7]])  # passes 0.3 m under the wall's end
    room = least_room(path, fp, grid)
    ends = least_room(path[:1], fp, grid)
    assert ends == pytest.approx(0.5 - fp.inscribed_radius, abs=1e-9)
    assert room == pytest.approx(0.3 - fp.inscribed_radius, abs=1e-6)


def run_general_seeing(monkeypatch, cls, attribute, **settings):
    """``bench general`` on one maze2d-large problem for the circle (its own models) with
    ``settings``, recording ``attribute`` of every ``cls`` it builds -> (result, values)."""
    from ecahd_core.bench.general import GeneralBenchSettings, run_general_benchmark

    seen = []
    original = cls.__init__

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        seen.append(getattr(self, attribute))

    monkeypatch.setattr(cls, "__init__", spy)
    result = run_general_benchmark(GeneralBenchSettings(
        maps=("maze2d-large",), problems=1, robots=("circle",), sd_model=None, dd_model=None,
        **settings), progress=False)
    return result, seen


def test_bench_general_replan_spacing_reaches_the_planner(monkeypatch):
    """``--replan-spacing M``: the planner re-plans with M (the table says so)."""
    from ecahd_core.bench.general import format_table
    from ecahd_core.planning.hierarchical import HierarchicalPlanner

    result, seen = run_general_seeing(monkeypatch, HierarchicalPlanner, "replan_spacing",
                                      replan_spacing=4.5)
    assert seen and set(seen) == {4.5}
    assert "replan spacing 4.5 m" in format_table(result)


def test_bench_general_precision_reaches_the_sd_transformer(monkeypatch):
    """``--precision``: SD's sampler computes in it (the table and the JSON say which), and the
    default is the node's "auto"."""
    from ecahd_core.bench.general import GeneralBenchSettings, format_table
    from ecahd_core.diffusion.sampler import DiffusionSampler

    assert GeneralBenchSettings().precision == "auto"
    result, seen = run_general_seeing(monkeypatch, DiffusionSampler, "precision",
                                      precision="bf16")
    assert "bf16" in seen
    assert result.to_dict()["precision"] == "bf16"
    assert "SD in bf16" in format_table(result)
