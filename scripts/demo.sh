#!/usr/bin/env bash
# The main job, on a fresh machine or not: `bash scripts/demo.sh` (extra args go to `ecahd plan`).
# Plans with the shipped Sparse Diffusion model (best of 10) on maze2d-large for the quadruped
# and writes runs/plan.png + runs/plan.json (the path, its footprint sweep, collisions in red).
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/venv.sh"
cd "$ROOT"
ecahd plan --map maze2d-large --robot quadruped --method sd \
    --png runs/plan.png --json runs/plan.json "$@"
