#!/usr/bin/env bash
# The whole test suite, on a fresh machine or not: `bash scripts/test.sh` (extra args go to pytest).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/venv.sh"
cd "$ROOT"
python -m pytest -q "$@"
