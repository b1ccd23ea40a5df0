"""``ecahd bench habits`` (issue 41, item 4): the shipped maze2d-large SD stands in for every
model, on 2 held-out pairs, with a no-go zone across a corridor one pair's shortest path runs
down. About 6 s on 2 cores."""
import json

import numpy as np
import pytest

from ecahd_core.bench.habits import (ASTAR, OPERATOR, PLANNERS, HabitsBenchSettings, format_table,
                                     parse_models, plot_habits, run_habits_benchmark)
from ecahd_core.errors import EcahdError
from ecahd_core.model_zoo import shipped_path
from ecahd_ros.cli import main

SD = str(shipped_path("maze2d-large", "sd"))
# a 1 x 1 m bay across the corridor x 6..7 m of maze2d-large, at y 4..5 m: pair 0 of seed 2026
# (8.76, 7.35) -> (6.44, 2.34) runs down that corridor, pair 1 (-> (1.46, 6.93)) turns west
# at y 5.5 m above it
ZONES = "zones:\n  - {name: bay, polygon: [[6.0, 4.0], [7.0, 4.0], [7.0, 5.0], [6.0, 5.0]]}\n"


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    import torch

    zones = tmp_path_factory.mktemp("habits") / "zones.yaml"
    zones.write_text(ZONES)
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield run_habits_benchmark(HabitsBenchSettings(
            map="maze2d-large", models=(("a", SD), ("b", SD)), problems=2, habit="zone",
            zones=str(zones)), progress=False)
    finally:
        torch.set_num_threads(before)


def test_rows_operator_astar_then_each_models_three(result):
    got = [(r.model, r.planner) for r in result.rows]
    assert got == [(OPERATOR, OPERATOR), (ASTAR, ASTAR)] + [(m, p) for m in "ab" for p in PLANNERS]
    for r in result.rows:
        assert r.problems == 2 and len(r.free_by_problem) == 2 and len(r.time_ms_by_problem) == 2
        assert r.zone is not None and r.corridor_m > 0 and r.right is not None
        assert (r.fallback is not None) == (r.planner == "ECAHD + net")
    assert result.row("a", "SD").checkpoint == SD and result.row(ASTAR, ASTAR).checkpoint is None


def test_every_row_plans_the_same_held_out_pairs(result):
    from ecahd_core.maps import load_map
    from ecahd_core.problems import make_problems

    # the benchmarks' held-out problems of seed 2026; neither end of these two lies in the bay
    want = [(p.start, p.goal) for p in make_problems(load_map("maze2d-large"), 2, seed=2026)]
    np.testing.assert_allclose(np.array(result.pairs), np.array(want), atol=1e-4)
    for key, paths in result.paths.items():
        assert len(paths) == 2, key
        for path, (start, goal) in zip(paths, want):
            np.testing.assert_allclose(path[0], start, atol=1e-3, err_msg=str(key))
            np.testing.assert_allclose(path[-1], goal, atol=1e-3, err_msg=str(key))


def test_the_same_checkpoint_draws_the_same_plans(result):
    # each problem samples from (sample seed, index): two models differ only by their weights
    for planner in PLANNERS:
        a, b = result.row("a", planner), result.row("b", planner)
        for pa, pb in zip(result.paths[("a", planner)], result.paths[("b", planner)]):
            np.testing.assert_array_equal(pa, pb)
        for name in ("right", "zone", "collision_free", "success", "length_ratio", "fallback"):
            assert getattr(a, name) == getattr(b, name), (planner, name)


def test_zone_share_astar_crosses_the_operator_goes_round(result):
    astar, op = result.row(ASTAR, ASTAR), result.row(OPERATOR, OPERATOR)
    assert astar.zone == 50.0  # pair 0's shortest path crosses the bay, pair 1's does not
    assert op.zone == 0.0
    assert op.length_ratio > astar.length_ratio + 0.1  # pair 0 goes round by another corridor
    assert astar.collision_free == op.collision_free == 100.0
    assert astar.success == op.success == 100.0


