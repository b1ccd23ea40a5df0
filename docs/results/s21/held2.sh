#!/bin/bash
# after office 3's training: offices 1-3 with the final code (6f0d59c) and Fourier-feature models
cd /tmp/s21
cp /tmp/s21/m_office3/*.pt /tmp/s21/mf/
for m in office1 office3 office2; do for S in 2034 2035; do
  CODE=/tmp/s21/final ./bench.sh fin_${m} /tmp/s21/mf /tmp/s19/$m.yaml $S "circle quadruped humanoid"
done; done
