#!/bin/bash
# session 28, second try (the first ran the benches beside the training: its pgrep wait did not
# match): depots 1 and 3 retrained alone (12 min each), then depots and warehouses one bench at a
# time on the quiet machine, then the offices left, two at a time
cd /tmp/s28/depot
for s in 3 1; do
  /work/main/.venv/bin/python -m ecahd_ros.cli train-all --map depot$s.yaml --minutes 12 --work-dir work --out-dir models > train$s.log 2>&1
  echo "train depot$s rc=$? $(date -u +%H:%M:%S)" >> train.out
done
cd /tmp/s28/held
CODE=/tmp/s28/held/code
job() { # models map-yaml robot seed dir
  n=$(basename $2 .yaml)
  PYTHONPATH=$CODE ECAHD_MODELS=$1 /work/main/.venv/bin/python -m ecahd_ros.cli bench planning --map $2 --problems 32 --seed $4 --robots $3 --methods hd --no-ablation --precision auto --guidance on --per-problem-seeds --md $5/${n}_$3_s$4.md --json $5/${n}_$3_s$4.json --no-progress > $5/${n}_$3_s$4.log 2>&1
  echo "$n $3 s$4 rc=$? $(date -u +%H:%M:%S)" >> held.out
}
for r in circle quadruped humanoid; do
  job /tmp/s28/depot/models /tmp/s28/depot/depot1.yaml $r 2048 quiet
  job /tmp/s27/depot/models /tmp/s27/depot/depot2.yaml $r 2048 quiet
  job /tmp/s28/depot/models /tmp/s28/depot/depot3.yaml $r 2048 quiet
done
M=/work/main/docs/results/models
for w in warehouse1 warehouse2 warehouse3; do for r in circle quadruped humanoid; do
  job $M /tmp/s25/maps/$w.yaml $r 2048 quiet
done; done
job $M /tmp/s25/maps/office3.yaml circle 2048 res & job $M /tmp/s25/maps/office3.yaml quadruped 2048 res; wait
job $M /tmp/s25/maps/office1.yaml humanoid 2048 res & job $M /tmp/s25/maps/office2.yaml humanoid 2048 res; wait
job $M /tmp/s25/maps/office3.yaml humanoid 2048 res
echo ALLDONE >> held.out
