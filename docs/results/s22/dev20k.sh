#!/bin/bash
# dev counts, office 2, seeds 2026/2027, 3 robots, SD from 20000 pairs (DD: the shipped office 2 DD)
source /work/main/.venv/bin/activate; cd /tmp/s22
mkdir -p m20k && cp /work/main/docs/results/models/office2_dd.pt m20k/ && cp m_p20k/office2_sd.pt m20k/
export ECAHD_MODELS=/tmp/s22/m20k PYTHONPATH=/tmp/s22/code
python -m ecahd_ros.cli bench sd-quality --map /tmp/s19/office2.yaml --sd m20k/office2_sd.pt --precision auto --json sdq_20k.json > sdq_20k.log 2>&1 &
python -m ecahd_ros.cli bench sd-quality --map /tmp/s19/office2.yaml --sd /work/main/docs/results/models/office2_sd.pt --precision auto --json sdq_5k.json > sdq_5k.log 2>&1
wait
(for r in circle humanoid quadruped; do python count6.py /tmp/s19/office2.yaml 2026 32 $r; done > p20k_2026.log 2>&1) &
(for r in circle humanoid quadruped; do python count6.py /tmp/s19/office2.yaml 2027 32 $r; done > p20k_2027.log 2>&1) &
wait
echo DEVDONE
