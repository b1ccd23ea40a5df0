"""``ecahd bench replan`` on a small generated building: it runs, its references agree."""
import json

import pytest

from ecahd_core.bench.replan import ReplanBenchSettings, load_bench_map, run_replan_benchmark
from ecahd_core.errors import EcahdError


def test_bench_replan_measures_and_its_references_agree(tmp_path, capsys):
    from ecahd_ros.cli import main

    out = tmp_path / "replan.json"
    assert main(["bench", "replan", "--map", "office:16x12:0.05:3", "--problems", "2",
                 "--min-distance", "6", "--repeats", "1", "--no-progress",
                 "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "verdicts agree: True" in printed and "reference / new" in printed
    data = json.loads(out.read_text())
    assert len(data["records"]) == 2
    for r in data["records"]:
        # the fused cost is the whole map's up to float32 rounding: cv2's distance transform
        # on a window can round a distance one ulp apart from the whole map's (seen with the
        # 0.5 m building margin: 8.9e-8)
        assert r["cost_max_diff"] <= 1e-6 and r["crosses_agree"] and r["detour_agree"]
        assert r["judge_agree"] and r["judge_ms"] > 0
        assert r["remembered_cells"] > 0 and r["crosses"]  # the boxes lie on the route
        if r["detour_m"] is not None:
            assert r["detour_m"] < 1.1 * r["detour_ref_m"]


@pytest.mark.parametrize("setting, bad", [
    ("problems", 0), ("problems", -3), ("repeats", 0), ("obstacles", -1),
    ("box", 0.0), ("box", -0.5), ("box", float("nan")), ("box", float("inf")),
    ("min_distance", -1.0), ("min_distance", float("nan")), ("min_distance", float("inf")),
])
def test_bench_replan_settings_are_validated(setting, bad):
    # a bad value is rejected with an error that names the setting (and no other)
    with pytest.raises(EcahdError, match=rf"^bench replan: {setting} must be") as info:
        ReplanBenchSettings(**{setting: bad})
    others = {"problems", "repeats", "obstacles", "box", "min_distance"} - {setting}
    assert not any(name in str(info.value) for name in others), str(info.value)


def test_bench_replan_accepts_good_settings_and_rejects_a_bad_map():
    # the least values each check allows, and the defaults, are accepted as given
    edge = dict(problems=1, repeats=1, obstacles=0, box=1e-3, min_distance=0.0)
    settings = ReplanBenchSettings(**edge)
    assert {name: getattr(settings, name) for name in edge} == edge
    assert ReplanBenchSettings().problems >= 1 and ReplanBenchSettings().box > 0
    # a generated building: KIND:WxH:RES:SEED, W x H [m] at RES [m/cell]
    grid = load_bench_map("office:16x12:0.05:3")
    assert grid.data.shape == (240, 320) and grid.resolution == pytest.approx(0.05)
    # a malformed spec names the expected form; the benchmark checks it before any work
    with pytest.raises(EcahdError, match="KIND:WxH:RES:SEED"):
        load_bench_map("office:axb:0.05:1")
    with pytest.raises(EcahdError, match="KIND:WxH:RES:SEED"):
        run_replan_benchmark(ReplanBenchSettings(map="office:axb:0.05:1"), progress=False)


def test_map_update_bench_times_an_update_against_the_first_map(capsys):
    """``ecahd bench map-update`` on maze2d-large with its own SD: a block on the route of each
    problem, the update planned round it (SD crosses a wall it never learnt: the A* detour),
    the table with the ratio to the first map."""
    from ecahd_core.bench.map_update import (MapUpdateBenchSettings, format_table,
                                             run_map_update_benchmark)

    result = run_map_update_benchmark(MapUpdateBenchSettings(problems=2), progress=False)
    assert len(result.records) == 2
    for r in result.records:
        assert r.round and r.method in ("sd", "fallback_astar")
        assert 0 < r.plan_ms <= r.update_ms and r.first_ms > 0
        assert 0 < r.changed_share < 0.05  # at most 400 cells of a 120 x 90 cell maze
    table = format_table(result)
    assert "ratio to first map" in table and "planned round the block: 2/2" in table
