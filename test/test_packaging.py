"""Packaging: colcon builds a runnable ament_python package; importing ecahd_core never loads
rclpy (what each package may import, statically: test_imports.py)."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXECUTABLES = ["ecahd", "map_publisher", "sim_bridge", "bag_recorder", "global_planner",
               "local_refiner"]
# colcon installed by the test extra lives beside this interpreter (a venv need not be on PATH)
COLCON = shutil.which("colcon", path=os.pathsep.join([str(Path(sys.executable).parent),
                                                      os.environ.get("PATH", "")]))


@pytest.mark.slow  # a subprocess importing every module (torch included)
def test_core_import_does_not_load_rclpy():
    modules = sorted(".".join(p.relative_to(ROOT).with_suffix("").parts)
                     for p in (ROOT / "ecahd_core").rglob("*.py") if p.stem != "__init__")
    code = ("import importlib, sys\n"
            f"for m in {modules!r}: importlib.import_module(m)\n"
            "assert 'rclpy' not in sys.modules, 'rclpy was imported'\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


@pytest.mark.slow
def test_colcon_build_installs_ros2_run_layout(tmp_path):
    assert COLCON, "colcon is missing: install the test extra (pip install -e .[test])"
    src = tmp_path / "src" / "ecahd_ros"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(
        ".venv", ".git", "build", "install", "log", "runs", "__pycache__", "*.egg-info"))
    result = subprocess.run([COLCON, "build", "--base-paths", "src"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    install = tmp_path / "install"
    lib = install / "ecahd_ros" / "lib" / "ecahd_ros"
    for exe in EXECUTABLES:  # where `ros2 run ecahd_ros <exe>` looks
        assert os.access(lib / exe, os.X_OK), f"{exe} missing from {lib}"
    share = install / "ecahd_ros" / "share"
    assert (share / "ecahd_ros" / "package.xml").is_file()
    assert (share / "ecahd_ros" / "launch" / "ecahd_sim.launch.py").is_file()
    assert (share / "ecahd_ros" / "config" / "ecahd.yaml").is_file()
    assert (share / "ecahd_ros" / "config" / "maps" / "maze2d-large.yaml").is_file()
    assert (share / "ament_index" / "resource_index" / "packages" / "ecahd_ros").is_file()
    site = next((install / "ecahd_ros" / "lib").glob("python3*/site-packages"))
    env = dict(os.environ, PYTHONPATH=str(site))
    out = subprocess.run([str(lib / "ecahd"), "--help"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "dataset" in out.stdout and "bench" in out.stdout
