#!/bin/bash
# device run: held-out seeds, offices 1-3, 3 robots, default re-plan spacing vs 4 m; CPU only, 1 thread a job
cd "$(dirname "$0")/.."
export PYTHONUNBUFFERED=1 CUDA_VISIBLE_DEVICES="" ECAHD_MODELS=$PWD/docs/results/models OMP_NUM_THREADS=1 MKL_NUM_THREADS=1
for f in .dev/maps/*.pgm.gz; do gunzip -kf $f; done
R=/tmp/res; mkdir -p $R
(lscpu; nproc; python3 -c "import torch,numpy,sys;print(sys.version,torch.__version__,numpy.__version__)"; python3 -c "from ecahd_core.threads import native_bf16; print('bf16', native_bf16('cpu'))") > $R/machine.txt 2>&1
cat $R/machine.txt | tail -4
(while true; do sleep 15; tar czf $OUT/res.tgz.tmp -C /tmp res && mv $OUT/res.tgz.tmp $OUT/res.tgz; done) > /dev/null 2>&1 &
TARPID=$!
job() { # arm map robot seed
  extra=""; [ $1 = sp4 ] && extra="--replan-spacing 4"
  t0=$(date +%s)
  python3 -m ecahd_ros.cli bench planning --map .dev/maps/$2.yaml --problems 32 --seed $4 --robots $3 --methods hd --no-ablation --precision auto --guidance on --md $R/$1_$2_$3_s$4.md --json $R/$1_$2_$3_s$4.json --no-progress $extra > $R/$1_$2_$3_s$4.log 2>&1
  echo "$1 $2 $3 s$4 rc=$? $(( $(date +%s)-t0 ))s" | tee -a $R/done.txt
}
export -f job; export R
{ for a in sp4 def; do for r in humanoid quadruped circle; do for s in 2042 2043; do for m in office1 office2 office3; do echo $a $m $r $s; done; done; done; done; } | xargs -P ${P:-16} -L1 bash -c 'job $0 $1 $2 $3'
tar czf $OUT/res.tgz.tmp -C /tmp res && mv $OUT/res.tgz.tmp $OUT/res.tgz
kill $TARPID; echo ALLDONE
