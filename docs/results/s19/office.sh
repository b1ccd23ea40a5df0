#!/bin/bash
# office 2: train-all --minutes 27, then R0 / F on held-out seeds 2030 2031 (circle)
./train2.sh office2
for S in 2030 2031; do for v in R0 F; do
  CODE=/tmp/s19/c$v ./bench.sh ho2$v /tmp/s19/m_office2 /tmp/s19/office2.yaml $S circle
done; done
