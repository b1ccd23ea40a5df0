"""launch/ecahd_sim.launch.py builds the demo's composition. `launch` and `launch_ros` are not on
PyPI, so the test runs the file against minimal stand-ins that record what it asks for."""
import importlib.util
import sys
import types
from pathlib import Path

LAUNCH_FILE = Path(__file__).resolve().parents[1] / "launch" / "ecahd_sim.launch.py"


class _Recorder:
    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


def _fake_modules(monkeypatch):
    names = {
        "launch": ["LaunchDescription"],
        "launch.actions": ["DeclareLaunchArgument"],
        "launch.conditions": ["IfCondition"],
        "launch.substitutions": ["LaunchConfiguration", "PathJoinSubstitution"],
        "launch_ros.actions": ["Node"],
        "launch_ros.substitutions": ["FindPackageShare"],
    }
    for module, classes in names.items():
        m = types.ModuleType(module)
        for cls in classes:
            setattr(m, cls, type(cls, (_Recorder,), {}))
        monkeypatch.setitem(sys.modules, module, m)
    monkeypatch.setitem(sys.modules, "launch_ros", types.ModuleType("launch_ros"))


def test_launch_description(monkeypatch):
    _fake_modules(monkeypatch)
    spec = importlib.util.spec_from_file_location("ecahd_sim_launch", LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    ld = module.generate_launch_description()
    actions = ld.args[0]
    args = {a.args[0]: a.kwargs for a in actions if type(a).__name__ == "DeclareLaunchArgument"}
    assert set(args) == {"params_file", "use_sim_time", "record"}
    nodes = {a.kwargs["executable"]: a.kwargs for a in actions if type(a).__name__ == "Node"}
    assert set(nodes) == {"sim_bridge", "global_planner", "local_refiner", "bag_recorder"}
    assert all(n["package"] == "ecahd_ros" for n in nodes.values())
    # executables exist as console scripts of the package
    setup = (LAUNCH_FILE.parents[1] / "setup.py").read_text()
    for exe in nodes:
        assert f'"{exe} = ' in setup
    # sim_bridge drives the clock and must not wait for it
    assert all(not isinstance(p, dict) for p in nodes["sim_bridge"]["parameters"])
    assert any(isinstance(p, dict) and "use_sim_time" in p
               for p in nodes["global_planner"]["parameters"])
    assert "condition" in nodes["bag_recorder"]
