#!/bin/bash
# dev counts on office 2 (seeds 2026-2027): shipped SD vs the local-pairs SD (meta spacing 4.06 and patched to 6.72), band code; humanoid main too
cd /tmp/s25
while pgrep -f "train sd" >/dev/null; do sleep 10; done
/work/main/.venv/bin/python - <<'PY'
import torch, shutil, os
ck = torch.load('loc/models/office2_sd.pt', map_location='cpu', weights_only=False)
print('local meta', ck['meta'])
ck['meta']['expert_spacing'] = 6.7196
os.makedirs('loc/models67', exist_ok=True)
torch.save(ck, 'loc/models67/office2_sd.pt'); shutil.copy('loc/models/office2_dd.pt', 'loc/models67/office2_dd.pt')
PY
run() { # TAG CODE MODELS SEED ROBOT
  ECAHD_MODELS=$3 PYTHONPATH=/tmp/s25/code_$2:/tmp/s25 /work/main/.venv/bin/python count7.py maps/office2.yaml $4 32 $5 dev_$1_$4_$5.npz > dev_$1_$4_$5.log 2>&1; }
for S in 2026 2027; do
  run main main /work/main/docs/results/models $S humanoid & run band band /work/main/docs/results/models $S humanoid; wait
  for r in circle quadruped humanoid; do
    run loc4 band /tmp/s25/loc/models $S $r & run loc67 band /tmp/s25/loc/models67 $S $r; wait
  done
  run band band /work/main/docs/results/models $S circle & run band band /work/main/docs/results/models $S quadruped; wait
done
echo DEVDONE
