#!/bin/bash
# session 22: offices 1-3 held-out, main 777e983, models docs/results/models
cd /tmp/s22
for m in office1 office3 office2; do for S in 2034 2035; do
  CODE=/tmp/s22/code ./bench.sh h_${m} /work/main/docs/results/models /tmp/s19/$m.yaml $S "circle quadruped humanoid"
done; done
echo ALLDONE
