#!/bin/bash
# session 28: closed loop with the humanoid (0.25 x 0.5 m) on office 3, ECAHD and A* + controller,
# 3 episodes, seed 10, alone on the quiet machine
cd /work/main
git rev-parse HEAD > /tmp/s28/nav3/commit.txt
date -u +%H:%M:%S > /tmp/s28/nav3/start.txt
ECAHD_MODELS=docs/results/models .venv/bin/python -m ecahd_ros.cli bench navigation --map /tmp/s25/maps/office3.yaml --robot humanoid --episodes 3 --seed 10 --variants ecahd astar --max-steps 3000 --out /tmp/s28/nav3/out --md /tmp/s28/nav3/nav_office3_humanoid.md --json /tmp/s28/nav3/nav_office3_humanoid.json --no-progress > /tmp/s28/nav3/nav.log 2>&1
echo "rc=$? $(date -u +%H:%M:%S)" >> /tmp/s28/nav3/done.txt
