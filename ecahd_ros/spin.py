"""The one ``main()`` body every node shares (ros2/examples, Jazzy), made robust for a robot:

- **Configuration that fails is visible.** A node constructor that raises (EcahdError: an unknown
  robot, a parameter out of range, an unreadable model) ends the process at once with exit code
  1 and one line on stderr, ``<node>: cannot configure: <reason>``, so ``ros2 launch`` and any
  supervisor (systemd ``Restart=on-failure``, a launch ``respawn``) see the failure. We chose this
  over lifecycle nodes: rclpy's lifecycle API adds a manual configure/activate dance that
  ``ros2 run`` users do not expect, and a node that cannot configure has nothing useful to do.
- **Nothing raised while spinning ends a node.** rclpy re-raises a callback's exception out of
  ``spin_once`` (e.g. its time source given a ``/clock`` with a negative time); :func:`spin_forever`
  logs it (each distinct message at most once per :data:`ERROR_LOG_PERIOD`) and keeps spinning.
  Only Ctrl-C and an external shutdown end the loop.
- **One executor thread.** rclpy's (Jazzy) MultiThreadedExecutor busy-spins its wait loop
  while a mutually exclusive callback group is busy and starves every
  other Python thread of the GIL: measured with ``ecahd bench control``, local_refiner on 3
  executor threads got 58-101 of 300 control ticks in 15 s (gaps of 1-2 s, DD taking 3x its
  time); on one executor thread, with the local stage on its own worker thread, 304 of 300 and
  jitter p99 2.5 ms. So every node spins one executor thread; long work goes to a worker.
- **A short GIL switch interval.** A worker thread running Python code (local_refiner's scan
  fusion and motion tracker) keeps the GIL until CPython's switch interval (5 ms by default)
  forces it to hand over, and the executor thread needs the GIL back several times per control
  tick (every rcl call releases it): each hand-over could delay ``cmd_vel`` by up to 5 ms.
  Nodes set ``sys.setswitchinterval`` to :data:`GIL_SWITCH_INTERVAL`. Measured with the rest of
  that session's changes, the maze2d-large loop's cmd_vel jitter p99 stayed at 15.8 ms (15.5 ms
  before; docs/RESULTS.md): the interval bounds a hand-over's wait, it did not fix the jitter.
"""
from __future__ import annotations

import sys
import time
from collections.abc import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from ecahd_core.errors import EcahdError

ERROR_LOG_PERIOD = 5.0  # [s] the same exception text is logged at most once per period
CONFIGURE_EXIT_CODE = 1  # exit status of a node that cannot configure
GIL_SWITCH_INTERVAL = 0.0005  # [s] sys.setswitchinterval of every node (CPython's default: 5 ms)


def spin_forever(executor, logger, *, period: float = 0.1) -> None:
    """Spin ``executor`` until Ctrl-C or shutdown; log any other exception and go on."""
    last_logged: dict[str, float] = {}
    context = executor.context
    while context.ok():
        try:
            executor.spin_once(timeout_sec=period)
        except (KeyboardInterrupt, ExternalShutdownException):
            return
        except Exception as exc:  # noqa: BLE001 (a robot's node must outlive one bad message)
            text = f"{type(exc).__name__}: {exc}"
            now = time.monotonic()
            if now - last_logged.get(text, -ERROR_LOG_PERIOD) >= ERROR_LOG_PERIOD:
                last_logged[text] = now
                logger.error(f"exception while spinning (ignored, node keeps running): {text}")


DIE_WITH_PARENT_ENV = "ECAHD_DIE_WITH_PARENT"  # set by `ecahd demo` / benchmarks for their nodes


def die_with_parent() -> None:
    """Linux: have the kernel send SIGTERM to this process when its parent dies (prctl
    PR_SET_PDEATHSIG), so nodes that `ecahd demo` or a benchmark started do not outlive a
    killed run (one did, and kept simulating on its ROS domain). No-op elsewhere."""
    import ctypes
    import os
    import signal

    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
    except OSError:
        return
    parent = int(os.environ.get(DIE_WITH_PARENT_ENV, "0") or 0)
    libc.prctl(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG = 1
    if parent and os.getppid() != parent:  # the parent died before the prctl took effect
        os.kill(os.getpid(), signal.SIGTERM)


def spin_node(make_node: Callable[[], Node], args=None, *, name: str = "node") -> None:
    """Create the node after ``rclpy.init`` and spin it until interrupted; ``destroy_node`` runs
    in every case (nodes release their resources, e.g. close a bag, there). A node that cannot
    configure exits with :data:`CONFIGURE_EXIT_CODE` and one line naming the reason. Started by
    `ecahd demo` (``ECAHD_DIE_WITH_PARENT`` set), the node ends with the process that started
    it (:func:`die_with_parent`)."""
    import os

    if os.environ.get(DIE_WITH_PARENT_ENV):
        die_with_parent()
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    rclpy.init(args=args)
    try:
        node = make_node()
    except EcahdError as exc:
        print(f"{name}: cannot configure: {exc}", file=sys.stderr, flush=True)
        rclpy.try_shutdown()
        sys.exit(CONFIGURE_EXIT_CODE)
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        spin_forever(executor, node.get_logger())
    finally:
        executor.remove_node(node)
        node.destroy_node()
        rclpy.try_shutdown()
