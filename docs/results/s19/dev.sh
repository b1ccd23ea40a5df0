#!/bin/bash
for S in 2026 2027; do for v in R0 R1 R2; do
CODE=/tmp/s19/c$v ./bench.sh w2$v /tmp/s19/mW2 /tmp/s19/warehouse2.yaml $S "circle quadruped humanoid"
done; done
