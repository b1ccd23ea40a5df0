"""config/ecahd.yaml documents every parameter of every node with its real default, and the
nodes accept it as a params file."""
from pathlib import Path

import yaml

from ecahd_ros.config_doc import NODES, render_yaml

CONFIG = Path(__file__).resolve().parents[1] / "config" / "ecahd.yaml"


def test_committed_config_is_up_to_date():
    assert CONFIG.read_text() == render_yaml(), "run `ecahd config --out config/ecahd.yaml`"


def test_every_parameter_documented_with_its_default():
    import importlib

    doc = yaml.safe_load(CONFIG.read_text())
    assert set(doc) == set(NODES)
    for node, module in NODES.items():
        specs = importlib.import_module(module).PARAMETERS
        params = doc[node]["ros__parameters"]
        assert [s.name for s in specs] == list(params)
        for s in specs:
            want = list(s.default) if isinstance(s.default, tuple) else s.default
            assert params[s.name] == want, (node, s.name)
            assert s.description.strip(), (node, s.name)
