"""What a benchmark hands back and writes: its exit code, its tables for docs/benchmarks.md, and a JSON file that
records the machine it ran on."""
from __future__ import annotations

import json
import os
import platform
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from odometry.shared.atomic_io import atomic_write_text


@dataclass(frozen=True)
class BenchResult:
    """A finished benchmark: `markdown` holds the tables for its section of docs/benchmarks.md (None: nothing to
    publish, e.g. a helper process or a study that is not a documented table)."""
    markdown: str | None = None
    exit_code: int = 0


def machine_info() -> dict:
    """Versions and CPU of this machine, stored with every result."""
    return {"python": platform.python_version(), "numpy": np.__version__, "opencv": cv2.__version__,
            "cpus": os.cpu_count(), "machine": platform.machine(), "processor": platform.processor()}


def write_json(path: str | Path, payload: dict) -> None:
    """`payload` with the machine's description in front, as JSON, written atomically."""
    payload = {"machine": machine_info(), **payload}
    atomic_write_text(path, json.dumps(payload, indent=2, default=float) + "\n")
