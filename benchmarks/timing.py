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
