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


def test_parameter_tables_of_the_docs_are_up_to_date():
    """docs/parameters.md's tables are rendered from the same declarations (with each node's
    run-time settable parameters marked)."""
    from ecahd_ros.config_doc import render_table, update_markdown

    doc = CONFIG.parents[1] / "docs" / "parameters.md"
    text = doc.read_text()
    assert text == update_markdown(text), \
        "run `ecahd config --md docs/parameters.md`"
    table = render_table("local_refiner")
    assert "| `max_v` |" in table and "(*dynamic*)" in table.split("| `max_v` |")[1].split("\n")[0]
