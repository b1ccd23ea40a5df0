"""Tests of ``ecahd bench cost`` (ecahd_core.commands.bench, ecahd_core.bench.cost)."""
import argparse
import json
import subprocess
import sys

import pytest
import torch

from ecahd_core.bench.cost import CostBenchSettings, format_table, run_cost_benchmark
from ecahd_core.commands import bench
from ecahd_core.errors import EcahdError

KEYS = {"batched_ms", "loop_ms", "speedup", "max_abs_diff", "B", "P", "R", "n_interp", "samples",
        "mode", "map", "footprint", "dtype", "device", "threads", "repeats", "loop_repeats",
        "torch", "python", "cpu_count"}


def parse(argv):
    parser = argparse.ArgumentParser(prog="ecahd bench")
    bench.add_arguments(parser)
    return parser.parse_args(argv)


def test_bench_cost_writes_json(tmp_path, capsys):
    out = tmp_path / "cost.json"
    threads_before = torch.get_num_threads()
    args = parse(["cost", "--json", str(out), "--repeats", "3", "--loop-repeats", "1",
                  "--batch", "1"])
    assert bench.run(args) == 0
    assert torch.get_num_threads() == threads_before  # restored after the run
    result = json.loads(out.read_text())
    assert set(result) == KEYS
    assert result["batched_ms"] > 0 and result["loop_ms"] > 0
    assert result["speedup"] == pytest.approx(result["loop_ms"] / result["batched_ms"])
    assert result["max_abs_diff"] < 1e-2  # float32 batched vs loops on the same inputs
    assert (result["B"], result["P"], result["R"], result["n_interp"]) == (1, 4, 34, 8)
    assert result["samples"] == 1 * (3 * 8 + 1) * 34
    assert result["torch"] == torch.__version__ and result["threads"] == 1
    printed = capsys.readouterr().out
    assert "batched" in printed and "loops" in printed and "speedup" in printed


def test_loop_reference_can_be_skipped():
    result = run_cost_benchmark(CostBenchSettings(repeats=2, warmup=0, loop_repeats=0, batch=2,
                                                  threads=None))
    assert result.loop_ms is None and result.speedup is None and result.batched_ms > 0
    assert "skipped" in format_table(result)


def test_registry_and_argument_errors():
    assert "cost" in bench.BENCHMARKS
    with pytest.raises(SystemExit):
        parse([])  # a benchmark name is required
    with pytest.raises(SystemExit):
        parse(["cost", "--repeats", "0"])
    with pytest.raises(EcahdError, match="horizon"):
        CostBenchSettings(horizon=0)


def test_command_module_does_not_import_torch():
    code = ("import sys, ecahd_core.commands.bench; "
            "sys.exit(1 if 'torch' in sys.modules else 0)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0
