"""The ground-texture simulator: determinism, geometric agreement of images / ground truth / odometry, floors."""
import argparse
import hashlib
import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from odometry.shared.poses import integrate_arcs, transform_points
from vslam.cli.cmd_simulate import add_arguments, config_from_args
from vslam.cli.main import main
from vslam.errors import ImageReadError
from vslam.io import open_sequence
from vslam.sim import Effects, Floor, FloorType, SensorNoise, SimConfig, plan_motion, simulate
from vslam.sim.render import FrameRenderer
from vslam.sim.trajectory import TrajectoryKind

SMALL = SimConfig(width=320, height=240, focal=250.0, length=2.0, fps=10.0, speed=0.5)


def digest(root):
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file():
            h.update(p.name.encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def test_deterministic_for_a_seed(tmp_path):
    a = simulate(SMALL, tmp_path / "a")
    b = simulate(SMALL, tmp_path / "b")
    c = simulate(replace(SMALL, seed=1), tmp_path / "c")
    assert a.frames == b.frames > 10
    assert digest(a.path) == digest(b.path)
    assert digest(a.path) != digest(c.path)


def test_sequence_validates_and_streams_agree(tmp_path):
    res = simulate(SMALL, tmp_path / "s")
    seq = open_sequence(res.path, check_images="decode")
    assert len(seq) == res.frames
    assert seq.odometry is not None and seq.imu is not None and seq.groundtruth is not None
    assert seq.odometry.timestamps[-1] <= seq.timestamps[-1] + 1e-9          # streams end with the last frame
    assert seq.path_length() == pytest.approx(res.path_length, rel=0.02)
    assert (tmp_path / "s" / "sim.yaml").is_file()


@pytest.mark.parametrize("kind", list(TrajectoryKind))
def test_noise_free_odometry_integrates_to_ground_truth(tmp_path, kind):
    cfg = replace(SMALL, trajectory=kind, length=6.0, sensor_noise=SensorNoise.preset("none"), effects=Effects.preset("none"),
                  max_frames=40)
    seq = open_sequence(simulate(cfg, tmp_path / "s").path)
    odo = seq.odometry
    dt = np.diff(np.append(odo.timestamps, odo.timestamps[-1] + 0.01))
    poses = integrate_arcs(odo.v, odo.omega, dt)               # rows hold until the next row
    at_frames = poses[np.searchsorted(odo.timestamps, seq.timestamps - 1e-9)]
    gt = seq.groundtruth_planar()
    assert np.abs(at_frames[:, :2] - gt[:, :2]).max() < 1e-6
    # the gyro reads the same yaw rate when noise is off
    np.testing.assert_allclose(seq.imu.gyro_z, odo.omega, atol=1e-12)


def test_closed_paths_return_to_start():
    for kind in (TrajectoryKind.LOOP, TrajectoryKind.FIGURE8):
        c = plan_motion(replace(SMALL, trajectory=kind, length=20.0))
        assert np.hypot(*c.poses[-1, :2]) < 0.06, kind
        assert abs(math.remainder(c.poses[-1, 2], 2 * math.pi)) < 0.02


def test_rendered_image_shows_the_floor_under_the_ground_truth_pose():
    """Each pixel shows the floor point the camera model maps it to (no effects, so exactly)."""
    cfg = replace(SMALL, effects=Effects.preset("none"))
    cam = cfg.camera()
    floor = Floor("gravel", seed=3, resolution=cam.ground_resolution())
    pose = np.array([0.7, -0.4, 0.9])
    img = FrameRenderer(floor, cam, cfg.effects).render(pose, 0.0).astype(np.float32)
    rng = np.random.default_rng(0)
    uv = rng.uniform([20, 20], [cam.width - 20, cam.height - 20], (400, 2))
    got = cv2.remap(img, uv[:, 0].astype(np.float32)[None], uv[:, 1].astype(np.float32)[None], cv2.INTER_LINEAR)[0]

    def predicted(offset):
        world = transform_points(pose, cam.pixel_to_floor(uv + offset))
        grid = world / floor.res - 0.5                      # floor pixel coordinates
        c0, r0 = np.floor(grid.min(axis=0)).astype(int) - 2
        c1, r1 = np.ceil(grid.max(axis=0)).astype(int) + 2
        region = floor.region(c0, r0, c1 - c0, r1 - r0)
        return cv2.remap(region, (grid[:, 0] - c0).astype(np.float32)[None],
                         (grid[:, 1] - r0).astype(np.float32)[None], cv2.INTER_LINEAR)[0]

    corr = {off: np.corrcoef(got, predicted(np.array(off)))[0, 1] for off in [(0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)]}
    assert corr[(0, 0)] > 0.97
    assert corr[(0, 0)] > max(v for k, v in corr.items() if k != (0, 0)) + 0.05   # aligned to better than a pixel
    # and the footprint is rendered where the camera model says: a shifted pose gives a different picture
    other = FrameRenderer(floor, cam, cfg.effects).render(pose + [0.3, 0, 0], 0.0)
    assert np.abs(other.astype(np.float32) - img).mean() > 10


def test_floor_tiles_are_seamless_and_cached():
    f = Floor("carpet", seed=1)
    whole = f.region(400, 400, 300, 300)
    # any window equals the corresponding slice of a larger window (tile borders do not show in the data)
    np.testing.assert_array_equal(whole[50:150, 100:300], f.region(500, 450, 200, 100))
    f2 = Floor("carpet", seed=1)
    np.testing.assert_array_equal(f2.region(500, 450, 200, 100), whole[50:150, 100:300])   # order-independent


def _best_match(floor, probe, search):
    res = cv2.matchTemplate(search, probe, cv2.TM_CCOEFF_NORMED)
    return float(res.max())


def test_printed_wood_repeats_and_natural_floors_do_not():
    """Far-apart floor patches: printed wood contains exact repeats of its prints; a natural floor does not."""
    scores = {}
    for ft in (FloorType.PRINTED_WOOD, FloorType.CARPET):
        f = Floor(ft, seed=5)
        probe = f.region(3000, 3000, 120, 80)
        search = f.region(0, 0, 2048, 2048)
        scores[ft] = _best_match(f, probe, search)
    assert scores[FloorType.PRINTED_WOOD] > 0.95
    assert scores[FloorType.CARPET] < 0.5


@pytest.mark.parametrize("ft", list(FloorType))
def test_every_floor_has_texture(ft):
    f = Floor(ft, seed=0)
    img = np.clip(f.region(0, 0, 640, 480), 0, 255).astype(np.uint8)
    assert img.std() > 8
    assert len(cv2.ORB_create(500).detect(img)) > 150


def test_dropped_and_corrupt_frames(tmp_path):
    eff = replace(Effects.preset("none"), dropped_frames=0.15, corrupt_frames=0.15)
    res = simulate(replace(SMALL, effects=eff, length=4.0), tmp_path / "s")
    assert res.dropped > 0 and res.corrupt > 0
    seq = open_sequence(res.path)
    gaps = np.diff(seq.timestamps)
    assert gaps.max() > 1.5 / SMALL.fps                 # a dropped frame leaves a gap in time
    bad = 0
    for i in range(len(seq)):
        try:
            seq.image(i)
        except ImageReadError as e:
            assert "cannot be decoded" in str(e)
            bad += 1
    assert bad == res.corrupt


def test_cli_simulate_and_info(tmp_path, capsys):
    out = tmp_path / "seq"
    assert main(["simulate", str(out), "--frames", "12", "--size", "160x120", "--quiet"]) == 0
    assert main(["info", str(out)]) == 0
    assert "frames     12" in capsys.readouterr().out
    assert main(["simulate", str(out), "--frames", "12", "--quiet"]) == 2          # exists, no --overwrite
    (out / "camera.yaml").write_text((out / "camera.yaml").read_text().replace("fx:", "fx_typo:"))
    assert main(["info", str(out)]) == 2
    assert "camera.yaml" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------------- issue 13

def test_lanes_alternate_direction_and_turn_in_place():
    cfg = replace(SMALL, trajectory="lanes", lanes=3, lane_spacing=0.4, length=3 * 1.0 + 2 * 0.4, speed=0.5)
    c = plan_motion(cfg)
    p = c.poses
    assert np.allclose(p[-1, :2], [1.0, 0.8], atol=1e-6)            # three 1 m lanes, 0.4 m apart
    assert math.isclose(math.cos(p[-1, 2]), 1.0, abs_tol=1e-9)      # lane 3 flies like lane 1
    turning = (np.abs(c.omega) > 0)
    assert np.all(c.v[turning] == 0)                                # turns are in place
    heading = p[:-1, 2][np.abs(c.v) > 0]
    assert np.any(np.isclose(np.cos(heading), -1.0))                # lane 2 is flown backwards
    assert math.isclose(np.sum(np.abs(c.omega)) / cfg.sensor_rate, 2 * math.pi, rel_tol=1e-6)  # 2 x 180 deg


def test_scene_scale_renders_the_same_view_at_any_height(tmp_path):
    """A camera at 40 m over the floor magnified 80x sees what a camera at 0.5 m sees: the ground photographs
    keep their pixel size (aerial-like scenes), while poses, odometry and camera.yaml are in true metres."""
    eff = Effects.preset("none")
    low = simulate(replace(SMALL, effects=eff, max_frames=3), tmp_path / "low")
    cfg = replace(SMALL, effects=eff, max_frames=3, camera_height=40.0, scene_scale=80.0, length=160.0, speed=40.0,
                  turn_radius=80.0)
    high = simulate(cfg, tmp_path / "high")
    a, b = open_sequence(low.path), open_sequence(high.path)
    assert b.require_camera().camera_height == 40.0
    assert np.array_equal(a.image(0, gray=True), b.image(0, gray=True))
    assert np.allclose(b.groundtruth_planar()[:, :2], 80.0 * a.groundtruth_planar()[:, :2], atol=1e-6)


def test_dropped_runs_and_exposure_jumps(tmp_path):
    eff = replace(Effects.preset("none"), dropped_frames=0.05, dropped_run=4, exposure_jumps=0.3,
                  exposure_jump_size=0.6)
    res = simulate(replace(SMALL, effects=eff, length=6.0), tmp_path / "s")
    seq = open_sequence(res.path)
    gaps = np.round(np.diff(seq.timestamps) * SMALL.fps).astype(int) - 1
    assert res.dropped > 0 and np.all((gaps == 0) | (gaps >= 4) | (gaps == res.dropped % 4))
    mean = np.array([seq.image(i, gray=True).mean() for i in range(len(seq))])
    assert np.max(np.abs(np.diff(np.log(mean)))) > 0.2                 # brightness steps between frames


def test_cli_simulate_has_the_regime_options(tmp_path):
    """`vslam simulate` reaches lanes, scene scale, dropped runs and exposure jumps (the SimConfig options)."""
    p = argparse.ArgumentParser()
    add_arguments(p)
    a = p.parse_args([str(tmp_path / "x"), "--trajectory", "lanes", "--lanes", "4", "--lane-spacing", "27",
                      "--camera-height", "40", "--scene-scale", "80", "--dropped-frames", "0.1", "--dropped-run", "8",
                      "--exposure-jumps", "0.2", "--exposure-jump-size", "0.3"])
    cfg = config_from_args(a)
    assert (cfg.lanes, cfg.lane_spacing, cfg.scene_scale, cfg.camera_height) == (4, 27.0, 80.0, 40.0)
    assert (cfg.effects.dropped_run, cfg.effects.exposure_jumps, cfg.effects.exposure_jump_size) == (8, 0.2, 0.3)
    assert config_from_args(p.parse_args([str(tmp_path / "y")])).scene_scale == 1.0      # default: unchanged
    out = tmp_path / "lanes"
    assert main(["simulate", str(out), "--trajectory", "lanes", "--lanes", "2", "--size", "160x120",
                 "--camera-height", "40", "--scene-scale", "80", "--speed", "14", "--fps", "0.2", "--length", "200",
                 "--turn-radius", "80", "--no-distortion", "--quiet"]) == 0
    gt = open_sequence(out).groundtruth_planar()
    assert np.any(np.isclose(np.cos(gt[:, 2]), -1.0, atol=1e-6))      # the second lane is flown backwards
    assert main(["simulate", str(tmp_path / "bad"), "--dropped-run", "0", "--quiet"]) == 2
