"""``ecahd bench navigation``: the table and the --results block from made-up results (no
ROS), the command's wiring, and one tiny closed-loop run of one variant."""
import json

import pytest

from ecahd_core.evaluation import PAPER_TABLE_III
from ecahd_ros import bench_navigation as nav
from ecahd_ros.cli import build_parser, main


def fake_result(**settings) -> nav.NavigationBenchResult:
    def variant(key, label, reward, reached):
        return nav.VariantResult(
            key=key, label=label,
            summary={"episodes": 2, "episode_reward": reward, "first_reach": 150.0,
                     "collision_rate": 1.25, "inference_time_s": 0.5, "reached": reached,
                     "path_collision_free": 0.5, "control_ms_p50": 1.5,
                     "control_ms_p99": 42.0},
            episodes=[{"penetration_fraction": 0.1}, {"penetration_fraction": 0.0}],
            goal_to_plan_ms=[30.0, None], wall_s=20.0, episodes_wall_s=12.0, sim_s=40.0,
            out="runs/x")

    s = nav.NavigationBenchSettings(**settings)
    context = {**nav.control_context(),
               "machine": {"cpu": "Test CPU", "logical_cpus": 2, "torch": "2.x",
                           "torch_threads": 1, "python": "3.x"}}
    return nav.NavigationBenchResult(settings=s, variants=[
        variant("ecahd", "ECAHD w/ DD", 12.5, 1.0), variant("astar", "A* + controller", 3.0, 0.5)],
        context=context)


def test_table_has_our_variants_then_the_paper_columns():
    md = nav.format_markdown(fake_result())
    header = next(line for line in md.splitlines() if line.startswith("| Metric"))
    cells = [c.strip() for c in header.strip("|").split("|")]
    assert cells[1:3] == ["**ECAHD w/ DD**", "**A* + controller**"]
    assert cells[3:] == [f"{name} (paper)" for name in PAPER_TABLE_III]
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.strip().strip("|").split("|")]
            for line in md.splitlines() if line.startswith("| ") and "Metric" not in line}
    assert rows["Episode Reward ↑"][1:3] == ["12.500", "3.000"]
    paper_w_dd = 3 + list(PAPER_TABLE_III).index("ECAHD w/ DD")
    assert rows["Episode Reward ↑"][paper_w_dd] == "46.862"
    assert rows["Reached episodes"][1:3] == ["2 / 2", "1 / 2"]
    assert rows["Control callback p50 / p99 [ms]"][1] == "1.50 / 42.00"
    assert rows["Goal -> first plan p50 / max [ms]"][1] == "30.0 / 30.0"  # None left out
    # mean penetration (0.1 + 0.0) / 2 = 5 % of the driven poses
    assert rows["Collision, exact checker [% of driven poses in a wall]"][1] == "5.000"
    assert rows["Inference Time [s / episode] ↓"][3] != "-"  # the paper has it
    assert rows["Reached episodes"][3] == "-"  # the paper does not
    # the settings, limits and machine are stated
    for text in ("0.05 s (20 Hz) of the steady wall clock", "|v| <= 0.5 m/s", "|w| <= 1.5 rad/s", "Test CPU",
                 "2 logical CPUs", "torch 2.x"):
        assert text in md
    # off real time the demo puts the control timer on sim time, and the table says so
    assert "(20 Hz) of sim time" in nav.format_markdown(fake_result(realtime_factor=4.0))


def test_results_block_is_replaced_between_the_markers_or_appended(tmp_path):
    block = nav.results_block(fake_result(episodes=1, variants=("ecahd", "astar")))
    assert block.startswith("`ecahd bench navigation --episodes 1 --seed 0 --robot circle "
                            "--map maze2d-large --variants ecahd astar`")
    path = tmp_path / "RESULTS.md"
    path.write_text("# Results\n\nintro\n")
    nav.write_results(path, "placeholder\n")
    text = path.read_text()
    assert text == f"# Results\n\nintro\n\n{nav.SECTION}\n\n{nav.BEGIN}\nplaceholder\n{nav.END}\n"
    path.write_text(text + "\n## Later section\n\nkept\n")
    nav.write_results(path, block)
    text = path.read_text()
    assert "placeholder" not in text and text.count(nav.BEGIN) == text.count(nav.END) == 1
    assert text.startswith("# Results\n\nintro\n") and text.endswith("## Later section\n\nkept\n")
    assert block in text and text.count(nav.SECTION) == 1
    nav.write_results(path, block)  # idempotent
    assert path.read_text() == text
    missing = tmp_path / "new.md"  # a file that does not exist yet
    nav.write_results(missing, "x")
    assert missing.read_text() == f"{nav.SECTION}\n\n{nav.BEGIN}\nx\n{nav.END}\n"


