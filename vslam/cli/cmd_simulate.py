"""`vslam simulate OUT_DIR`: render a downward-camera sequence over a procedural floor."""
from __future__ import annotations

import argparse
from dataclasses import replace

from vslam.cli.progress import Progress
from vslam.errors import VslamError
from vslam.sim import Effects, SensorNoise, SimConfig, simulate
from vslam.sim.floor import FloorType
from vslam.sim.simulate import length_for_frames
from vslam.sim.trajectory import TrajectoryKind

NAME = "simulate"
HELP = "render a simulated downward-camera sequence (images, wheel odometry, gyro, ground truth)"
DESCRIPTION = ("Render a downward-camera sequence over a floor built from real ground-texture photographs. "
               "With no options: ~440 frames at 640x480 over carpet along a 10 m closed loop. Deterministic per seed.")


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = text.lower().split("x")
        return int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x480, got {text!r}") from None


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out_dir", help="output sequence directory (must not exist unless --overwrite)")
    p.add_argument("--floor", default="carpet", choices=[f.value for f in FloorType],
                   help="floor type; printed-wood repeats a few laminate prints on purpose (false-loop worst case)")
    p.add_argument("--trajectory", default="loop", choices=[t.value for t in TrajectoryKind])
    p.add_argument("--length", type=float, default=None,
                   help="path length in metres (default 10, or what --frames needs)")
    p.add_argument("--laps", type=int, default=1, help="drive the closed path this many times")
    p.add_argument("--frames", type=int, default=None,
                   help="number of frames: sizes the path to fit (with --length: stop after this many frames)")
    p.add_argument("--speed", type=float, default=0.5, help="nominal speed m/s (default 0.5)")
    p.add_argument("--fps", type=float, default=20.0, help="camera frame rate (default 20)")
    p.add_argument("--size", type=_size, default=(640, 480), help="image size WxH (default 640x480)")
    p.add_argument("--focal", type=float, default=None, help="focal length in pixels (default 500 at 640 px width)")
    p.add_argument("--camera-height", type=float, default=0.5, help="metres above the floor (default 0.5)")
    p.add_argument("--no-distortion", action="store_true", help="ideal pinhole lens")
    p.add_argument("--turn-radius", type=float, default=1.0)
    p.add_argument("--lanes", type=int, default=3,
                   help="--trajectory lanes: number of parallel lanes flown in alternating directions (default 3)")
    p.add_argument("--lane-spacing", type=float, default=None, metavar="M",
                   help="--trajectory lanes: metres between lanes (default 2/3 of the footprint width)")
    p.add_argument("--scene-scale", type=float, default=None, metavar="K",
                   help="floor size relative to its photographs (default 1: their physical size). Camera height "
                        "/ 0.5 keeps the 0.5 m look at any height: --camera-height 40 --scene-scale 80 is an "
                        "aerial-like scene")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--color", action="store_true", help="colour images (default greyscale, like most floor cameras)")
    p.add_argument("--image-format", default="jpg", choices=["jpg", "png"])
    fx = p.add_argument_group("effects (all on by default except dropped/corrupt frames)")
    fx.add_argument("--no-blur", action="store_true", help="no motion blur")
    fx.add_argument("--no-lighting", action="store_true", help="no illumination changes")
    fx.add_argument("--no-vignetting", action="store_true")
    fx.add_argument("--no-noise", action="store_true", help="no image sensor noise")
    fx.add_argument("--no-wobble", action="store_true", help="no camera height/tilt wobble")
    fx.add_argument("--clean", action="store_true", help="all image effects off")
    fx.add_argument("--dropped-frames", type=float, default=0.0, metavar="P", help="probability a frame is dropped")
    fx.add_argument("--corrupt-frames", type=float, default=0.0, metavar="P",
                    help="probability a frame is written corrupt (undecodable)")
    fx.add_argument("--dropped-run", type=int, default=1, metavar="N",
                    help="frames lost at each drop: runs of N dropped frames (default 1)")
    fx.add_argument("--exposure", type=float, default=0.008, help="exposure time in seconds (motion blur)")
    fx.add_argument("--exposure-jumps", type=float, default=0.0, metavar="P",
                    help="probability per frame of an auto-exposure step (the image brighter or darker from then on)")
    fx.add_argument("--exposure-jump-size", type=float, default=0.5, metavar="S",
                    help="auto-exposure step: log gain uniform in +-S (default 0.5)")
    sn = p.add_argument_group("wheel odometry and gyro")
    sn.add_argument("--sensor-noise", type=float, default=1.0, metavar="K",
                    help="scale every wheel/gyro error (0 = perfect sensors; default 1)")
    p.add_argument("--overwrite", action="store_true", help="replace OUT_DIR if it exists")
    p.add_argument("--quiet", action="store_true")


