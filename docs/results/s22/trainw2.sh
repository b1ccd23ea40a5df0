#!/bin/bash
# session 22: warehouse 2 SD+DD with the default Fourier features (train-all as a user runs it), then paired held-out benches
source /work/main/.venv/bin/activate
cd /tmp/s22
echo "=== train start $(date -u +%H:%M:%S)"
PYTHONPATH=/tmp/s22/code python -m ecahd_ros.cli train-all --map /tmp/s19/warehouse2.yaml --minutes 27 --work-dir /tmp/s22/work_w2 --out-dir /tmp/s22/m_w2 --no-progress > /tmp/s22/train_w2.log 2>&1
echo "=== train end $(date -u +%H:%M:%S) rc=$?"
for S in 2036 2037; do
  CODE=/tmp/s22/code ./bench.sh ffw2 /tmp/s22/m_w2 /tmp/s19/warehouse2.yaml $S "circle quadruped humanoid"
  CODE=/tmp/s22/code ./bench.sh linw2 /work/main/docs/results/models /tmp/s19/warehouse2.yaml $S "circle quadruped humanoid"
done
echo ALLDONE
