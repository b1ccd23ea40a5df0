#!/bin/bash
# session 27: the settle rule on offices 1-3 x 3 robots, seed 2044 (spent: development),
# against session 26's runs of main's code on it (/tmp/s26/held/res/new_*); 2 benches at a time
cd /tmp/s27/dev
M=/work/main/docs/results/models
job() { # arm map robot seed
  PYTHONPATH=/tmp/s27/dev/code_$1 ECAHD_MODELS=$M /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map /tmp/s25/maps/$2.yaml --problems 32 --seed $4 --robots $3 --methods hd --no-ablation --precision auto --guidance on --md res/$1_$2_$3_s$4.md --json res/$1_$2_$3_s$4.json --no-progress > res/$1_$2_$3_s$4.log 2>&1
  echo "$1 $2 $3 s$4 rc=$? $(date -u +%H:%M:%S)" >> dev.out
}
job settle office1 circle 2044 & job settle office1 humanoid 2044; wait
job settle office1 quadruped 2044 & job settle office2 circle 2044; wait
job settle office2 humanoid 2044 & job settle office2 quadruped 2044; wait
job settle office3 circle 2044 & job settle office3 humanoid 2044; wait
job settle office3 quadruped 2044; wait
echo ALLDONE >> dev.out