def test_table_json_and_figure(result, tmp_path):
    table = format_table(result)
    rows = [line for line in table.splitlines() if line.startswith("| ")]
    assert len(rows) == 1 + len(result.rows)  # the header, then one line per row
    assert "in a zone %" in rows[0] and rows[1].startswith("| operator (target) |")
    assert rows[3].startswith("| a | SD |")
    data = json.loads(json.dumps(result.to_dict()))
    assert [r["planner"] for r in data["rows"]][2:5] == list(PLANNERS)
    assert data["map"] == "maze2d-large" and len(data["pairs"]) == 2
    png = plot_habits(result, tmp_path / "habits.png")
    assert png.stat().st_size > 10_000 and not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize("models, message", [
    (["astar"], "expected NAME=CKPT"),
    (["=a.pt"], "expected NAME=CKPT"),
    (["a="], "expected NAME=CKPT"),
    (["1a=a.pt"], "expected NAME=CKPT"),
    (["a=x.pt", "a=y.pt"], "the name 'a' is given twice"),
    (["a=1", "b=2", "c=3", "d=4"], "give 1 to 3 NAME=CKPT, got 4"),
])
def test_bad_models_one_line_exit_2(models, message, capsys):
    with pytest.raises(EcahdError, match=message):
        parse_models(models)
    assert main(["bench", "habits", "--map", "maze2d-large", "--models", *models]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


@pytest.mark.parametrize("checkpoint, message", [
    (SD, "trained for map 'maze2d-large'"),  # a checkpoint of another map
    ("{tmp}/missing.pt", "does not exist"),
])
def test_a_checkpoint_that_cannot_plan_the_map_one_line_nothing_written(checkpoint, message,
                                                                         tmp_path, capsys):
    out = tmp_path / "h.json"
    assert main(["bench", "habits", "--map", "maze2d-medium", "--models",
                 f"mix={checkpoint.format(tmp=tmp_path)}", "--json", str(out),
                 "--png", str(tmp_path / "h.png")]) == 2
    err = capsys.readouterr().err
    assert "--models mix=" in err and message in err and err.count("\n") == 1
    assert not list(tmp_path.iterdir())


def test_zone_habit_needs_zones(capsys):
    assert main(["bench", "habits", "--map", "maze2d-large", "--models", f"a={SD}",
                 "--habit", "zone"]) == 2
    assert "needs --zones" in capsys.readouterr().err


def test_lanes_rows_move_plans_to_the_right_never_into_collision(tmp_path):
    """--lanes: a field fitted on the keep-right operator's routes of other pairs of a small
    generated office (maze2d-large's 1 m corridors are too narrow for the habit) moves A*'s and
    the generalist ECAHD's plans right; every shaped plan stays free by the exact checker."""
    import torch

    from ecahd_core.bench.habits import ASTAR_LANES, LANES
    from ecahd_core.footprint import make_footprint
    from ecahd_core.lanes import LaneField
    from ecahd_core.operator import Operator, OperatorConfig
    from ecahd_core.problems import make_problems

    from ecahd_core.bench.replan import load_bench_map

    office = "office:16x12:0.05:5"
    grid = load_bench_map(office)
    operator = Operator(grid, make_footprint("circle"), [], OperatorConfig())
    routes = [operator.plan(p.start, p.goal).path  # demonstrations: pairs of another seed
              for p in make_problems(grid, 60, seed=7)]
    LaneField.fit(routes, grid).save(tmp_path / "lanes.npz")
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        res = run_habits_benchmark(HabitsBenchSettings(
            map=office, models=(("a", "general"),), problems=4,
            lanes=str(tmp_path / "lanes.npz")), progress=False)
    finally:
        torch.set_num_threads(before)
    got = [(r.model, r.planner) for r in res.rows]
    assert got == [(OPERATOR, OPERATOR), (ASTAR, ASTAR), (ASTAR_LANES, ASTAR_LANES)] + [
        ("a", p) for p in PLANNERS + (LANES,)]
    astar, shaped = res.row(ASTAR, ASTAR), res.row(ASTAR_LANES, ASTAR_LANES)
    assert shaped.right > astar.right and shaped.shaped > 0
    lanes, net = res.row("a", LANES), res.row("a", "ECAHD + net")
    # measured: A* 60.6 -> 65.7% right, ECAHD + net 46.2 -> 82.2% (the operator 83.9%)
    assert lanes.right > net.right + 20
    assert lanes.collision_free == 100.0 and lanes.success == 100.0
    assert lanes.fallback == net.fallback and net.shaped is None
    table = format_table(res)
    assert "lanes of lanes.npz" in table and "| A* + lanes | – |" in table
    assert plot_habits(res, tmp_path / "h.png").stat().st_size > 10_000


def test_lanes_of_another_map_one_line(tmp_path, capsys):
    from ecahd_core.lanes import LaneField
    from ecahd_core.maps import load_map

    LaneField.fit([np.array([[1.5, 1.5], [3.5, 1.5]])], load_map("maze2d-umaze")).save(
        tmp_path / "u.npz")
    assert main(["bench", "habits", "--map", "maze2d-large", "--models", f"a={SD}",
                 "--lanes", str(tmp_path / "u.npz")]) == 2
    err = capsys.readouterr().err
    assert "does not belong to map 'maze2d-large'" in err and err.count("\n") == 1
