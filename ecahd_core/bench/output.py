"""Where a JSON result goes: the one writer behind every ``--json`` option (the benchmarks,
``ecahd plan``, ``ecahd eval-bag``), so each file is written the same way (parent directories made,
indented, a final newline) and a path that cannot be written is an EcahdError naming it."""
from __future__ import annotations

import json
from pathlib import Path

from ecahd_core.errors import EcahdError


def write_json(path, payload: dict, *, indent: int = 2) -> None:
    """Write ``payload`` as JSON to ``path`` (str or Path), making its parent directories;
    raises EcahdError naming the path when it cannot be written."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(payload, indent=indent) + "\n")
    except OSError as exc:
        raise EcahdError(f"cannot write the JSON result to {str(path)!r}: {exc}") from exc
