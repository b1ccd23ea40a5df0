#!/usr/bin/env bash
# The main job, on a fresh machine or not: `bash scripts/demo.sh` (extra args go to `ecahd demo`).
# Runs the ROS 2 graph in one process (PyBullet sim_bridge, global_planner with the shipped
# Sparse Diffusion model, local_refiner with guided Dense Diffusion, bag_recorder) through three
# seeded goals in maze2d-large, records an MCAP bag, scores it like the paper's Table III and
# draws the driven paths: everything lands in runs/demo-<date>-<time>/.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/venv.sh"
cd "$ROOT"
ecahd demo "$@"
