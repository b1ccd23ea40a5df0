#!/bin/bash
# session 25: the leg band (2565008, code_band) against main (3aca607, code_main), humanoid, held-out seeds 2040-2041
M=/work/main/docs/results/models
for S in 2040 2041; do for m in office2 office1 office3; do
  CODE=/tmp/s25/code_main ./bench.sh main_${m} $M /tmp/s25/maps/$m.yaml $S humanoid
  CODE=/tmp/s25/code_band ./bench.sh band_${m} $M /tmp/s25/maps/$m.yaml $S humanoid
done; done
for m in warehouse1 warehouse2 warehouse3; do
  CODE=/tmp/s25/code_main ./bench.sh main_${m} $M /tmp/s25/maps/$m.yaml 2040 humanoid
  CODE=/tmp/s25/code_band ./bench.sh band_${m} $M /tmp/s25/maps/$m.yaml 2040 humanoid
done
echo ALLDONE
