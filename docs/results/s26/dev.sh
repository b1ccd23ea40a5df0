#!/bin/bash
# development counts of the subgoal rule (code_geo), seeds 2042 (spent by the spacing run)
cd /tmp/s26/diag
run() { SUBVIS=$1 ECAHD_MODELS=/work/main/docs/results/models PYTHONPATH=/tmp/s26/code_geo:/tmp/s26/diag /work/main/.venv/bin/python count8.py /tmp/s25/maps/$2.yaml 2042 32 $3 dev_v$1_$2_$3.npz > dev_v$1_$2_$3.log 2>&1; echo "v$1 $2 $3 $(date -u +%H:%M)" >> dev.out; }
run 0 office1 circle & run 1 office1 circle; wait
run 0 office2 humanoid & run 1 office2 humanoid; wait
run 0 office3 humanoid & run 1 office3 humanoid; wait
echo DEVDONE >> dev.out
