"""The timing helpers of the benchmarks: best of ``repeat`` runs after a warm-up, wall or CPU time."""

from __future__ import annotations

import time


def best_time(fn, repeat: int) -> float:
    """Seconds of the fastest of ``repeat`` calls of ``fn`` (after one call that compiles/warms)."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def best_cpu(fn, repeat: int) -> float:
    """CPU seconds of this process for the fastest of ``repeat`` calls (after a warm-up): on a
    shared machine, steadier than wall time."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return min(times)
