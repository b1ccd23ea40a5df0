#!/bin/bash
# session 28: a second held-out seed (2049) on every family with main's code (route_sight):
# depots and warehouses one bench at a time on the quiet machine, offices two at a time
cd /tmp/s28/h49
CODE=/tmp/s28/h49/code
job() { # models map-yaml robot seed dir
  n=$(basename $2 .yaml)
  PYTHONPATH=$CODE ECAHD_MODELS=$1 /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map $2 --problems 32 --seed $4 --robots $3 --methods hd --no-ablation --precision auto --guidance on --per-problem-seeds --md $5/${n}_$3_s$4.md --json $5/${n}_$3_s$4.json --no-progress > $5/${n}_$3_s$4.log 2>&1
  echo "$n $3 s$4 rc=$? $(date -u +%H:%M:%S)" >> h49.out
}
M=/work/main/docs/results/models
for r in circle quadruped humanoid; do for d in depot1 depot2 depot3; do
  job $M /tmp/s28/depot/$d.yaml $r 2049 quiet
done; done
for w in warehouse1 warehouse2 warehouse3; do for r in circle quadruped humanoid; do
  job $M /tmp/s25/maps/$w.yaml $r 2049 quiet
done; done
job $M /tmp/s25/maps/office1.yaml circle 2049 res & job $M /tmp/s25/maps/office1.yaml humanoid 2049 res; wait
job $M /tmp/s25/maps/office2.yaml circle 2049 res & job $M /tmp/s25/maps/office2.yaml humanoid 2049 res; wait
job $M /tmp/s25/maps/office3.yaml circle 2049 res & job $M /tmp/s25/maps/office3.yaml humanoid 2049 res; wait
job $M /tmp/s25/maps/office1.yaml quadruped 2049 res & job $M /tmp/s25/maps/office2.yaml quadruped 2049 res; wait
job $M /tmp/s25/maps/office3.yaml quadruped 2049 res
echo ALLDONE >> h49.out
