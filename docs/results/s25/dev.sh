#!/bin/bash
# dev counts, office 2 seeds 2026-2027, humanoid: main vs band (shipped models)
cd /tmp/s25; export ECAHD_MODELS=/work/main/docs/results/models
for S in 2026 2027; do for c in main band; do
  PYTHONPATH=/tmp/s25/code_$c:/tmp/s25 /work/main/.venv/bin/python count7.py maps/office2.yaml $S 32 humanoid dev_${c}_$S.npz > dev_${c}_$S.log 2>&1
done; done
echo DEVDONE