def config_from_args(a: argparse.Namespace):
    w, h = a.size
    if a.clean:
        effects = Effects.preset("none")
    else:
        effects = Effects(motion_blur=not a.no_blur, lighting=not a.no_lighting, vignetting=not a.no_vignetting,
                          sensor_noise=not a.no_noise, wobble=not a.no_wobble)
    for name, v in (("--dropped-frames", a.dropped_frames), ("--corrupt-frames", a.corrupt_frames),
                    ("--exposure-jumps", a.exposure_jumps)):
        if not 0.0 <= v <= 1.0:
            raise VslamError(f"{name} must be a probability in [0, 1], got {v}")
    if a.dropped_run < 1 or a.lanes < 1:
        raise VslamError("--dropped-run and --lanes must be at least 1")
    if a.exposure_jump_size < 0:
        raise VslamError(f"--exposure-jump-size must be >= 0, got {a.exposure_jump_size}")
    for name, v in (("--lane-spacing", a.lane_spacing), ("--scene-scale", a.scene_scale)):
        if v is not None and v <= 0:
            raise VslamError(f"{name} must be positive, got {v}")
    effects = replace(effects, dropped_frames=a.dropped_frames, corrupt_frames=a.corrupt_frames, exposure=a.exposure,
                      dropped_run=a.dropped_run, exposure_jumps=a.exposure_jumps,
                      exposure_jump_size=a.exposure_jump_size)
    length = a.length
    if length is None:
        length = 10.0 if a.frames is None else length_for_frames(a.frames, a.fps, a.speed)
    if a.frames is not None and a.frames < 2:
        raise VslamError("--frames must be at least 2")
    if length <= 0 or a.speed <= 0 or a.fps <= 0 or a.camera_height <= 0:
        raise VslamError("--length, --speed, --fps and --camera-height must be positive")
    return SimConfig(floor=a.floor, trajectory=a.trajectory, length=length, laps=a.laps, speed=a.speed, fps=a.fps,
                     width=w, height=h, focal=a.focal if a.focal else 500.0 * w / 640.0,
                     camera_height=a.camera_height,
                     distortion=(0.0,) * 5 if a.no_distortion else SimConfig().distortion,
                     turn_radius=a.turn_radius, seed=a.seed, gray=not a.color, image_format=a.image_format,
                     effects=effects, sensor_noise=SensorNoise().scaled(a.sensor_noise), max_frames=a.frames,
                     lanes=a.lanes, lane_spacing=a.lane_spacing,
                     scene_scale=a.scene_scale if a.scene_scale is not None else 1.0)


def run(a: argparse.Namespace) -> int:
    cfg = config_from_args(a)
    bar = Progress(0, label="simulate", enabled=None if not a.quiet else False)
    res = simulate(cfg, a.out_dir, overwrite=a.overwrite, progress=bar.update)
    bar.close()
    if not a.quiet:
        print(f"wrote {res.path}: {res.frames} frames ({res.dropped} dropped, {res.corrupt} corrupt), "
              f"{res.path_length:.1f} m of {cfg.trajectory.value if hasattr(cfg.trajectory, 'value') else cfg.trajectory} "
              f"over {cfg.floor.value if hasattr(cfg.floor, 'value') else cfg.floor}, "
              f"{res.seconds:.1f} s ({res.fps:.0f} frames/s)")
    return 0
