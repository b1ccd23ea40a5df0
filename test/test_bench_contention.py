"""Tests of ``ecahd bench contention`` (ecahd_core.bench.contention) and of ``--threads`` on the
benchmarks and training (ecahd_core.threads wiring). No test asserts on a timing: the machine
is shared; they pin the structure, the ratios' arithmetic and that every hog is gone after."""
import argparse
import json
import math
import multiprocessing
import os

import pytest
import torch

from ecahd_core.bench import contention
from ecahd_core.bench.contention import (Cell, ContentionBenchResult, ContentionBenchSettings,
                                         cpu_hog, format_table)
from ecahd_core.commands import bench, train
from ecahd_core.errors import EcahdError
from ecahd_core.threads import training_threads

CELL_KEYS = {"workload", "threads", "hog", "p50_ms", "p99_ms", "mean_ms", "calls", "budget_hit",
             "load_before", "times_ms"}
RATIO_KEYS = {"workload", "threads", "hog", "p50_ratio", "p99_ratio", "within_target"}


def parse(argv):
    parser = argparse.ArgumentParser(prog="ecahd bench")
    bench.add_arguments(parser)
    return parser.parse_args(argv)


def gone(pid: int) -> bool:
    """The process no longer exists (reaped: not even a zombie)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


@pytest.mark.slow
def test_quick_run_writes_every_cell_and_leaves_no_hog(tmp_path, capsys):
    out = tmp_path / "contention.json"
    threads_before = torch.get_num_threads()
    # ours = 1 thread, the reference = 2 (different even on a 1-core machine)
    args = parse(["contention", "--quick", "--reference-threads", "2", "--json", str(out)])
    assert bench.run(args) == 0
    assert torch.get_num_threads() == threads_before  # restored after the run
    r = json.loads(out.read_text())
    assert set(r) == {"cells", "ratios", "context"}
    # 3 workloads x 2 thread counts x (none, torch, spin)
    assert len(r["cells"]) == 3 * 2 * 3 and len(r["ratios"]) == 3 * 2 * 2
    assert {(c["workload"], c["threads"], c["hog"]) for c in r["cells"]} == {
        (w, t, h) for w in ("sd", "hd", "alg1") for t in (1, 2)
        for h in ("none", "torch", "spin")}
    for c in r["cells"]:
        assert set(c) == CELL_KEYS and c["calls"] == len(c["times_ms"]) >= 1
        assert 0 < c["p50_ms"] <= c["p99_ms"] and math.isfinite(c["p99_ms"])
    for x in r["ratios"]:
        assert set(x) == RATIO_KEYS and x["hog"] in ("torch", "spin")
        assert math.isfinite(x["p50_ratio"]) and x["p50_ratio"] > 0
        assert math.isfinite(x["p99_ratio"]) and x["p99_ratio"] > 0
        assert (x["within_target"] is None) == (x["threads"] != 1)  # judged for ours only
    ctx = r["context"]
    assert ctx["thread_counts"] == [1, 2] and ctx["candidates"] == 2
    # one torch hog + 2 spinners (quick), per thread count; all terminated and reaped
    assert len(ctx["hog_pids"]) == 2 * (1 + 2)
    assert all(gone(pid) for pid in ctx["hog_pids"])
    assert not multiprocessing.active_children()
    printed = capsys.readouterr().out
    assert "target (issue 9)" in printed and "Alg. 1, replan once" in printed
    assert "Alg. 1, every waypoint" in printed  # what the nodes run


def test_hog_is_cleaned_up_when_the_body_raises():
    with pytest.raises(RuntimeError, match="boom"):
        with cpu_hog("spin", spinners=2, width=8, threads=1, settle_s=0.0) as pids:
            assert len(pids) == 2
            raise RuntimeError("boom")
    assert all(gone(pid) for pid in pids)
    with cpu_hog("none", spinners=2, width=8, threads=1, settle_s=0.0) as none:
        assert none == []
    with pytest.raises(EcahdError, match="unknown hog"):
        with cpu_hog("disk", spinners=1, width=8, threads=1, settle_s=0.0):
            pass


def synthetic_result() -> ContentionBenchResult:
    def cell(workload, threads, hog, ms):
        return Cell(workload=workload, threads=threads, hog=hog, p50_ms=ms, p99_ms=2 * ms,
                    mean_ms=ms, calls=3, budget_hit=hog == "torch", load_before=1.0,
                    times_ms=[ms] * 3)

    # quiet 100 ms; torch hog 250 ms (2.5x, within 3x); spin 400 ms (4x, beyond)
    cells = [cell("sd", 1, "none", 100.0), cell("sd", 1, "torch", 250.0),
             cell("sd", 1, "spin", 400.0), cell("sd", 2, "none", 50.0),
             cell("sd", 2, "torch", 5000.0)]
    ratios = contention._ratios(cells, ours=1)
    context = {"map": "m", "robot": "circle", "candidates": 10, "problems": 4, "threads": 1,
               "hog_width": 512, "hog_torch_threads": 2, "spinners": 2, "budget_s": 10.0,
               "target_ratio": 3.0, "wall_s": 1.0,
               "machine": {"cpu": "cpu", "logical_cpus": 2, "torch": "x"}}
    return ContentionBenchResult(cells=cells, ratios=ratios, context=context)


def test_ratios_and_table():
    r = synthetic_result()
    by = {(x["threads"], x["hog"]): x for x in r.ratios}
    assert by[(1, "torch")]["p50_ratio"] == pytest.approx(2.5)
    assert by[(1, "torch")]["within_target"] is True
    assert by[(1, "spin")]["p99_ratio"] == pytest.approx(4.0)
    assert by[(1, "spin")]["within_target"] is False
    assert by[(2, "torch")]["p50_ratio"] == pytest.approx(100.0)
    assert by[(2, "torch")]["within_target"] is None  # the reference is not judged
    table = format_table(r)
    assert "NOT met (worst 4.0x)" in table and "3*" in table  # * = stopped by the budget
    assert json.loads(json.dumps(r.to_dict()))["ratios"] == r.ratios


def test_settings_validation_and_thread_counts():
    with pytest.raises(EcahdError, match="threads"):
        ContentionBenchSettings(threads=0)
    with pytest.raises(EcahdError, match="hogs"):
        ContentionBenchSettings(hogs=("disk",))
    with pytest.raises(EcahdError, match="budget_s"):
        ContentionBenchSettings(budget_s=0.0)
    assert ContentionBenchSettings(reference_threads=1).thread_counts() == (1,)
    assert ContentionBenchSettings(reference_threads=3).thread_counts() == (1, 3)
    assert ContentionBenchSettings().thread_counts()[-1] == training_threads()
    quick = ContentionBenchSettings().quick()
    assert quick.sd_repeats < ContentionBenchSettings().sd_repeats and quick.problems == 1


def test_every_benchmark_takes_threads_and_run_applies_it():
    required = {"habits": ["--map", "m.yaml", "--models", "a=a.pt"]}  # no default models
    for name in bench.BENCHMARKS:
        assert parse([name] + required.get(name, [])).threads == 1  # inference default
    assert parse(["sampling", "--threads", "2"]).threads == 2
    seen = []
    table = {"probe": bench.Benchmark(help="", add_arguments=lambda p: None,
                                      run=lambda a: seen.append(torch.get_num_threads()) or 0)}
    before = torch.get_num_threads()
    parser = argparse.ArgumentParser()
    bench.add_arguments(parser, table)
    for argv, expected in ((["probe", "--threads", "1"], 1), (["probe", "--threads", "0"], before)):
        assert bench.run(parser.parse_args(argv), table) == 0
        assert seen[-1] == expected and torch.get_num_threads() == before
    with pytest.raises(EcahdError, match="threads"):
        bench.run(parser.parse_args(["probe", "--threads", "-1"]), table)


def test_train_threads_default_to_every_core():
    p = argparse.ArgumentParser()
    train.add_arguments(p)
    args = p.parse_args(["sd", "--data", "d.npz", "--out", "o.pt"])
    assert args.threads is None  # training: every core (training_threads())
    p = argparse.ArgumentParser()
    train.add_all_arguments(p)
    assert p.parse_args(["--threads", "2"]).threads == 2
