#!/bin/bash
cd /tmp/s21
for S in 2034 2035; do
  CODE=/tmp/s21/base ./bench.sh base_o2 /work/main/docs/results/models /tmp/s19/office2.yaml $S "circle quadruped humanoid"
  CODE=/tmp/s21/ff ./bench.sh ff_o2 /tmp/s21/m_ff /tmp/s19/office2.yaml $S "circle quadruped humanoid"
done
