"""Timing shared by the benchmark scripts: medians of repeated calls in one process."""

from __future__ import annotations

import platform
import statistics
import time
from pathlib import Path


def timed_ms(fn, repeat: int, warmup: int = 5) -> dict:
    """Median and best of ``repeat`` calls of ``fn`` (after ``warmup`` untimed calls), in ms."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return {"median": 1e3 * statistics.median(times), "best": 1e3 * min(times)}


def cpu_name() -> str:
    """The processor's model name (from ``/proc/cpuinfo`` where there is one), e.g. ``AMD EPYC 7B13``."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def matmul_gflops(rows: int = 410, inner: int = 256, cols: int = 512, repeat: int = 200) -> float:
    """This CPU's float32 matrix-product rate on one torch thread, in GFLOP/s (median of ``repeat``).

    The default shape ``(410, 256) @ (256, 512)`` is the transformer's feed-forward product for 10 windows
    of 41 frames. Shared cloud VMs of one kind differ by up to about 2x in this rate from day to day, so
    the speed benchmarks report it beside their times.
    """
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        a, b = torch.randn(rows, inner), torch.randn(inner, cols)
        ms = timed_ms(lambda: a @ b, repeat, warmup=20)["median"]
    finally:
        torch.set_num_threads(threads)
    return 2 * rows * inner * cols / (ms * 1e6)
