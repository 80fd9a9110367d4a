"""The unit of work of a batch: one sequence through `vslam.app.run.run_sequence` (the function `vslam run`
calls), on whichever process or cluster worker the engine picked.

The run writes into a staging folder OUT/.batch/work/<name>.<run>.<attempt>/ that is moved to OUT/<name>/ only
when it finished: a killed worker leaves no half-written outputs where finished ones are expected, and a failed
redo never removes the outputs of an earlier successful run. Each start appends a line to
OUT/.batch/attempts/<name>.<run>, which counts starts the engine cannot see (a Dask scheduler reschedules the task
of a lost worker by itself): past `max_attempts` starts the task gives up and reports the sequence as failed.
OUT/.batch/running/<name>.json says which host and process runs a sequence while it runs. A finished outcome is
also kept in OUT/.batch/outcomes/<name>.<run>.json: a Dask result lives on its worker until the client fetches it,
so a worker lost just after finishing makes the scheduler run the task again, and the task then hands back the
saved outcome instead of redoing the sequence.

A bad sequence (a `ToolkitError`, an `OSError`) or a bug (any other exception, with its traceback) becomes a
"failed" outcome; only a dead process escapes, and the engine handles that.
"""
from __future__ import annotations

import json
import os
import shutil
import socket
import time
import traceback
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.errors import ToolkitError
from vslam.app.run import run_sequence
from vslam.batch.inputs import BatchItem
from vslam.pipeline import PipelineConfig

STATE_DIR = ".batch"


@dataclass(frozen=True)
class SequenceTask:
    """Everything a worker needs for one sequence; plain data, pickled to pool processes and Dask workers."""
    item: BatchItem
    config: PipelineConfig          # the batch's configuration with the item's overrides applied
    out_root: str                   # OUT: outputs go to OUT/<name>/
    run_id: str                     # this invocation of the batch (names staging folders and attempt files)
    camera: str | None = None
    max_frames: int | None = None
    max_attempts: int = 2           # a sequence whose worker dies is started once more, then reported failed

    @property
    def name(self) -> str:
        return self.item.name


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def state_dir(out_root: str | Path) -> Path:
    return Path(out_root) / STATE_DIR


def attempts_started(task: SequenceTask) -> int:
    """How many times this batch run started the task (lines of its attempt file)."""
    f = state_dir(task.out_root) / "attempts" / f"{task.name}.{task.run_id}"
    try:
        return len(f.read_text().splitlines())
    except FileNotFoundError:
        return 0


def _outcome_file(task: SequenceTask) -> Path:
    return state_dir(task.out_root) / "outcomes" / f"{task.name}.{task.run_id}.json"


def _begin_attempt(task: SequenceTask) -> int:
    d = state_dir(task.out_root) / "attempts"
    d.mkdir(parents=True, exist_ok=True)
    # append, not rewrite: two starts never lose each other's line, even on a shared filesystem
    with open(d / f"{task.name}.{task.run_id}", "a") as f:
        f.write(f"{socket.gethostname()} {os.getpid()} {now_iso()}\n")
    return attempts_started(task)


def _publish(stage: Path, final: Path, trash: Path) -> None:
    """Put a finished staging folder at `final`, replacing an earlier run's outputs only once the new ones exist."""
    if final.exists():
        trash.parent.mkdir(parents=True, exist_ok=True)
        os.replace(final, trash)
    os.replace(stage, final)
    shutil.rmtree(trash, ignore_errors=True)


def _metrics(summary) -> dict:
    s = summary.result.summary()
    row = {"frames": s["frames"], "keyframes": s["keyframes"], "pipeline_seconds": s["wall_seconds"],
           "frames_per_second": s["frames_per_second"], "loops_kept": s["loops_kept"]}
    ev = summary.evaluation or {}
    if "slam" in ev:
        row["ate_slam_m"] = ev["slam"]["ape_m"]["rmse"]
        row["ate_slam_percent"] = ev["slam"]["ape_rmse_percent_of_path"]
    if "vo" in ev:
        row["ate_vo_m"] = ev["vo"]["ape_m"]["rmse"]
    return row


def process_sequence(task: SequenceTask, progress: Callable[[int, int], None] | None = None) -> dict:
    """Run one sequence and return its outcome: name, status ("done" or "failed"), attempt, host, pid, started,
    finished, seconds, cpu_seconds, and the run's metrics (frames, frames/s, loops kept, ATE with ground truth) or its error."""
    saved = _outcome_file(task)
    if saved.is_file():
        return json.loads(saved.read_text())
    base = {"name": task.name, "host": socket.gethostname(), "pid": os.getpid(), "started": now_iso()}
    attempt = _begin_attempt(task)
    base["attempt"] = attempt
    if attempt > task.max_attempts:
        return {**base, "status": "failed", "finished": now_iso(), "seconds": 0.0,
                "error": f"its worker died during each of {task.max_attempts} attempts"}
    state = state_dir(task.out_root)
    running = state / "running" / f"{task.name}.json"
    running.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(running, json.dumps({**base, "run_id": task.run_id}) + "\n")
    stage = state / "work" / f"{task.name}.{task.run_id}.{attempt}"
    shutil.rmtree(stage, ignore_errors=True)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        summary = run_sequence(task.item.sequence, stage, task.config, camera=task.camera,
                               max_frames=task.max_frames, progress=progress)
        _publish(stage, Path(task.out_root) / task.name, state / "trash" / f"{task.name}.{task.run_id}.{attempt}")
        # CPU seconds of the whole process (all its threads): the cost of a sequence whatever else loads the machine
        outcome = {**base, "status": "done", "finished": now_iso(), "seconds": time.perf_counter() - t0,
                   "cpu_seconds": time.process_time() - c0, **_metrics(summary)}
        saved.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(saved, json.dumps(outcome, default=float) + "\n")
        return outcome
    except Exception as exc:   # one sequence's failure is reported, never raised into the engine
        out = {**base, "status": "failed", "finished": now_iso(), "seconds": time.perf_counter() - t0,
               "error": f"{type(exc).__name__}: {exc}"}
        if not isinstance(exc, (ToolkitError, OSError)):
            out["traceback"] = traceback.format_exc()   # a bug, not bad input: keep where it happened
        shutil.rmtree(stage, ignore_errors=True)
        return out
    finally:
        running.unlink(missing_ok=True)
