#!/bin/bash
# held-out: seeds 2030 2031, R0 (before) and F (relocation), W1-3; then W2 dev seeds with F
for w in 1 2 3; do
  M=/tmp/s19/m_warehouse$w; [ $w = 2 ] && M=/tmp/s19/mW2
  for S in 2030 2031; do for v in R0 F; do
    CODE=/tmp/s19/c$v ./bench.sh hw$w$v $M /tmp/s19/warehouse$w.yaml $S "circle quadruped humanoid"
  done; done
done
for S in 2026 2027; do CODE=/tmp/s19/cF ./bench.sh w2F /tmp/s19/mW2 /tmp/s19/warehouse2.yaml $S "circle quadruped humanoid"; done
