"""Loop detection alone (compact descriptors) over any image sequence, with its files (`vslam loops`).

No odometry, ground truth or camera height is needed. A downward camera (camera_height in camera.yaml) uses the
floor geometry check (rotation + translation); anything else the general one (affine). Writes OUT/loops.csv and
OUT/summary.json.

Recent keyframes are excluded by time (`exclude_seconds`) and, when the sequence has odometry (its wheel
odometry, our visual odometry, or a given TUM trajectory) and a downward camera, by footprint: a keyframe is a
candidate only once the camera has left its floor footprint. With odometry, verified candidates must also agree
with the motion between the two keyframes (vslam.pipeline.motion_gate, the gate of the SLAM pipeline too).
`appearance_only` turns both off.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from loops.cdvs import CdvsParams, GeometryModel
from loops.cdvs.database import DatabaseParams
from loops.cdvs.detector import LOOPS_CSV_HEADER, detect_loops
from loops.cdvs.model import LoopModel
from odometry.fusion import FusionConfig
from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.tum import read_tum
from odometry.vo import VOConfig, VOStatus, run_visual_odometry
from vslam.app.odometry import fuse_sequence_odometry
from vslam.app.outdir import LOOPS_OUTPUTS, prepare_out_dir
from vslam.errors import VslamError
from vslam.io import open_sequence
from vslam.io.bad_frames import check_mode
from vslam.pipeline.motion_gate import ChainMotion, MotionGate, MotionGateParams
from vslam.sequence import Sequence, Trajectory

GEOMETRIES = ("auto", "floor", "general")
ODOMETRY_SOURCES = ("auto", "wheel", "vo", "none")   # or the path of a TUM trajectory


@dataclass(frozen=True)
class MotionSource:
    """Odometry of the frames for exclusion and gating: poses (N, 3) per frame index and the relative motion."""
    name: str
    poses: np.ndarray
    relative: Callable[[int, int], tuple[np.ndarray, np.ndarray]]


def _tum_motion(seq: Sequence, path: Path, gate: MotionGateParams) -> MotionSource:
    """A TUM trajectory (e.g. `vslam odometry`'s trajectory_vo.txt), interpolated at the frame times."""
    try:
        traj = Trajectory(*read_tum(path))
    except (OSError, ValueError) as exc:
        raise VslamError(f"{path}: cannot read the odometry trajectory: {exc}") from None
    poses = traj.planar_at(np.asarray(seq.timestamps, float))
    missing = np.flatnonzero(np.isnan(poses[:, 0]))
    if len(missing):
        raise VslamError(f"{path}: field 'timestamp': no pose at frame {int(missing[0])} "
                         f"(t = {float(seq.timestamps[missing[0]]):.6f}, outside the trajectory's time span)")
    return MotionSource(f"tum:{path}", poses, ChainMotion(poses, gate.drift))


def motion_source(seq: Sequence, odometry: str, gate: MotionGateParams) -> MotionSource | None:
    """The odometry named by `odometry` (auto: wheel odometry when the sequence has it, else our visual odometry
    for a downward camera, else none)."""
    downward = seq.camera is not None and seq.camera.camera_height is not None
    if odometry == "none":
        return None
    if odometry not in ODOMETRY_SOURCES:
        return _tum_motion(seq, Path(odometry), gate)
    if odometry == "wheel" or (odometry == "auto" and seq.odometry is not None):
        if seq.odometry is None:
            raise VslamError(f"{seq.root or seq.name}: --odometry wheel: the sequence has no odometry.csv")
        fused = fuse_sequence_odometry(seq, FusionConfig())
        return MotionSource("wheel", fused.poses, fused.relative)
    if not downward:
        if odometry == "vo":
            raise VslamError(f"{seq.root or seq.name}: --odometry vo needs a downward camera (camera_height)")
        return None
    traj = run_visual_odometry(seq.camera, seq.timestamps, lambda i: seq.image(i, gray=True), VOConfig())
    lost = np.array([s == VOStatus.LOST for s in traj.status])   # motion not measured: the gate cannot judge
    return MotionSource("vo", traj.poses, ChainMotion(traj.poses, gate.drift, unknown=lost))


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
                          threshold: float | None = None, every: int = 1, shortlist: int = 5, exclude_recent: int = 0,
                          confirmations: int = 1, geometry: str = "auto", camera: str | None = None,
                          fps: float = 10.0, progress: Callable[[int, int], None] | None = None,
                          exclude_seconds: float = 2.0, odometry: str = "auto", appearance_only: bool = False,
                          gate: MotionGateParams | None = None, overwrite: bool = False,
                          skip_bad_frames: bool = False) -> LoopsRun:
    """Detect loops between every `every`-th frame of a sequence (descriptor `mode`, loop `model` JSON or the
    shipped one; `threshold` overrides the model's). progress(done, total) per keyframe.

    Keyframes taken less than `exclude_seconds` before the query, and the `exclude_recent` last ones, are never
    candidates. `odometry` (auto, wheel, vo, none, or a TUM trajectory file) gives the poses for the footprint
    exclusion and the motion gate; `appearance_only` ignores odometry (time and count exclusion only). A frames.csv
    listing a missing image is refused unless `skip_bad_frames`; unreadable frames are skipped and listed in
    summary.json."""
    if every < 1 or shortlist < 1 or exclude_recent < 0 or confirmations < 1 or exclude_seconds < 0:
        raise VslamError("--every, --shortlist and --confirmations must be >= 1 and --exclude-recent, "
                         "--exclude-seconds >= 0")
    seq = open_sequence(sequence, camera=camera, fps=fps, check_images=check_mode(skip_bad_frames))
    out = prepare_out_dir(out, LOOPS_OUTPUTS, overwrite)   # before any work; non-empty refused unless overwrite
    gate_params = gate or MotionGateParams()
    motion = None if appearance_only else motion_source(seq, odometry, gate_params)
    loop_model = LoopModel.load(model) if model else LoopModel.default()
    downward = seq.camera is not None and seq.camera.camera_height is not None
    geometry_model = {"floor": GeometryModel.SIMILARITY, "general": GeometryModel.AFFINE,
                      "auto": GeometryModel.SIMILARITY if downward else GeometryModel.AFFINE}[geometry]
    params = CdvsParams.floor(mode) if downward else CdvsParams.for_mode(mode)
    params = replace(params, matching=replace(params.matching, geometry=geometry_model))
    dbp = DatabaseParams(shortlist=shortlist, exclude_recent=exclude_recent, confirmations=confirmations,
                         exclude_seconds=exclude_seconds, exclude_unleft=motion is not None)
    footprint = seq.camera if (motion is not None and downward) else None
    gate_fn = MotionGate.for_camera(seq.camera, motion.relative, gate_params) if footprint is not None else None
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
                            on_frame=None if progress is None else (lambda k: progress(k + 1, len(indices))),
                            stamps=np.asarray(seq.timestamps, float), poses=None if motion is None else motion.poses,
                            camera=footprint, gate=gate_fn)
    elapsed = time.perf_counter() - t0
    atomic_write_text(out / "loops.csv", ",".join(LOOPS_CSV_HEADER) + "\n" + "".join(r.csv() + "\n" for r in rows))
    thr = threshold if threshold is not None else loop_model.threshold(mode)
    summary = {"sequence": str(sequence), "mode": mode, "keyframes": st.frames, "skipped_frames": st.skipped,
               "candidates": st.candidates, "accepted": st.accepted,
               "threshold": thr if thr != float("inf") else None, "geometry": geometry_model.value,
               "model": str(model) if model else "default",
               "odometry": "none (appearance only)" if motion is None else motion.name,
               "footprint_exclusion": footprint is not None, "motion_gate": gate_fn is not None,
               "exclude_seconds": exclude_seconds, "exclude_recent": exclude_recent,
               "rejected_by_motion": sum(1 for r in rows if r.candidate.motion_consistent is False),
               "mean_bytes": st.bytes_total / max(st.frames, 1),
               "encode_ms_per_frame": 1e3 * st.encode_seconds / max(st.frames, 1),
               "query_ms_per_frame": 1e3 * st.query_seconds / max(st.frames, 1), "seconds": elapsed,
               "warnings": warnings[:20]}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    return LoopsRun(out, summary, warnings)
