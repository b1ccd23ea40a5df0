#!/bin/bash
# control: the shipped office-2 SD with its meta spacing patched to 4.06 m (re-plan spacing as the local-pairs model's)
cd /tmp/s25
run() { ECAHD_MODELS=/tmp/s25/loc/ship4 PYTHONPATH=/tmp/s25/code_band:/tmp/s25 /work/main/.venv/bin/python count7.py maps/office2.yaml $1 32 $2 dev_ship4_$1_$2.npz > dev_ship4_$1_$2.log 2>&1; }
run 2026 circle & run 2027 circle; wait
run 2026 quadruped & run 2027 quadruped; wait
run 2026 humanoid & run 2027 humanoid; wait
echo SHIP4DONE
