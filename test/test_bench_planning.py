"""`ecahd bench planning --problems 4` with the shipped models: well-formed JSON and markdown."""
import json

from ecahd_ros.cli import main

KEYS = {"method", "guidance", "robot", "success", "success_final", "collision_free",
        "collision_rate", "length_ratio", "time_ms_mean", "time_ms_p95", "dd_ratio"}


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


def test_bench_defaults_follow_the_planner():
    # the bench module avoids importing torch at parser-build time, so it restates two defaults
    from ecahd_core.bench.planning import PlanningBenchSettings
    from ecahd_core.planner import DenseConfig

    assert PlanningBenchSettings().guidance_weight == DenseConfig().guidance_weight
    assert PlanningBenchSettings().guidance_space == DenseConfig().guidance_space
    assert PlanningBenchSettings().c_th == DenseConfig().c_th
