#!/bin/bash
# session 27: the settle rule on a depot (depot2, trained here with train-all --minutes 12),
# held-out seed 2047, paired per problem, 3 robots, settle off then on, one bench at a time
cd /tmp/s27/depot
for r in circle quadruped humanoid; do for a in off on; do
  flag=""; [ "$a" = off ] && flag="--no-settle"
  ECAHD_MODELS=/tmp/s27/depot/models /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map /tmp/s27/depot/depot2.yaml --problems 32 --seed 2047 --robots $r --methods hd --no-ablation --precision auto --guidance on --per-problem-seeds $flag --md res/${a}_depot2_${r}_s2047.md --json res/${a}_depot2_${r}_s2047.json --no-progress > res/${a}_depot2_${r}_s2047.log 2>&1
  echo "$a depot2 $r rc=$? $(date -u +%H:%M:%S)" >> bench.out
done; done
echo ALLDONE >> bench.out
