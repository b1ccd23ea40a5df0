#!/bin/bash
# held-out seeds 2032 2033 (never used before this): warehouses base vs new (3 robots), offices new (3 robots), office 2 base
cd /tmp/s20
M=/work/main/docs/results/models
for S in 2032 2033; do
  for w in 1 2 3; do
    for v in new base; do CODE=/tmp/s20/$v ./bench.sh hw${w}_$v $M /tmp/s19/warehouse$w.yaml $S "circle quadruped humanoid"; done
  done
done
for S in 2032 2033; do
  CODE=/tmp/s20/new ./bench.sh ho2_new $M /tmp/s19/office2.yaml $S "circle quadruped humanoid"
  CODE=/tmp/s20/base ./bench.sh ho2_base $M /tmp/s19/office2.yaml $S circle
  CODE=/tmp/s20/new ./bench.sh ho3_new /tmp/s19/m_office3 /tmp/s19/office3.yaml $S "circle quadruped humanoid"
  CODE=/tmp/s20/new ./bench.sh ho1_new /tmp/s19/m_office1 /tmp/s19/office1.yaml $S "circle quadruped humanoid"
done
