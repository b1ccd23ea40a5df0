#!/bin/bash
source /work/main/.venv/bin/activate
cd /tmp/s19
for s in 2 3 1; do
  echo "=== W$s start $(date -u +%H:%M:%S)"
  ecahd train-all --map /tmp/s19/warehouse$s.yaml --minutes 27 --work-dir /tmp/s19/work$s --out-dir /tmp/s19/mW$s --no-progress > /tmp/s19/train_w$s.log 2>&1
  echo "=== W$s end $(date -u +%H:%M:%S) rc=$?"
done
