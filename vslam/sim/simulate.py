"""`simulate(config, out_dir)`: a complete downward-camera sequence over a procedural floor.

Writes the sequence directory format (camera.yaml, frames.csv, odometry.csv, imu.csv, groundtruth.txt) plus
sim.yaml with the configuration that produced it. Deterministic for a given seed.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
import yaml

from odometry.shared.camera import CameraModel
from odometry.shared.config import Config, setting
from odometry.shared.tum import se2_to_tum
from vslam.io.sequence_dir import SequenceWriter
from vslam.sequence import GyroStream, Trajectory, WheelOdometry
from vslam.sim.floor import Floor, FloorType
from vslam.sim.randomness import keyed_rng
from vslam.sim.render import Effects, FrameRenderer, image_motion
from vslam.sim.sensors import SensorNoise, gyro_measurements, wheel_measurements
from vslam.sim.trajectory import TrajectoryKind, curvature_profile, drive, lanes_controls

_P_TRAJ, _P_SENS, _P_FRAME, _P_WOBBLE = 101, 102, 103, 104


@dataclass(frozen=True)
class SimConfig(Config):
    """Everything that defines a simulated sequence. Defaults: ~400 frames, 640x480, carpet, a 10 m closed loop."""

    floor: FloorType = FloorType.CARPET
    trajectory: TrajectoryKind = TrajectoryKind.LOOP
    length: float = setting(10.0, range="(0, inf)", unit="m", doc="path length")
    speed: float = setting(0.5, range="(0, inf)", unit="m/s", doc="nominal")
    fps: float = setting(20.0, range="(0, inf)", unit="Hz")
    width: int = setting(640, range="[1, inf)", unit="px")
    height: int = setting(480, range="[1, inf)", unit="px")
    focal: float = setting(500.0, range="(0, inf)", unit="px", doc="fx = fy")
    camera_height: float = setting(0.5, range="(0, inf)", unit="m")
    distortion: tuple[float, float, float, float, float] = (-0.04, 0.01, 0.0, 0.0, 0.0)
    turn_radius: float = setting(1.0, range="(0, inf)", unit="m")
    laps: int = setting(1, range="[1, inf)")
    sensor_rate: float = setting(100.0, range="(0, inf)", unit="Hz", doc="wheel odometry and gyro")
    seed: int = setting(0, range="[0, inf)")
    gray: bool = True
    image_format: str = setting("jpg", choices=("jpg", "png"))
    jpeg_quality: int = setting(95, range="[0, 100]")
    effects: Effects = field(default_factory=Effects)
    sensor_noise: SensorNoise = field(default_factory=SensorNoise)
    max_frames: int | None = setting(None, range="[1, inf)")
    # aerial-like scenes: a camera at 40 m over a floor made of ground-texture photographs at their physical size
    # would see a grey blur; the scene is magnified instead, so that one texture pixel still covers about one
    # image pixel (`scene_scale` = camera_height / 0.5 keeps the 0.5 m look at any height)
    scene_scale: float = setting(1.0, range="(0, inf)",
                                 doc="floor size relative to its photographs (the view at camera_height / scale)")
    lanes: int = setting(3, range="[1, inf)", doc="trajectory lanes: number of lanes")
    lane_spacing: float | None = setting(None, range="(0, inf)", unit="m",
                                         doc="trajectory lanes: between lanes (default 2/3 of the footprint width)")

    def camera(self) -> CameraModel:
        return CameraModel(width=self.width, height=self.height, fx=self.focal, fy=self.focal,
                           cx=(self.width - 1) / 2, cy=(self.height - 1) / 2, distortion=tuple(self.distortion),
                           camera_height=self.camera_height)


@dataclass(frozen=True)
class SimResult:
    path: Path
    frames: int
    dropped: int
    corrupt: int
    seconds: float
    path_length: float

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else float("inf")


def length_for_frames(frames: int, fps: float, speed: float, accel: float = 0.5, pauses: float = 1.0) -> float:
    """Path length whose run lasts about `frames` frames (cruise at `speed`, ramps at `accel`, rests at both ends)."""
    cruise = frames / fps - pauses - speed / accel
    return max(0.2, cruise * speed + speed * speed / accel * 0.5)


def plan_motion(cfg: SimConfig):
    """The controls (and exact poses) of the run."""
    if TrajectoryKind(cfg.trajectory) == TrajectoryKind.LANES:
        across = cfg.height * cfg.camera_height / cfg.focal   # footprint across the lanes (image rows)
        spacing = cfg.lane_spacing if cfg.lane_spacing is not None else 2.0 / 3.0 * across
        return lanes_controls(cfg.length, spacing, cfg.lanes, cfg.speed, cfg.sensor_rate)
    ds = 0.002
    rng = keyed_rng(cfg.seed, _P_TRAJ)
    kappa = curvature_profile(cfg.trajectory, cfg.length, ds, rng, turn_radius=cfg.turn_radius)
    if cfg.laps > 1:
        kappa = np.tile(kappa, cfg.laps)
    return drive(kappa, ds, cfg.speed, cfg.sensor_rate, rng=rng)


def simulate(cfg: SimConfig, out_dir: str | Path, overwrite: bool = False,
             progress: Callable[[int, int], None] | None = None) -> SimResult:
    t_start = time.perf_counter()
    camera = cfg.camera()
    controls = plan_motion(cfg)
    sens_rng = keyed_rng(cfg.seed, _P_SENS)
    wt, wv, ww = wheel_measurements(controls.t, controls.v, controls.omega, cfg.sensor_noise, sens_rng)
    gt_, gz = gyro_measurements(controls.t, controls.omega, cfg.sensor_noise, sens_rng)

    duration = float(controls.t[-1])
    n_frames = int(math.floor(duration * cfg.fps)) + 1
    if cfg.max_frames is not None:
        n_frames = min(n_frames, cfg.max_frames)
    frame_t = np.arange(n_frames) / cfg.fps
    poses = controls.pose_at(frame_t)
    k = cfg.scene_scale
    # the renderer sees the scene shrunk by k: camera height / k over the floor at its photographs' size
    view_cam = camera if k == 1.0 else replace(camera, camera_height=camera.camera_height / k)
    floor = Floor(cfg.floor, seed=cfg.seed, resolution=view_cam.ground_resolution(), gray=cfg.gray)
    renderer = FrameRenderer(floor, view_cam, cfg.effects, seed=cfg.seed)
    gain = 1.0
    run_left = 0
    fx = cfg.effects
    wob = keyed_rng(cfg.seed, _P_WOBBLE)
    ph = wob.uniform(0, 2 * math.pi, 4)
    ext = "." + cfg.image_format.lower().lstrip(".")
    kept_t, kept_pose = [], []
    dropped = corrupt = 0
    with SequenceWriter(out_dir, camera, image_ext=ext, overwrite=overwrite, jpeg_quality=cfg.jpeg_quality) as w:
        for i, (t, pose) in enumerate(zip(frame_t, poses)):
            frng = keyed_rng(cfg.seed, _P_FRAME, i)
            if run_left > 0 and i < n_frames - 1:
                run_left -= 1
                dropped += 1
                continue
            if fx.dropped_frames > 0 and 0 < i < n_frames - 1 and frng.random() < fx.dropped_frames:
                dropped += 1
                run_left = fx.dropped_run - 1   # a run of dropped frames (a stalled link, a full buffer)
                continue
            small = pose if k == 1.0 else np.array([pose[0] / k, pose[1] / k, pose[2]])
            blur = None
            if fx.motion_blur:
                a, b = controls.pose_at(np.array([t - fx.exposure / 2, t + fx.exposure / 2]))
                blur = image_motion(camera, a, b)
            height, tilt = view_cam.camera_height, (0.0, 0.0)
            if fx.wobble:
                height = height + fx.height_wobble * math.sin(2 * math.pi * 0.37 * t + ph[0])
                tilt = (fx.tilt_wobble * math.sin(2 * math.pi * 0.53 * t + ph[1]),
                        fx.tilt_wobble * math.sin(2 * math.pi * 0.29 * t + ph[2]))
            img = renderer.render(small, float(t), blur_px=blur, height=height, tilt=tilt, rng=frng)
            if fx.exposure_jumps > 0 and i > 0 and frng.random() < fx.exposure_jumps:
                # auto-exposure stepping: the whole image brighter or darker from this frame on
                gain = float(np.clip(gain * math.exp(frng.uniform(-1, 1) * fx.exposure_jump_size), 0.3, 3.0))
            if gain != 1.0:
                img = np.clip(img.astype(np.float32) * gain + 0.5, 0, 255).astype(np.uint8)
            if fx.corrupt_frames > 0 and 0 < i < n_frames - 1 and frng.random() < fx.corrupt_frames:
                # a truncated file with garbage: what a failing SD card or transfer leaves behind
                junk = frng.integers(0, 256, 2048, dtype=np.uint8).tobytes()
                w.add_frame(float(t), raw_bytes=junk)
                corrupt += 1
            else:
                w.add_frame(float(t), img)
            kept_t.append(float(t))
            kept_pose.append(pose)
            if progress is not None:
                progress(i + 1, n_frames)
        kept_pose_arr = np.asarray(kept_pose)
        # sensor streams end with the last frame
        last = frame_t[-1] + 1e-9
        wk, gk = wt <= last, gt_ <= last
        wt, wv, ww, gt_, gz = wt[wk], wv[wk], ww[wk], gt_[gk], gz[gk]
        gt = Trajectory(np.asarray(kept_t), se2_to_tum(kept_pose_arr))
        sim_yaml = "# configuration that produced this sequence (vslam simulate)\n" + yaml.safe_dump(cfg.to_dict(),
                                                                                                    sort_keys=False)
        path = w.close(odometry=WheelOdometry(wt, wv, ww), imu=GyroStream(gt_, gz), groundtruth=gt,
                       extra_files={"sim.yaml": sim_yaml})
    travelled = controls.pose_at(np.linspace(0.0, frame_t[-1], max(2, int(frame_t[-1] * cfg.sensor_rate) + 1)))
    length = float(np.sum(np.hypot(*np.diff(travelled[:, :2], axis=0).T)))
    return SimResult(path=path, frames=len(kept_t), dropped=dropped, corrupt=corrupt,
                     seconds=time.perf_counter() - t_start, path_length=length)
