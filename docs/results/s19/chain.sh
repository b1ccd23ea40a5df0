#!/bin/bash
while ! grep -q "warehouse1 end" /tmp/s19/train2.log; do sleep 5; done
echo "suite start $(date -u +%T)"
(cd /work/main && source .venv/bin/activate && timeout 900 python -m pytest -q -p no:cacheprovider > /tmp/s19/suite.log 2>&1; echo "suite rc=$?")
echo "held start $(date -u +%T)"
./held.sh
echo "office start $(date -u +%T)"
./office.sh
echo "all done $(date -u +%T)"
