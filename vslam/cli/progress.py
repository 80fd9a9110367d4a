"""Progress of long work on stderr: a tqdm bar on a terminal, a few plain lines in a log file.

A bar redraws itself with carriage returns, which a log file keeps verbatim ("frame 1/18frame 2/18..." on one
line). When stderr is not a terminal the progress is written as whole lines instead, one per quarter of the work
(every `log_interval` seconds when the total is unknown), so a log stays short and readable:

    vslam run: 110/440 frames (25 %), 96.3 frames/s
"""
from __future__ import annotations

import sys
import time


class Progress:
    """update(done, total) per unit of work; close() ends the bar and returns the elapsed seconds.

    enabled: None = on (bar or lines by whether the stream is a terminal), False = silent (--quiet)."""

    def __init__(self, total: int, label: str = "", unit: str = "frames", stream=None, enabled: bool | None = None,
                 log_steps: int = 4, log_interval: float = 10.0):
        self.total = int(total)
        self.label = label
        self.unit = unit
        self.stream = stream or sys.stderr
        self.enabled = enabled is not False
        self.terminal = bool(getattr(self.stream, "isatty", lambda: False)())
        self.log_steps = max(1, int(log_steps))
        self.log_interval = float(log_interval)
        self.t0 = time.perf_counter()
        self.done = 0
        self._bar = None
        self._next_step = 1           # the next quarter (of log_steps) that prints a line
        self._last_line = -1e9

    def _tqdm(self):
        if self._bar is None:
            from tqdm import tqdm  # on first use: `vslam --help` never pays for it

            self._bar = tqdm(total=self.total or None, desc=self.label, unit=f" {self.unit}", file=self.stream,
                             dynamic_ncols=True, leave=True, mininterval=0.25)
        return self._bar

    def update(self, done: int, total: int | None = None) -> None:
        if total is not None:
            self.total = int(total)
        step, self.done = done - self.done, done
        if not self.enabled:
            return
        if self.terminal:
            bar = self._tqdm()
            if self.total and bar.total != self.total:
                bar.total = self.total
            bar.update(step)
            return
        self._log_line(done)

    def _log_line(self, done: int) -> None:
        now = time.perf_counter()
        if self.total:   # one line per quarter crossed (the last at the end)
            if done * self.log_steps < self._next_step * self.total:
                return
            self._next_step = done * self.log_steps // self.total + 1
        elif now - self._last_line < self.log_interval:   # total unknown: one line every log_interval seconds
            return
        self._last_line = now
        rate = done / max(now - self.t0, 1e-9)
        of = f"/{self.total}" if self.total else ""
        pct = f" ({100 * done / self.total:.0f} %)" if self.total else ""
        self.stream.write(f"{self.label}: {done}{of} {self.unit}{pct}, {rate:.1f} {self.unit}/s\n")
        self.stream.flush()

    def close(self) -> float:
        elapsed = time.perf_counter() - self.t0
        if self._bar is not None:
            self._bar.close()
        return elapsed
