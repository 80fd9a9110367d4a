"""The task pool of `vslam bench paper`: named, independent measurements on worker processes (or in this process
with one job), each timed (wall and CPU seconds of the task itself), so the benchmark reports where its time goes."""
from __future__ import annotations

import multiprocessing
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, Callable


def timed_call(fn: Callable, *args) -> tuple[Any, float, float]:
    """fn(*args), its wall seconds and the CPU seconds of the process meanwhile (all its threads)."""
    w0, c0 = time.perf_counter(), time.process_time()
    value = fn(*args)
    return value, time.perf_counter() - w0, time.process_time() - c0


class TaskPool:
    """`submit(name, fn, *args)` -> a Future of fn's value. jobs > 1: a pool of spawned processes (a clean
    interpreter each: no inherited threads or OpenCV state); jobs == 1: the task runs at once, here."""

    def __init__(self, jobs: int, t0: float | None = None):
        self.jobs = max(1, int(jobs))
        self.t0 = time.perf_counter() if t0 is None else t0
        self._pool = (ProcessPoolExecutor(self.jobs, mp_context=multiprocessing.get_context("spawn"))
                      if self.jobs > 1 else None)
        self._times: dict[str, dict] = {}
        self._lock = threading.Lock()

    def __enter__(self) -> TaskPool:
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=exc[0] is None, cancel_futures=exc[0] is not None)

    def submit(self, name: str, fn: Callable, *args, describe: Callable[[Any], str] | None = None) -> Future:
        """Run fn(*args); as it finishes, the log gets its name, times and `describe(value)`."""
        out: Future = Future()

        def done(f: Future) -> None:
            if f.cancelled():          # the pool was shut down (an interrupt, another task's failure)
                out.cancel()
                return
            if f.exception() is not None:
                print(f"[{self._elapsed()}] {name}: FAILED ({f.exception()!r})", flush=True)
                out.set_exception(f.exception())
                return
            value, wall, cpu = f.result()
            with self._lock:
                self._times[name] = {"wall_s": wall, "cpu_s": cpu, "finished_at_s": time.perf_counter() - self.t0}
            note = describe(value) if describe is not None else ""
            print(f"[{self._elapsed()}] {name}: {wall:.0f} s ({cpu:.0f} s CPU)" + (f"; {note}" if note else ""),
                  flush=True)
            out.set_result(value)

        if self._pool is None:
            inner: Future = Future()
            try:
                inner.set_result(timed_call(fn, *args))
            except Exception as exc:   # handed to the caller through the future, as a worker's failure would be
                inner.set_exception(exc)
            done(inner)
        else:
            self._pool.submit(timed_call, fn, *args).add_done_callback(done)
        return out

    def report(self) -> dict[str, dict]:
        """Per task: wall and CPU seconds, and when it finished (seconds since the benchmark started)."""
        with self._lock:
            return dict(self._times)

    def _elapsed(self) -> str:
        s = int(time.perf_counter() - self.t0)
        return f"{s // 60:02d}:{s % 60:02d}"
