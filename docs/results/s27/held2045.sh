#!/bin/bash
# session 27: the settle rule on held-out seed 2045, paired per problem (--per-problem-seeds):
# offices 1-3 x 3 robots, settle off and on side by side (the same load on both), 1 torch thread
# each; then warehouses 1-3 (humanoid + circle) one bench at a time on the quiet machine
cd /tmp/s27/held
M=/work/main/docs/results/models
CODE=/tmp/s27/held/code
job() { # arm map robot seed dir
  flag=""; [ "$1" = off ] && flag="--no-settle"
  PYTHONPATH=$CODE ECAHD_MODELS=$M /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map /tmp/s25/maps/$2.yaml --problems 32 --seed $4 --robots $3 --methods hd --no-ablation --precision auto --guidance on --per-problem-seeds $flag --md $5/$1_$2_$3_s$4.md --json $5/$1_$2_$3_s$4.json --no-progress > $5/$1_$2_$3_s$4.log 2>&1
  echo "$1 $2 $3 s$4 rc=$? $(date -u +%H:%M:%S)" >> held.out
}
for m in office1 office2 office3; do for r in circle humanoid quadruped; do
  job off $m $r 2045 res & job on $m $r 2045 res; wait
done; done
for m in warehouse1 warehouse2 warehouse3; do for r in humanoid circle; do for a in off on; do
  job $a $m $r 2045 quiet
done; done; done
echo ALLDONE >> held.out
