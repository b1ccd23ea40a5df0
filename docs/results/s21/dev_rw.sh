source /work/main/.venv/bin/activate; cd /tmp/s21; export ECAHD_MODELS=/tmp/s21/m_ff
(for r in circle humanoid quadruped; do PYTHONPATH=/tmp/s21/rw python ../s20/count3.py /tmp/s19/office2.yaml 2026 32 $r; done > rw_2026.log 2>&1;
 ECAHD_LEG_HALF_WIDTH=1 PYTHONPATH=/tmp/s21/rwhw python ../s20/count3.py /tmp/s19/office2.yaml 2026 32 humanoid > rwhw_2026.log 2>&1) &
(for r in circle humanoid quadruped; do PYTHONPATH=/tmp/s21/rw python ../s20/count3.py /tmp/s19/office2.yaml 2027 32 $r; done > rw_2027.log 2>&1;
 ECAHD_LEG_HALF_WIDTH=1 PYTHONPATH=/tmp/s21/rwhw python ../s20/count3.py /tmp/s19/office2.yaml 2027 32 humanoid > rwhw_2027.log 2>&1) &
wait
