"""``ecahd_core.bench.output.write_json``: the one writer of the ``--json`` results."""
import json

import pytest

from ecahd_core.bench.output import write_json
from ecahd_core.errors import EcahdError


def test_write_json_makes_the_parents_and_round_trips(tmp_path):
    path = tmp_path / "a" / "b" / "result.json"
    payload = {"ms": 1.5, "records": [{"ok": True}, {"ok": None}], "name": "maze2d-large"}
    write_json(path, payload)
    text = path.read_text()
    assert json.loads(text) == payload
    assert text.endswith("}\n") and '\n  "ms": 1.5' in text  # indent 2, a final newline
    write_json(str(path), {"x": [1]}, indent=1)  # a str path; overwrites
    assert path.read_text() == '{\n "x": [\n  1\n ]\n}\n'


def test_an_unwritable_path_is_an_error_naming_it(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    with pytest.raises(EcahdError, match="cannot write the JSON result to .*file/out.json"):
        write_json(blocker / "out.json", {})
