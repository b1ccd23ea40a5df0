#!/bin/bash
source /work/main/.venv/bin/activate
cd /tmp/s21
for m in ${MAPS:-office1}; do
  echo "=== $m start $(date -u +%H:%M:%S)"
  PYTHONPATH=/tmp/s21/ff python -m ecahd_ros.cli train-all --map /tmp/s19/$m.yaml --minutes 27 --work-dir /tmp/s21/work_$m --out-dir /tmp/s21/m_$m --no-progress > /tmp/s21/train_$m.log 2>&1
  echo "=== $m end $(date -u +%H:%M:%S) rc=$?"
done
