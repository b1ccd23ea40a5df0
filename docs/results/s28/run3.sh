#!/bin/bash
# session 28: route_sight (3d74e73) on the same held-out seed 2048 problems, paired with run2's
# main-1571b84 arm: depots and warehouses one bench at a time (quiet), offices two at a time
cd /tmp/s28/held
until grep -q ALLDONE held.out 2>/dev/null; do sleep 10; done
CODE=/tmp/s28/held/code2
job() { # models map-yaml robot seed dir
  n=$(basename $2 .yaml)
  PYTHONPATH=$CODE ECAHD_MODELS=$1 /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map $2 --problems 32 --seed $4 --robots $3 --methods hd --no-ablation --precision auto --guidance on --per-problem-seeds --md $5/${n}_$3_s$4.md --json $5/${n}_$3_s$4.json --no-progress > $5/${n}_$3_s$4.log 2>&1
  echo "new $n $3 s$4 rc=$? $(date -u +%H:%M:%S)" >> held3.out
}
for r in circle quadruped humanoid; do
  job /tmp/s28/depot/models /tmp/s28/depot/depot1.yaml $r 2048 new_quiet
  job /tmp/s27/depot/models /tmp/s27/depot/depot2.yaml $r 2048 new_quiet
  job /tmp/s28/depot/models /tmp/s28/depot/depot3.yaml $r 2048 new_quiet
done
M=/work/main/docs/results/models
for w in warehouse1 warehouse2 warehouse3; do for r in circle quadruped humanoid; do
  job $M /tmp/s25/maps/$w.yaml $r 2048 new_quiet
done; done
job $M /tmp/s25/maps/office2.yaml circle 2048 new_res & job $M /tmp/s25/maps/office2.yaml humanoid 2048 new_res; wait
job $M /tmp/s25/maps/office1.yaml circle 2048 new_res & job $M /tmp/s25/maps/office1.yaml humanoid 2048 new_res; wait
job $M /tmp/s25/maps/office3.yaml circle 2048 new_res & job $M /tmp/s25/maps/office3.yaml humanoid 2048 new_res; wait
job $M /tmp/s25/maps/office1.yaml quadruped 2048 new_res & job $M /tmp/s25/maps/office2.yaml quadruped 2048 new_res; wait
job $M /tmp/s25/maps/office3.yaml quadruped 2048 new_res
echo ALLDONE >> held3.out
