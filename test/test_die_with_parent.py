"""Nodes that `ecahd demo` starts end with it: a killed benchmark leaves no node behind."""
import os
import signal
import subprocess
import sys
import time

import pytest

CHILD = ("import os, time; from ecahd_ros.spin import die_with_parent; die_with_parent(); "
         "time.sleep(60)")
PARENT = ("import os, subprocess, sys, time; "
          f"p = subprocess.Popen([sys.executable, '-c', {CHILD!r}], "
          "env={**os.environ, 'ECAHD_DIE_WITH_PARENT': str(os.getpid())}); "
          "print(p.pid, flush=True); time.sleep(60)")


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl(PR_SET_PDEATHSIG)")
def test_a_node_process_dies_with_the_process_that_started_it():
    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True)
    child = int(parent.stdout.readline())
    time.sleep(1.0)  # the child has imported and called die_with_parent
    os.kill(child, 0)  # alive while its parent lives
    parent.send_signal(signal.SIGKILL)  # a killed benchmark: no cleanup code runs
    parent.wait()
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            return
        # reaped by init once it exits; a zombie still answers kill(0): check its state
        try:
            with open(f"/proc/{child}/stat") as f:
                if f.read().split()[2] == "Z":
                    return
        except FileNotFoundError:
            return
        time.sleep(0.1)
    os.kill(child, signal.SIGKILL)
    raise AssertionError("the child outlived its parent by 10 s")
