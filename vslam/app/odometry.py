"""Downward visual odometry over a sequence, with its files (`vslam odometry`).

Writes OUT/trajectory_vo.txt (TUM, one pose per input frame at the same timestamps, the first at the origin),
OUT/odometry.csv (per-frame motion, covariance, inliers, status) and, when the sequence has wheel odometry,
OUT/trajectory_fused.txt (the wheel/gyro EKF used as the VO's prediction and fallback).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import yaml

from odometry.fusion import FusedTrajectory, FusionConfig, fuse_wheel_gyro
from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.poses import between
from odometry.shared.tum import write_tum
from odometry.vo import VOConfig, VOStatus, VOTrajectory, run_visual_odometry
from vslam.app.outdir import ODOMETRY_OUTPUTS, prepare_out_dir
from vslam.errors import VslamError
from vslam.io import open_sequence
from vslam.io.bad_frames import check_mode, note_bad_frames
from vslam.sequence import Sequence as FrameSequence


def parse_overrides(items: Sequence[str]) -> dict:
    """KEY=VALUE strings (`--set`) -> {key: value}, values parsed as YAML (numbers, booleans, lists)."""
    out = {}
    for item in items:
        if "=" not in item:
            raise VslamError(f"--set {item!r}: expected KEY=VALUE")
        k, v = item.split("=", 1)
        out[k.strip()] = yaml.safe_load(v)
    return out


def fuse_sequence_odometry(seq: FrameSequence, config: FusionConfig | None = None) -> FusedTrajectory:
    """The wheel/gyro EKF (odometry.fusion) of a sequence with wheel odometry, at its frame times."""
    if seq.odometry is None:
        raise VslamError(f"{seq.root or seq.name}: no wheel odometry (odometry.csv) to fuse")
    gyro = seq.imu
    return fuse_wheel_gyro(seq.odometry.timestamps, seq.odometry.v, seq.odometry.omega,
                           None if gyro is None else gyro.timestamps, None if gyro is None else gyro.gyro_z,
                           seq.timestamps, config)


@dataclass(frozen=True)
class OdometryRun:
    """What `run_odometry` measured and wrote."""
    out: Path
    trajectory: VOTrajectory
    end_error_m: float | None       # end-point error against ground truth, when the sequence has it
    path_length_m: float | None
    bad_frames: tuple[dict, ...] = ()   # frames that could not be read (index, file, problem)

    def summary(self) -> str:
        traj = self.trajectory
        n = len(traj.timestamps)
        counts = {s: sum(1 for x in traj.status if x == s) for s in VOStatus}
        vo_ms = float(np.median(traj.vo_seconds[1:]) * 1e3) if n > 1 else 0.0
        msg = (f"{n} frames: {counts[VOStatus.OK]} by vision, {counts[VOStatus.FALLBACK]} fallback, "
               f"{counts[VOStatus.LOST]} lost; {int(traj.is_keyframe.sum())} keyframes; VO step {vo_ms:.2f} ms/frame "
               f"(median); wrote {self.out / 'trajectory_vo.txt'} and {self.out / 'odometry.csv'}")
        if self.bad_frames:
            msg += f"; {len(self.bad_frames)} unreadable frames (flagged in odometry.csv)"
        if self.end_error_m is not None:
            err, dist = self.end_error_m, self.path_length_m
            msg += f"; end-point error {err * 100:.1f} cm over {dist:.1f} m ({err / dist * 100:.2f} %)"
        return msg


def run_odometry(sequence: str | Path, out: str | Path, camera: str | None = None, preset: str = "default",
                 fusion_preset: str = "default", overrides: dict | None = None, fallback: bool = True,
                 progress: Callable[[int, int], None] | None = None, overwrite: bool = False,
                 skip_bad_frames: bool = False) -> OdometryRun:
    """Visual odometry over a sequence (VOConfig `preset` with `overrides`); wheel odometry and gyro, when present
    and `fallback`, are fused and used as the motion prediction and the fallback. progress(done, total) per frame.
    A frames.csv listing a missing image is refused unless `skip_bad_frames`; a frame that cannot be read is a
    failed frame (fallback), warned about, its reason in odometry.csv."""
    seq = open_sequence(sequence, camera=camera, check_images=check_mode(skip_bad_frames))
    noted = note_bad_frames(seq)
    cam = seq.require_camera()
    if not cam.is_downward:
        raise VslamError(f"{sequence}: the camera has no camera_height; visual odometry needs a downward camera")
    config = VOConfig.from_dict(overrides or {}, base=VOConfig.preset(preset))
    out = prepare_out_dir(out, ODOMETRY_OUTPUTS, overwrite)   # non-empty refused unless overwrite
    fused = None
    if seq.odometry is not None and fallback:
        fused = fuse_sequence_odometry(seq, FusionConfig.preset(fusion_preset))
        write_tum(out / "trajectory_fused.txt", seq.timestamps, fused.poses)
    n = len(seq)
    traj = run_visual_odometry(cam, seq.timestamps, lambda i: seq.image(i, gray=True), config,
                               fallback=None if fused is None else (lambda i: fused.relative(i - 1, i)),
                               on_frame=None if progress is None else (lambda est: progress(est.index + 1, n)))
    write_tum(out / "trajectory_vo.txt", traj.timestamps, traj.poses)
    atomic_write_text(out / "odometry.csv", "\n".join(traj.csv_rows()) + "\n")
    err, dist = _end_point_error(seq, traj.poses)
    return OdometryRun(out, traj, err, dist, tuple(noted.rows()))


def _end_point_error(seq: FrameSequence, poses: np.ndarray) -> tuple[float | None, float | None]:
    """(end-point error, ground-truth path length) in metres, or (None, None) without usable ground truth."""
    gt = seq.groundtruth_planar()
    if gt is None or not np.all(np.isfinite(gt[[0, -1]])):
        return None, None
    g = between(gt[0], gt)
    dist = float(np.sum(np.hypot(*np.diff(g[:, :2][np.all(np.isfinite(g), 1)], axis=0).T)))
    if dist <= 0:
        return None, None
    return float(np.hypot(*(poses[-1, :2] - g[-1, :2]))), dist
