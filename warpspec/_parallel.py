"""Two launches at once on the CPU backend, which runs each launch on one thread.

A CPU launch releases Python's global interpreter lock while its native code runs, so two
launches made from two threads run on two cores. Only launches that touch disjoint memory, or
that only read what they share, may be paired.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

__all__ = ["cpu_cores", "run_pair"]

_pool: ThreadPoolExecutor | None = None


def cpu_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def run_pair(first: Callable[[], None], second: Callable[[], None]) -> None:
    """Run ``second`` in a worker thread while ``first`` runs here; return when both are done.

    An exception in either is raised here, after both have finished.
    """
    global _pool
    if _pool is None:
        _pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="warpspec")
    future = _pool.submit(second)
    try:
        first()
    finally:
        future.result()


SPLIT_MIN = 32768
"""Fewest threads of a launch worth splitting between two cores (a hand-over costs about as
much as a few thousand nodes of a stencil)."""


def launch_halves(launch: Callable[[int, int, int], None], size: int, device, *,
                  nodes: int | None = None) -> None:
    """Call ``launch(first, count, half)`` over the slots ``0 .. size - 1``, in two on the CPU.

    ``launch`` must launch a kernel over ``count`` slots from ``first`` whose threads write
    only their own slots' outputs and use no atomics (which the CPU backend does not make
    atomic) other than into a buffer of their own ``half`` (0 or 1). On CUDA, on one core,
    below :data:`SPLIT_MIN` nodes (``nodes``, default ``size``) or while a graph is being
    captured it is one call, ``launch(0, size, 0)``.
    """
    work = size if nodes is None else nodes
    if device.is_cuda or work < SPLIT_MIN or device.is_capturing or cpu_cores() < 2:
        launch(0, size, 0)
        return
    half = size // 2
    run_pair(lambda: launch(0, half, 0), lambda: launch(half, size - half, 1))
