#!/bin/bash
# session 22: backtracking (working tree copy in code_bt): dev counts, then held-out offices 1-3
source /work/main/.venv/bin/activate; cd /tmp/s22
while kill -0 10380 2>/dev/null; do sleep 10; done
echo "=== dev start $(date -u +%H:%M:%S)"
export ECAHD_MODELS=/work/main/docs/results/models
(for r in humanoid circle quadruped; do PYTHONPATH=/tmp/s22/code_bt python count6.py /tmp/s19/office2.yaml 2026 32 $r; done > bt_2026.log 2>&1) &
(for r in humanoid circle quadruped; do PYTHONPATH=/tmp/s22/code_bt python count6.py /tmp/s19/office2.yaml 2027 32 $r; done > bt_2027.log 2>&1) &
wait
echo "=== dev end $(date -u +%H:%M:%S)"
for m in office2 office1 office3; do for S in 2034 2035; do
  CODE=/tmp/s22/code_bt ./bench.sh bt_${m} /work/main/docs/results/models /tmp/s19/$m.yaml $S "circle quadruped humanoid"
done; done
echo ALLDONE
