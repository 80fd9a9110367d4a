"""`run_many`: many sequences through the pipeline, each into OUT/<name>/ exactly as `vslam run` writes it, on a
local process pool or a Dask cluster, resumable through OUT/batch.json."""
from __future__ import annotations

import hashlib
import json
import shutil
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

from odometry.shared.errors import ToolkitError
from vslam.batch.errors import BatchError
from vslam.batch.hashing import config_hash, input_hash, stat_fingerprint
from vslam.batch.inputs import BatchItem, resolve_inputs
from vslam.batch.manifest import Manifest
from vslam.batch.pool import LocalPool
from vslam.batch.summary import COLUMNS, BatchSummary
from vslam.batch.task import SequenceTask, now_iso, state_dir
from vslam.pipeline import PipelineConfig


@dataclass
class BatchProgress:
    """What a progress callback sees: sequences finished of `total` (those reused from an earlier run count as
    finished from the start), and frames (done, total) of each running sequence the engine reports on."""
    finished: int
    total: int
    running: dict[str, tuple[int, int]] = field(default_factory=dict)


class _Events:
    """Engine events -> manifest records (saved on every change) and the caller's progress callback."""

    def __init__(self, manifest: Manifest, progress: Callable[[BatchProgress], None] | None, finished: int,
                 total: int):
        self.manifest = manifest
        self.callback = progress
        self.state = BatchProgress(finished, total)

    def _tell(self) -> None:
        if self.callback is not None:
            self.callback(self.state)

    def started(self, name: str, attempt: int) -> None:
        self.manifest.update(name, status="running", attempts=attempt, started=now_iso())
        self.manifest.save()
        self.state.running[name] = (0, 0)
        self._tell()

    def progress(self, name: str, done: int, total: int) -> None:
        self.state.running[name] = (done, total)
        self._tell()

    def finished(self, outcome: dict) -> None:
        name = outcome["name"]
        rec = {k: v for k, v in outcome.items() if k != "name"}
        rec["attempts"] = max(outcome.get("attempt", 1), self.manifest.get(name).get("attempts") or 0)
        rec.setdefault("error", None)
        self.manifest.update(name, **rec)
        self.manifest.save()
        self.state.running.pop(name, None)
        self.state.finished += 1
        self._tell()


def _combined_hash(item: BatchItem, in_hash: str, cfg_hash: str) -> str:
    return hashlib.sha256(f"{item.sequence}\0{in_hash}\0{cfg_hash}".encode()).hexdigest()


def _engine(client, workers: int | None):
    if client is None:
        return LocalPool(workers)
    try:   # on use: dask[distributed] is an optional extra (vslam[cluster]); the local pool needs nothing from it
        from vslam.batch.cluster import DaskCluster
    except ImportError as exc:
        raise BatchError(None, f"a Dask scheduler needs dask[distributed] ({exc}): pip install 'vslam[cluster]'") \
            from None
    return DaskCluster(client)


def _row(item: BatchItem, rec: dict, reused: bool) -> dict:
    row = {k: rec.get(k) for k in COLUMNS}
    row.update(name=item.name, sequence=item.sequence, reused=reused)
    return row


def run_many(paths: Iterable[str | Path] | str | Path, config: PipelineConfig | None = None, client=None, *,
             out: str | Path, workers: int | None = None, retry_failed: bool = False, camera: str | None = None,
             max_frames: int | None = None, max_attempts: int = 2,
             progress: Callable[[BatchProgress], None] | None = None) -> BatchSummary:
    """Run every sequence `paths` name (sequence folders, folders of them, globs, manifest CSVs; see
    `vslam.batch.inputs`) with `config` (each manifest row's overrides applied on top) into OUT/<name>/, and
    return the summary (also written as OUT/summary.csv, .json and .png).

    `client`: None for a local pool of `workers` processes (default: one per CPU), or a `distributed.Client`, a
    scheduler address (tcp://HOST:PORT) or a scheduler file to run on a Dask cluster. A sequence already done with
    the same inputs and configuration (OUT/batch.json) is not run again; one that failed is retried only with
    `retry_failed`. A sequence whose worker dies is started once more (`max_attempts` starts in all).
    """
    t0 = time.perf_counter()
    items = resolve_inputs([str(paths)] if isinstance(paths, (str, Path)) else [str(p) for p in paths])
    config = config or PipelineConfig()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    manifest = Manifest.load(out)
    run_id = f"{time.strftime('%Y%m%dT%H%M%S')}-{uuid.uuid4().hex[:6]}"
    camera = str(Path(camera).resolve()) if camera else None
    options = {"camera": camera, "max_frames": max_frames}
    extra = (camera,) if camera else ()
    tasks, reused = [], set()
    for item in items:
        prev = manifest.get(item.name) or {}
        try:
            cfg = config.with_overrides(item.overrides, source=item.source) if item.overrides else config
        except ToolkitError as exc:   # a bad override fails its row, not the batch
            manifest.queue(item.name, {"sequence": item.sequence, "overrides": list(item.overrides), "hash": None})
            manifest.update(item.name, status="failed", error=f"{type(exc).__name__}: {exc}", finished=now_iso())
            continue
        stat = stat_fingerprint(item.sequence, extra)
        in_hash = prev["input_hash"] if prev.get("input_stat") == stat and prev.get("input_hash") \
            else input_hash(item.sequence, extra)
        cfg_hash = config_hash(cfg.to_dict(), options)
        h = _combined_hash(item, in_hash, cfg_hash)
        if prev.get("hash") == h and (
                (prev["status"] == "done" and (out / item.name).is_dir()) or (prev["status"] == "failed"
                                                                              and not retry_failed)):
            reused.add(item.name)
            continue
        manifest.queue(item.name, {"sequence": item.sequence, "overrides": list(item.overrides), "hash": h,
                                   "input_hash": in_hash, "input_stat": stat, "config_hash": cfg_hash,
                                   "run_id": run_id})
        tasks.append(SequenceTask(item, cfg, str(out.resolve()), run_id, camera, max_frames, max_attempts))
    manifest.save()
    if tasks:
        events = _Events(manifest, progress, len(items) - len(tasks), len(items))
        engine = _engine(client, workers)
        try:
            engine.run(tasks, events)
        finally:
            if hasattr(engine, "close"):
                engine.close()
            _clean_state(out, run_id)
    elif progress is not None:
        progress(BatchProgress(len(items), len(items)))
    rows = [_row(item, manifest.get(item.name), item.name in reused) for item in items]
    summary = BatchSummary(rows, out, wall_seconds=time.perf_counter() - t0)
    summary.write()
    return summary


def _clean_state(out: Path, run_id: str) -> None:
    """Remove this run's staging folders, attempt counters, saved outcomes and trash (needed only while it runs)."""
    state = state_dir(out)
    for sub in ("work", "trash", "attempts", "outcomes"):
        for p in (state / sub).glob(f"*.{run_id}*"):
            shutil.rmtree(p, ignore_errors=True) if p.is_dir() else p.unlink(missing_ok=True)
    for marker in (state / "running").glob("*.json"):   # left behind by a process that was killed
        try:
            stale = json.loads(marker.read_text()).get("run_id") == run_id
        except (OSError, ValueError):
            stale = False
        if stale:
            marker.unlink(missing_ok=True)
