#!/bin/bash
# usage: CODE=dir bench.sh TAG MODELS MAP SEED "ROBOTS" [extra...]
set -u
TAG=$1; M=$2; MAP=$3; S=$4; R=$5; shift 5
[ -f /tmp/s25/res/${TAG}_s$S.json ] && { echo "$TAG s$S exists"; exit 0; }
source /work/main/.venv/bin/activate
cd /tmp/s25
PYTHONPATH=${CODE:-/work/main} ECAHD_MODELS=$M python -m ecahd_ros.cli bench planning --map $MAP --problems ${N:-32} --seed $S --robots $R --methods hd --no-ablation --precision auto --guidance on --md /tmp/s25/res/${TAG}_s$S.md --json /tmp/s25/res/${TAG}_s$S.json --no-progress "$@" > /tmp/s25/res/${TAG}_s$S.log 2>&1
echo "$TAG s$S rc=$? $(date -u +%H:%M:%S)"
