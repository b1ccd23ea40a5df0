#!/bin/bash
# session 22: office 2 SD from 20000 expert pairs (superset of the 5000), same code, same budget per SD
source /work/main/.venv/bin/activate
cd /tmp/s22
while kill -0 8732 2>/dev/null; do sleep 10; done
echo "=== start $(date -u +%H:%M:%S)"
PYTHONPATH=/tmp/s22/code python -m ecahd_ros.cli train-all --map /tmp/s19/office2.yaml --kinds sd --pairs 20000 --minutes 26.5 --work-dir /tmp/s22/work_p20k --out-dir /tmp/s22/m_p20k --no-progress > /tmp/s22/train_p20k.log 2>&1
echo "=== end $(date -u +%H:%M:%S) rc=$?"
