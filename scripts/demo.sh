#!/usr/bin/env bash
# The main job, on a fresh machine or not: `bash scripts/demo.sh` (extra args go to `ecahd plan`).
# Plans with the A* expert on maze2d-large for the quadruped and writes runs/plan.png + plan.json.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/venv.sh"
cd "$ROOT"
ecahd plan --map maze2d-large --robot quadruped --method astar \
    --png runs/plan.png --json runs/plan.json "$@"
