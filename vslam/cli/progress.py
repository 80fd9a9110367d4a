"""A one-line progress bar with a rate, for long runs on a terminal (quiet when not a TTY unless forced)."""
from __future__ import annotations

import sys
import time


class Progress:
    def __init__(self, total: int, label: str = "", unit: str = "frames", stream=None, enabled: bool | None = None,
                 min_interval: float = 0.25):
        self.total = total
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self.enabled = self.stream.isatty() if enabled is None else enabled
        self.t0 = time.perf_counter()
        self._last = 0.0
        self.min_interval = min_interval
        self.done = 0

    def update(self, done: int, total: int | None = None) -> None:
        self.done = done
        if total is not None:
            self.total = total
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < self.min_interval and done < self.total:
            return
        self._last = now
        rate = done / max(now - self.t0, 1e-9)
        frac = done / self.total if self.total else 1.0
        bar = "#" * int(30 * frac) + "-" * (30 - int(30 * frac))
        eta = (self.total - done) / rate if rate > 0 else 0.0
        self.stream.write(f"\r{self.label} [{bar}] {done}/{self.total} {self.unit}  {rate:6.1f} {self.unit}/s  "
                          f"eta {eta:5.0f} s ")
        self.stream.flush()

    def close(self) -> float:
        elapsed = time.perf_counter() - self.t0
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
        return elapsed
