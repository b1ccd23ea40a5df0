"""Torch's thread pools set on purpose (one home for every entry point: nodes, ``ecahd plan``,
benchmarks, training).

Two processes that each let torch use every core oversubscribe a 2-core robot computer badly
(measured before this module: ``ecahd plan`` 0.41 s quiet, 35 s beside a training run). So
inference defaults to 1 thread (:data:`INFERENCE_THREADS`) and training to all cores; both are
flags / parameters. Interop threads are set too, once per process (torch allows it only before
any parallel work), so a second call with another count changes the intra-op pool only.
OpenCV's pool gets the same count (the waypoint placer reads cells with ``cv2.remap`` hundreds
of times a plan: left at every core, its threads woke on each call, 4x the system time).
"""
from __future__ import annotations

import logging
import os
import threading

log = logging.getLogger("ecahd.threads")

INFERENCE_THREADS = 1  # default of nodes, `ecahd plan` and the benchmarks


def training_threads() -> int:
    """The default for training: every core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def set_torch_threads(n: int) -> int:
    """torch.set_num_threads(n) (and interop threads, once) and OpenCV's threads (the waypoint
    placer's ``cv2.remap``, the maps' distance transforms); returns n. n must be >= 1."""
    import cv2
    import torch

    from ecahd_core.errors import EcahdError

    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise EcahdError(f"torch threads must be an integer >= 1, got {n!r}")
    torch.set_num_threads(n)
    cv2.setNumThreads(n)
    try:
        torch.set_num_interop_threads(n)
    except RuntimeError:  # already set, or parallel work already started in this process
        pass
    log.debug("torch threads: %d intra-op, %d interop", torch.get_num_threads(),
              torch.get_num_interop_threads())
    return n


def add_threads_argument(parser, default: int | None = INFERENCE_THREADS) -> None:
    """``--threads N`` on a command (default ``default``; None: all cores, for training)."""
    parser.add_argument("--threads", type=int, default=default,
                        help="torch threads of this process (inference: 1 keeps a busy CPU "
                             "from being oversubscribed; default for training: all cores)")


PRECISIONS = ("fp32", "bf16")  # what the diffusion Transformers compute in
PRECISION_CHOICES = ("auto",) + PRECISIONS  # "auto": bf16 where native_bf16()


def native_bf16(device="cpu") -> bool:
    """Whether ``device`` computes bfloat16 matrix products natively: a CPU with AVX512-BF16 or
    AMX tiles, or a CUDA device that supports bfloat16."""
    import torch

    device = torch.device(device)
    if device.type == "cuda":
        return bool(torch.cuda.is_available() and torch.cuda.is_bf16_supported())
    if device.type != "cpu":
        return False
    checks = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")
    return any(bool(getattr(torch.cpu, name, lambda: False)()) for name in checks)


def resolve_precision(precision: str, device="cpu") -> str:
    """"auto" -> "bf16" where :func:`native_bf16`, else "fp32"; "fp32" / "bf16" unchanged."""
    if precision == "auto":
        return "bf16" if native_bf16(device) else "fp32"
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISION_CHOICES)}, "
                         f"got {precision!r}")
    return precision


def add_precision_argument(parser, default: str, help: str) -> None:
    """``--precision {auto,fp32,bf16}`` on a command."""
    parser.add_argument("--precision", default=default, choices=PRECISION_CHOICES, help=help)


def lower_priority(increment: int) -> int | None:
    """Raise the nice value of the calling thread by ``increment`` (0..19), so that the work
    running there yields the CPU to a node's control timer on a busy computer. On Linux the
    nice value belongs to each thread, and threads started afterwards from this one inherit
    it. Lowering priority needs no privilege; raising it back does, so it is for threads that
    keep the lower priority. Returns the new nice value, or None for 0 or where the system
    refused or has no such call."""
    if isinstance(increment, bool) or not isinstance(increment, int) or not 0 <= increment <= 19:
        from ecahd_core.errors import EcahdError

        raise EcahdError(f"a nice increment must be an integer in 0..19, got {increment!r}")
    if increment == 0:
        return None
    try:
        tid = threading.get_native_id()
        nice = min(19, os.getpriority(os.PRIO_PROCESS, tid) + increment)
        os.setpriority(os.PRIO_PROCESS, tid, nice)
        return nice
    except (AttributeError, OSError) as exc:  # not Linux, or not allowed
        log.debug("nice +%d not applied: %s", increment, exc)
        return None
