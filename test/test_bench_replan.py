"""``ecahd bench replan`` on a small generated building: it runs, its references agree."""
import json

import pytest

from ecahd_core.bench.replan import ReplanBenchSettings, format_table, run_replan_benchmark
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


def test_bench_replan_settings_are_validated():
    with pytest.raises(EcahdError, match="problems"):
        ReplanBenchSettings(problems=0)
    with pytest.raises(EcahdError, match="box"):
        ReplanBenchSettings(box=float("nan"))
    with pytest.raises(EcahdError, match="KIND:WxH:RES:SEED"):
        run_replan_benchmark(ReplanBenchSettings(map="office:axb:0.05:1"), progress=False)
    assert callable(format_table)
