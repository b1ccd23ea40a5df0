#!/bin/bash
source /work/main/.venv/bin/activate
cd /tmp/s19
for s in "$@"; do
  echo "=== $s start $(date -u +%H:%M:%S)"
  ecahd train-all --map /tmp/s19/$s.yaml --minutes 27 --work-dir /tmp/s19/work_$s --out-dir /tmp/s19/m_$s --no-progress > /tmp/s19/train_$s.log 2>&1
  echo "=== $s end $(date -u +%H:%M:%S) rc=$?"
done
