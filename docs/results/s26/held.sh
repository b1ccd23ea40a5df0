#!/bin/bash
# session 26: the subgoal rule (code_new) against main 983601a (code_base), held-out seed 2044,
# offices 1-3 x 3 robots, then warehouses 1-3 (humanoid + circle, seed 2044); base and new side
# by side (the same load on both), 1 torch thread each
cd /tmp/s26/held
M=/work/main/docs/results/models
job() { # arm map robot seed
  PYTHONPATH=/tmp/s26/held/code_$1 ECAHD_MODELS=$M /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map /tmp/s25/maps/$2.yaml --problems 32 --seed $4 --robots $3 --methods hd --no-ablation --precision auto --guidance on --md res/$1_$2_$3_s$4.md --json res/$1_$2_$3_s$4.json --no-progress > res/$1_$2_$3_s$4.log 2>&1
  echo "$1 $2 $3 s$4 rc=$? $(date -u +%H:%M:%S)" >> held.out
}
for m in office1 office2 office3; do for r in circle humanoid quadruped; do
  job base $m $r 2044 & job new $m $r 2044; wait
done; done
for m in warehouse1 warehouse2 warehouse3; do for r in humanoid circle; do
  job base $m $r 2044 & job new $m $r 2044; wait
done; done
echo ALLDONE >> held.out
