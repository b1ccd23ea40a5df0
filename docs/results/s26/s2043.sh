#!/bin/bash
# session 26: the subgoal rule (code_new) on seed 2043 (held-out for this rule; the default arm of
# the spacing run is its baseline), offices 1-3 x 3 robots, two at a time
cd /tmp/s26/held
M=/work/main/docs/results/models
job() { PYTHONPATH=/tmp/s26/held/code_new ECAHD_MODELS=$M /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map /tmp/s25/maps/$1.yaml --problems 32 --seed 2043 --robots $2 --methods hd --no-ablation --precision auto --guidance on --md res43/new_$1_$2_s2043.md --json res43/new_$1_$2_s2043.json --no-progress > res43/new_$1_$2_s2043.log 2>&1; echo "new $1 $2 s2043 rc=$? $(date -u +%H:%M:%S)" >> s2043.out; }
export -f job; export M
mkdir -p res43
printf '%s\n' "office1 circle" "office2 circle" "office3 circle" "office1 humanoid" "office2 humanoid" "office3 humanoid" "office1 quadruped" "office2 quadruped" "office3 quadruped" | xargs -P 2 -L1 bash -c 'job $0 $1'
echo ALLDONE >> s2043.out
