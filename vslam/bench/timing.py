"""Timing for benchmarks: repeated calls and medians.

The machine is shared and noisy: time many repetitions and report medians; compare against a baseline measured in
the same run rather than against absolute numbers.
"""
from __future__ import annotations

import statistics
import time
from typing import Any, Callable, Sequence


def time_calls(fn: Callable[[], Any], repeat: int = 20, warmup: int = 2) -> list[float]:
    """Seconds per call for `repeat` calls after `warmup` untimed ones."""
    for _ in range(warmup):
        fn()
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def median(xs: Sequence[float]) -> float:
    """The median, NaN for no values."""
    return float(statistics.median(xs)) if len(xs) else float("nan")
