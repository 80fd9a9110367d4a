"""Shared helpers for benchmarks: repeated timing with medians, tables, JSON output.

The machine is shared and noisy: time many repetitions and report medians; compare against a baseline
measured in the same run rather than against absolute numbers.
"""
from __future__ import annotations

import json
import platform
import statistics
import time
from pathlib import Path
from typing import Any, Callable, Sequence

from odometry.shared.atomic_io import atomic_write_text


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
    return float(statistics.median(xs)) if len(xs) else float("nan")


def machine_info() -> dict:
    import os

    import cv2
    import numpy as np

    return {"python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
            "cpus": os.cpu_count(), "machine": platform.machine(), "processor": platform.processor()}


def format_table(headers: Sequence[str], rows: Sequence[Sequence[Any]], floatfmt: str = ".3g") -> str:
    """A GitHub-flavoured markdown table (also readable in a terminal)."""
    def cell(v: Any) -> str:
        if isinstance(v, float):
            return format(v, floatfmt)
        return str(v)

    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    lines += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return "\n".join(lines)


def write_json(path: str | Path, payload: dict) -> None:
    payload = {"machine": machine_info(), **payload}
    atomic_write_text(path, json.dumps(payload, indent=2, default=float) + "\n")
