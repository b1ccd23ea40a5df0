#!/bin/bash
# session 28: Table III-style closed loop on office 2 with main's code (route_sight), ECAHD and
# A* + controller, 3 episodes, seed 9, alone on the machine after the benches
cd /tmp/s28/nav
until grep -q ALLDONE /tmp/s28/held/held3.out 2>/dev/null; do sleep 10; done
git -C /work/main rev-parse HEAD > commit.txt
date -u +%H:%M:%S > start.txt
cd /work/main && ECAHD_MODELS=docs/results/models .venv/bin/python -m ecahd_ros.cli bench navigation --map /tmp/s25/maps/office2.yaml --episodes 3 --seed 9 --variants ecahd astar --max-steps 3000 --out /tmp/s28/nav/out --md /tmp/s28/nav/nav_office2.md --json /tmp/s28/nav/nav_office2.json --no-progress > /tmp/s28/nav/nav.log 2>&1
echo "rc=$? $(date -u +%H:%M:%S)" >> /tmp/s28/nav/done.txt
