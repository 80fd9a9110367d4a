"""Loop detection alone (compact descriptors) over any image sequence, with its files (`vslam loops`).

No odometry, ground truth or camera height is needed. A downward camera (camera_height in camera.yaml) uses the
floor geometry check (rotation + translation); anything else the general one (affine). Writes OUT/loops.csv and
OUT/summary.json.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from loops.cdvs import CdvsParams, GeometryModel
from loops.cdvs.database import DatabaseParams
from loops.cdvs.detector import LOOPS_CSV_HEADER, detect_loops
from loops.cdvs.model import LoopModel
from odometry.shared.atomic_io import atomic_write_text
from vslam.app.outdir import LOOPS_OUTPUTS, prepare_out_dir
from vslam.errors import VslamError
from vslam.io import open_sequence
from vslam.io.bad_frames import check_mode

GEOMETRIES = ("auto", "floor", "general")


@dataclass(frozen=True)
class LoopsRun:
    """What `detect_sequence_loops` found and wrote; `summary` is summary.json's content."""
    out: Path
    summary: dict
    warnings: list[str]     # unreadable frames, skipped

    def line(self) -> str:
        s = self.summary
        thr = s["threshold"] if s["threshold"] is not None else float("inf")
        return (f"{s['keyframes']} keyframes, {s['candidates']} verified candidates, {s['accepted']} accepted loops "
                f"(mode {s['mode']}, threshold {thr:.3g}) -> {self.out / 'loops.csv'}")


def detect_sequence_loops(sequence: str | Path, out: str | Path, mode: int = 4, model: str | None = None,
                          threshold: float | None = None, every: int = 1, shortlist: int = 5, exclude_recent: int = 20,
                          confirmations: int = 1, geometry: str = "auto", camera: str | None = None,
                          fps: float = 10.0, progress: Callable[[int, int], None] | None = None,
                          overwrite: bool = False, skip_bad_frames: bool = False) -> LoopsRun:
    """Detect loops between every `every`-th frame of a sequence (descriptor `mode`, loop `model` JSON or the
    shipped one; `threshold` overrides the model's). progress(done, total) per keyframe. A frames.csv listing a
    missing image is refused unless `skip_bad_frames`; unreadable frames are skipped and listed in summary.json."""
    if every < 1 or shortlist < 1 or exclude_recent < 0 or confirmations < 1:
        raise VslamError("--every, --shortlist and --confirmations must be >= 1 and --exclude-recent >= 0")
    seq = open_sequence(sequence, camera=camera, fps=fps, check_images=check_mode(skip_bad_frames))
    out = prepare_out_dir(out, LOOPS_OUTPUTS, overwrite)   # before any work; non-empty refused unless overwrite
    loop_model = LoopModel.load(model) if model else LoopModel.default()
    downward = seq.camera is not None and seq.camera.camera_height is not None
    geometry_model = {"floor": GeometryModel.SIMILARITY, "general": GeometryModel.AFFINE,
                      "auto": GeometryModel.SIMILARITY if downward else GeometryModel.AFFINE}[geometry]
    params = CdvsParams.floor(mode) if downward else CdvsParams.for_mode(mode)
    params = replace(params, matching=replace(params.matching, geometry=geometry_model))
    dbp = DatabaseParams(shortlist=shortlist, exclude_recent=exclude_recent, confirmations=confirmations)
    indices = list(range(0, len(seq), every))
    warnings: list[str] = []

    def frames():
        for i in indices:
            try:
                yield i, seq.image(i, gray=True)
            except (ValueError, OSError) as exc:  # an unreadable frame is skipped, not fatal
                warnings.append(str(exc))
                yield i, None

    t0 = time.perf_counter()
    rows, st = detect_loops(frames(), mode, params, dbp, model=loop_model, threshold=threshold,
                            on_frame=None if progress is None else (lambda k: progress(k + 1, len(indices))))
    elapsed = time.perf_counter() - t0
    atomic_write_text(out / "loops.csv", ",".join(LOOPS_CSV_HEADER) + "\n" + "".join(r.csv() + "\n" for r in rows))
    thr = threshold if threshold is not None else loop_model.threshold(mode)
    summary = {"sequence": str(sequence), "mode": mode, "keyframes": st.frames, "skipped_frames": st.skipped,
               "candidates": st.candidates, "accepted": st.accepted,
               "threshold": thr if thr != float("inf") else None, "geometry": geometry_model.value,
               "model": str(model) if model else "default",
               "mean_bytes": st.bytes_total / max(st.frames, 1),
               "encode_ms_per_frame": 1e3 * st.encode_seconds / max(st.frames, 1),
               "query_ms_per_frame": 1e3 * st.query_seconds / max(st.frames, 1), "seconds": elapsed,
               "warnings": warnings[:20]}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    return LoopsRun(out, summary, warnings)
