"""OUT/batch.json: per sequence its status, the hashes of its inputs and configuration, timings and error.

Written atomically after every change by the process that runs the batch (workers never write it), so a batch
stopped at any point leaves a readable manifest; sequences it shows "running" or "pending" are redone next time.

    {"version": 1, "updated": "...", "sequences": {"<name>": {"status": "done", "sequence": "/abs/path",
     "hash": "...", "input_hash": "...", "input_stat": "...", "config_hash": "...", "attempts": 1,
     "started": "...", "finished": "...", "seconds": 12.3, "frames": 400, "frames_per_second": 41.0,
     "loops_kept": 3, "ate_slam_m": 0.02, "error": null, ...}}}
"""
from __future__ import annotations

import json
from pathlib import Path

from odometry.shared.atomic_io import atomic_write_text
from vslam.batch.errors import BatchError
from vslam.batch.task import now_iso

MANIFEST_FILE = "batch.json"
VERSION = 1
STATUSES = ("pending", "running", "done", "failed")
# fields of a record that belong to one attempt: cleared when a sequence is (re)queued
RESULT_FIELDS = ("started", "finished", "seconds", "cpu_seconds", "frames", "keyframes", "pipeline_seconds", "frames_per_second",
                 "loops_kept", "ate_slam_m", "ate_slam_percent", "ate_vo_m", "error", "traceback", "host", "pid",
                 "attempt")


class Manifest:
    def __init__(self, path: str | Path, sequences: dict[str, dict] | None = None):
        self.path = Path(path)
        self.sequences: dict[str, dict] = sequences or {}

    @classmethod
    def load(cls, out: str | Path) -> "Manifest":
        """OUT/batch.json, or an empty manifest when there is none yet."""
        path = Path(out) / MANIFEST_FILE
        if not path.exists():
            return cls(path)
        try:
            data = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise BatchError(path, f"unreadable batch manifest ({exc}); move it away to start the batch afresh") \
                from None
        if not isinstance(data, dict) or not isinstance(data.get("sequences"), dict):
            raise BatchError(path, "not a batch manifest: expected an object with 'sequences'", field="sequences")
        if data.get("version") != VERSION:
            raise BatchError(path, f"manifest version {data.get('version')!r}, this toolkit writes {VERSION}",
                             field="version")
        for name, rec in data["sequences"].items():
            if not isinstance(rec, dict) or rec.get("status") not in STATUSES:
                raise BatchError(path, f"sequence {name!r}: status must be one of {', '.join(STATUSES)}",
                                 field="status")
        return cls(path, data["sequences"])

    def get(self, name: str) -> dict | None:
        return self.sequences.get(name)

    def queue(self, name: str, fields: dict) -> None:
        """(Re)start a record: identity and hashes from `fields`, status pending, no result of an earlier attempt."""
        rec = {k: v for k, v in self.sequences.get(name, {}).items() if k not in RESULT_FIELDS}
        rec.update(fields, status="pending", attempts=0)
        self.sequences[name] = rec

    def update(self, name: str, **fields) -> None:
        self.sequences.setdefault(name, {}).update(fields)

    def save(self) -> None:
        payload = {"version": VERSION, "updated": now_iso(), "sequences": self.sequences}
        atomic_write_text(self.path, json.dumps(payload, indent=1, default=float) + "\n")