def test_bench_navigation_is_an_ecahd_bench_subcommand_beside_the_core_ones():
    parser = build_parser()
    args = parser.parse_args(["bench", "navigation", "--episodes", "2", "--variants", "astar"])
    assert args.benchmark == "navigation" and args.episodes == 2 and args.variants == ["astar"]
    for name in ("cost", "sampling", "planning", "sd-quality"):
        assert parser.parse_args(["bench", name]).benchmark == name
    with pytest.raises(SystemExit):
        parser.parse_args(["bench", "navigation", "--variants", "rrt"])


@pytest.mark.slow
def test_one_tiny_run_writes_json_md_and_results(tmp_path):
    # one short episode of the A* baseline (no diffusion model at all on the global side)
    results = tmp_path / "RESULTS.md"
    results.write_text(f"# R\n\n{nav.BEGIN}\nstale block\n{nav.END}\n")
    code = main(["bench", "navigation", "--episodes", "1", "--variants", "astar",
                 "--max-steps", "60", "--hold-steps", "5", "--out", str(tmp_path / "runs"),
                 "--json",
                 str(tmp_path / "nav.json"), "--md", str(tmp_path / "nav.md"), "--results",
                 str(results), "--no-progress"])
    assert code == 0
    data = json.loads((tmp_path / "nav.json").read_text())
    (variant,) = data["variants"]
    assert variant["label"] == "A* + controller" and variant["summary"]["episodes"] == 1
    assert variant["goal_to_plan_ms"][0] > 0
    assert variant["summary"]["control_ms_p50"] > 0
    stages = variant["episodes"][0]["stage_ms"]
    assert "astar" in stages and "sd" not in stages and "dd" not in stages  # w/o DD
    text = results.read_text()
    assert "stale block" not in text and "--variants astar --max-steps 60 --hold-steps 5" in text
    md = (tmp_path / "nav.md").read_text()
    assert "A* + controller" in md and "held for 5 control steps" in md


def test_set_overrides_a_node_parameter_for_every_variant_and_names_bad_ones():
    from ecahd_core.errors import EcahdError

    assert nav.parse_override("local_refiner.monitor_shuttles=true") == (
        "local_refiner", "monitor_shuttles", True)
    assert nav.parse_override("local_refiner.max_v=0.3") == ("local_refiner", "max_v", 0.3)
    value = nav.parse_override("local_refiner.max_v=1")[2]
    assert value == 1.0 and isinstance(value, float)  # a double parameter stays a double
    assert nav.parse_override("global_planner.replan=once") == (
        "global_planner", "replan", "once")  # not JSON: a string
    for bad, what in (("local_refiner.max_v", "NODE.PARAM=VALUE"),
                      ("sim_bridge.rate_hz=10", "not one of"),
                      ("local_refiner.no_such=1", "no parameter 'no_such'")):
        with pytest.raises(EcahdError, match=what):
            nav.parse_override(bad)
    settings = nav.NavigationBenchSettings(overrides=(
        nav.parse_override("local_refiner.max_v=0.3"),
        nav.parse_override("global_planner.num_candidates=4")))
    assert nav._overrides(settings, "local_refiner") == {"max_v": 0.3}
    assert nav._overrides(settings, "global_planner") == {"num_candidates": 4}
    assert nav.command_line(settings).endswith(
        "--set local_refiner.max_v=0.3 --set global_planner.num_candidates=4")
    args = build_parser().parse_args(["bench", "navigation", "--set",
                                      "local_refiner.max_v=0.3", "--set",
                                      "local_refiner.monitor_shuttles=true"])
    assert args.overrides == ["local_refiner.max_v=0.3", "local_refiner.monitor_shuttles=true"]
