#!/bin/bash
# session 26: warehouse medians, one bench at a time on a quiet machine, main (base) then the
# subgoal rule (new), humanoid and circle, seed 2044
cd /tmp/s26/held
M=/work/main/docs/results/models
for m in warehouse1 warehouse2 warehouse3; do for r in humanoid circle; do for a in base new; do
  PYTHONPATH=/tmp/s26/held/code_$a ECAHD_MODELS=$M /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map /tmp/s25/maps/$m.yaml --problems 32 --seed 2044 --robots $r --methods hd --no-ablation --precision auto --guidance on --md quiet/${a}_${m}_${r}_s2044.md --json quiet/${a}_${m}_${r}_s2044.json --no-progress > quiet/${a}_${m}_${r}_s2044.log 2>&1
  echo "$a $m $r rc=$? $(date -u +%H:%M:%S)" >> quiet.out
done; done; done
echo ALLDONE >> quiet.out
