"""The default engine: a local pool of worker processes, one process per sequence.

Each sequence runs in a fresh child process forked from a server process that has already imported the
toolkit (multiprocessing's "forkserver" with the pipeline preloaded), so a child starts in milliseconds, holds one
sequence and returns all its memory when it exits. A child that dies (killed, out of memory, a crash in native
code) costs only its own sequence, which is started once more; the others go on.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import time
from collections import deque
from multiprocessing.connection import Connection, wait

import cv2

from vslam.batch.events import EngineEvents, lost_worker_outcome
from vslam.batch.task import SequenceTask, process_sequence

PROGRESS_INTERVAL = 0.25   # seconds between a child's progress messages: enough for a bar, little traffic
PRELOAD = ["vslam.batch.warm"]   # the pipeline and what a run imports on first use, once, in the fork server


def default_workers() -> int:
    """The CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:   # not on Linux
        return max(1, os.cpu_count() or 1)


def _context() -> mp.context.BaseContext:
    if "forkserver" in mp.get_all_start_methods():
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        return ctx
    return mp.get_context("spawn")


def _noop() -> None:
    pass


def start_server() -> float:
    """Start the fork server (importing the toolkit into it) now rather than with the first sequence; seconds it
    took, 0 when it was already up. It then serves every pool of this process."""
    t0 = time.perf_counter()
    proc = _context().Process(target=_noop)
    proc.start()
    proc.join()
    return time.perf_counter() - t0


def _child(task: SequenceTask, conn: Connection, threads: int) -> None:
    # a pool of N processes on N cores: OpenCV's own thread pool in every child would oversubscribe the cores
    cv2.setNumThreads(threads)
    last = [0.0]

    def progress(done: int, total: int) -> None:
        now = time.monotonic()
        if now - last[0] >= PROGRESS_INTERVAL or done == total:
            last[0] = now
            conn.send(("progress", done, total))

    conn.send(("result", process_sequence(task, progress=progress)))
    conn.close()


class LocalPool:
    """Run tasks on up to `workers` local processes at a time."""

    def __init__(self, workers: int | None = None):
        self.workers = workers or default_workers()
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")

    def run(self, tasks: list[SequenceTask], events: EngineEvents) -> None:
        ctx = _context()
        pending = deque(tasks)
        starts: dict[str, int] = {}
        running: dict[object, tuple[SequenceTask, mp.Process, Connection]] = {}   # sentinel -> ...
        while pending or running:
            while pending and len(running) < self.workers:
                task = pending.popleft()
                recv, send = ctx.Pipe(duplex=False)
                threads = 1 if self.workers > 1 else -1   # -1: OpenCV's default
                proc = ctx.Process(target=_child, args=(task, send, threads), name=f"vslam-batch-{task.name}",
                                   daemon=True)
                proc.start()
                send.close()   # the child holds the only writing end: EOF when it dies
                starts[task.name] = starts.get(task.name, 0) + 1
                running[proc.sentinel] = (task, proc, recv)
                events.started(task.name, starts[task.name])
            conns = {c: s for s, (_, _, c) in running.items()}
            for ready in wait(list(conns)):
                sentinel = conns[ready]
                task, proc, conn = running[sentinel]
                try:
                    msg = conn.recv()
                except EOFError:
                    msg = None
                if msg is not None and msg[0] == "progress":
                    events.progress(task.name, msg[1], msg[2])
                    continue
                del running[sentinel]
                conn.close()
                proc.join()
                if msg is not None:
                    events.finished(msg[1])
                elif starts[task.name] < task.max_attempts:
                    pending.appendleft(task)   # the retry goes first: its sequence has waited longest
                else:
                    events.finished(lost_worker_outcome(task.name, starts[task.name],
                                                        f"process exit code {proc.exitcode}"))
