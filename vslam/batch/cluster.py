"""The cluster engine: the same per-sequence function submitted to a Dask distributed cluster.

Needs the optional extra (`pip install vslam[cluster]`, i.e. dask[distributed]); vslam itself must be installed on
every worker, and every worker must reach the sequences and the output folder by the same paths as the machine
that submits (a shared filesystem): a task carries paths, not frames.

One task is one sequence. Start workers with `--nthreads 1` so that a worker process holds one sequence at a time
(the pipeline's own threads still run inside it). When a worker dies, the scheduler moves its task to another
worker by itself; the task counts its starts (see `vslam.batch.task`) and gives up after its second. If the
scheduler gives up first (KilledWorker, when its `allowed-failures` is 0) the task is submitted once more here.
"""
from __future__ import annotations

from pathlib import Path

import cv2
from distributed import Client, as_completed

from vslam.batch.errors import BatchError
from vslam.batch.events import EngineEvents, lost_worker_outcome
from vslam.batch.task import SequenceTask, attempts_started, process_sequence


def process_on_one_core(task: SequenceTask) -> dict:
    """`process_sequence` with OpenCV single-threaded: a worker process holds one core (start workers with
    `--nthreads 1`, one per core), and OpenCV's own thread pool in each would oversubscribe the machine."""
    cv2.setNumThreads(1)
    return process_sequence(task)


def connect(scheduler: str) -> Client:
    """A client of the scheduler at `scheduler`: an address (tcp://HOST:PORT, or any Dask address) or the path
    of a scheduler file (`dask scheduler --scheduler-file PATH`)."""
    if "://" in scheduler:
        return Client(scheduler, timeout="30s")
    if Path(scheduler).is_file():
        return Client(scheduler_file=scheduler, timeout="30s")
    if "/" in scheduler or scheduler.endswith((".json", ".yaml")):
        raise BatchError(scheduler, "no such scheduler file (or give the address as tcp://HOST:PORT)")
    # HOST:PORT without a protocol
    return Client(f"tcp://{scheduler}", timeout="30s")


class DaskCluster:
    """Run tasks on the workers of a Dask cluster (a `distributed.Client`, an address or a scheduler file)."""

    def __init__(self, client: Client | str):
        self.own = not isinstance(client, Client)
        self.client = connect(client) if self.own else client

    def close(self) -> None:
        if self.own:
            self.client.close()

    def _submit(self, task: SequenceTask, n: int):
        # pure=False: the same sequence submitted again is new work, not a cached result
        return self.client.submit(process_on_one_core, task, key=f"vslam-batch-{task.run_id}-{task.name}-{n}",
                                  pure=False, retries=0)

    def run(self, tasks: list[SequenceTask], events: EngineEvents) -> None:
        submits: dict[str, int] = {}
        by_future = {}
        for task in tasks:
            submits[task.name] = 1
            by_future[self._submit(task, 1)] = task
            events.started(task.name, 1)
        pending = as_completed(list(by_future))
        for fut in pending:
            task = by_future.pop(fut)
            if fut.status == "finished":
                events.finished(fut.result())
                continue
            reason = repr(fut.exception())
            fut.release()
            # starts the task recorded itself: the scheduler may already have moved it after a lost worker
            started = max(attempts_started(task), submits[task.name])
            if started < task.max_attempts:
                submits[task.name] += 1
                new = self._submit(task, submits[task.name])
                by_future[new] = task
                pending.add(new)
                events.started(task.name, started + 1)
            else:
                events.finished(lost_worker_outcome(task.name, started, reason))
