#!/bin/bash
# the default-arm jobs the device run did not return, run here (2 at a time), + one device job as a cross-machine check
cd /work/main
export ECAHD_MODELS=/work/main/docs/results/models
job() { t0=$(date +%s); .venv/bin/python -m ecahd_ros.cli bench planning --map /tmp/s25/maps/$2.yaml --problems 32 --seed $4 --robots $3 --methods hd --no-ablation --precision auto --guidance on --md /tmp/s26/loc/$1_$2_$3_s$4.md --json /tmp/s26/loc/$1_$2_$3_s$4.json --no-progress > /tmp/s26/loc/$1_$2_$3_s$4.log 2>&1; echo "$1 $2 $3 s$4 rc=$? $(( $(date +%s)-t0 ))s $(date -u +%H:%M)" >> /tmp/s26/loc/done.txt; }
export -f job
printf '%s\n' "def office2 quadruped 2042" "def office1 circle 2042" "def office1 circle 2043" "def office2 circle 2042" "def office2 circle 2043" "def office3 circle 2042" "def office3 circle 2043" "def office1 humanoid 2042" "def office1 quadruped 2042" "def office3 quadruped 2043" | xargs -P 2 -L1 bash -c 'job $0 $1 $2 $3'
echo LOCDONE >> /tmp/s26/loc/done.txt
