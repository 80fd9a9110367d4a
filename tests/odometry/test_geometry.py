"""Camera model, floor mapping, footprint overlap and planar pose conventions."""
import math

import numpy as np
import pytest

from odometry.shared.camera import CameraModel
from odometry.shared.footprint import footprint_overlap, footprint_polygon, overlap_matrix, overlap_pairs
from odometry.shared.poses import between, compose, integrate, inverse, relative_motions, wrap_angle
from odometry.shared.rotations import quat_to_rotmat, quat_to_yaw, rotmat_to_quat
from odometry.shared.tum import TumFormatError, read_tum, se2_to_tum, tum_to_se2, write_tum

CAM = CameraModel(640, 480, 500.0, 500.0, 319.5, 239.5, camera_height=0.5)
DIST = CameraModel(640, 480, 480.0, 470.0, 322.0, 236.0, distortion=(-0.28, 0.07, 0.001, -0.0012, 0.0),
                   camera_height=0.42, mount=(0.12, -0.03, 0.2), tilt=(0.02, -0.015))


def test_pixel_to_floor_matches_design_convention():
    # DESIGN.md: floor point = mount_xy + R(mount_yaw) [(u - cx) h / fx, -(v - cy) h / fy]
    uv = np.array([[319.5, 239.5], [419.5, 239.5], [319.5, 339.5], [619.5, 39.5]])
    xy = CAM.pixel_to_floor(uv)
    expected = np.column_stack([(uv[:, 0] - 319.5) * 0.5 / 500, -(uv[:, 1] - 239.5) * 0.5 / 500])
    np.testing.assert_allclose(xy, expected, atol=1e-12)
    # u grows forward (+x), v grows to the robot's right (-y)
    assert xy[1, 0] > 0 and xy[2, 1] < 0


def test_mount_yaw_rotates_floor_points():
    cam = CameraModel(640, 480, 500.0, 500.0, 319.5, 239.5, camera_height=0.5, mount=(0.1, 0.2, math.pi / 2))
    xy = cam.pixel_to_floor([[419.5, 239.5]])[0]          # 0.1 m forward in the camera frame
    np.testing.assert_allclose(xy, [0.1, 0.2 + 0.1], atol=1e-12)


@pytest.mark.parametrize("cam", [CAM, DIST])
def test_pixel_floor_pixel_round_trip(cam):
    uv = np.random.default_rng(0).uniform([0, 0], [cam.width - 1, cam.height - 1], (2000, 2))
    back = cam.floor_to_pixel(cam.pixel_to_floor(uv))
    assert np.abs(back - uv).max() < 1e-6


def test_distortion_round_trip_and_effect():
    xn = np.random.default_rng(1).uniform(-0.6, 0.6, (500, 2))
    uv = DIST.denormalize(xn)
    np.testing.assert_allclose(DIST.normalize(uv), xn, atol=1e-9)
    # barrel distortion pulls off-centre points towards the centre
    ideal = np.column_stack([DIST.fx * xn[:, 0] + DIST.cx, DIST.fy * xn[:, 1] + DIST.cy])
    r_dist = np.hypot(uv[:, 0] - DIST.cx, uv[:, 1] - DIST.cy)
    r_ideal = np.hypot(ideal[:, 0] - DIST.cx, ideal[:, 1] - DIST.cy)
    assert np.all(r_dist[r_ideal > 100] < r_ideal[r_ideal > 100])


def test_floor_mapping_needs_height():
    cam = CameraModel(640, 480, 500.0, 500.0, 319.5, 239.5)
    with pytest.raises(ValueError, match="camera_height"):
        cam.pixel_to_floor([[1.0, 2.0]])


@pytest.mark.parametrize("kwargs", [dict(fx=0.0), dict(fy=-1.0), dict(cx=float("nan")), dict(width=0)])
def test_camera_rejects_bad_values(kwargs):
    base = dict(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5)
    base.update(kwargs)
    with pytest.raises(ValueError):
        CameraModel(**base)


def test_footprint_area_and_orientation():
    fp = CAM.footprint()
    x, y = fp[:, 0], fp[:, 1]
    area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    assert area == pytest.approx(0.64 * 0.48, rel=1e-9)  # counter-clockwise, whole image


def test_overlap_identical_disjoint_half():
    p = np.array([1.0, -2.0, 0.7])
    assert footprint_overlap(CAM, p, p) == pytest.approx(1.0)
    assert footprint_overlap(CAM, p, p + [5.0, 0, 0]) == 0.0
    # shifting by half the footprint length along the robot's x: intersection 1/2, union 3/2 -> J = 1/3
    half = compose(p, np.array([0.32, 0.0, 0.0]))
    assert footprint_overlap(CAM, p, half) == pytest.approx(1 / 3, abs=1e-9)
    # rotated by 90 deg about the same point: intersection 0.48^2, union 2*0.64*0.48 - 0.48^2
    rot = compose(p, np.array([0.0, 0.0, math.pi / 2]))
    inter = 0.48 * 0.48
    assert footprint_overlap(CAM, p, rot) == pytest.approx(inter / (2 * 0.64 * 0.48 - inter), abs=1e-9)


def test_overlap_matrix_matches_pairs():
    rng = np.random.default_rng(2)
    poses = np.column_stack([np.cumsum(rng.uniform(0, 0.1, 60)), rng.normal(0, 0.05, 60), rng.normal(0, 0.3, 60)])
    J = overlap_matrix(CAM, poses)
    i, j = np.triu_indices(60, 1)
    np.testing.assert_allclose(J[i, j], overlap_pairs(CAM, poses[i], poses[j]), atol=1e-12)
    assert np.allclose(J, J.T) and np.all(np.diag(J) == 1)


def test_footprint_polygon_moves_with_pose():
    p = np.array([2.0, 3.0, math.pi / 2])
    poly = footprint_polygon(CAM, p)
    # robot heading +y: the camera's forward extent 0.32 m lies along +y
    assert poly[:, 1].max() == pytest.approx(3.32) and poly[:, 0].max() == pytest.approx(2.24)


def test_pose_composition_hand_cases():
    a = np.array([1.0, 2.0, math.pi / 2])
    b = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(compose(a, b), [1.0, 3.0, math.pi / 2], atol=1e-12)
    np.testing.assert_allclose(compose(a, inverse(a)), [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(between(a, compose(a, b)), b, atol=1e-12)
    c = np.array([0.0, 0.0, 3.0])
    assert compose(c, c)[2] == pytest.approx(wrap_angle(6.0))


def test_integrate_is_inverse_of_relative_motions():
    d = np.random.default_rng(3).normal(0, 0.2, (50, 3))
    poses = integrate(d, start=np.array([1.0, -1.0, 0.4]))
    np.testing.assert_allclose(relative_motions(poses), np.column_stack([d[:, :2], wrap_angle(d[:, 2])]), atol=1e-12)
    # eq. (1)-(2): a step (1, 0, pi/2) from the origin, then (1, 0, 0): ends at (1, 1) heading pi/2
    np.testing.assert_allclose(integrate(np.array([[1.0, 0, math.pi / 2], [1.0, 0, 0]]))[-1], [1, 1, math.pi / 2],
                               atol=1e-12)


def test_tum_conversions_and_file_round_trip(tmp_path):
    p = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 2.5], [-1.0, 0.5, -3.0]])
    tum = se2_to_tum(p)
    np.testing.assert_allclose(tum_to_se2(tum), p, atol=1e-12)
    R = quat_to_rotmat(tum[:, 3:])
    np.testing.assert_allclose(rotmat_to_quat(R), tum[:, 3:] * np.sign(tum[:, 6:7]), atol=1e-12)  # qw >= 0
    np.testing.assert_allclose(quat_to_yaw(tum[:, 3:]), p[:, 2], atol=1e-12)
    f = tmp_path / "t.txt"
    write_tum(f, np.array([0.0, 0.1, 0.2]), p)
    t, back = read_tum(f)
    np.testing.assert_allclose(tum_to_se2(back), p, atol=1e-8)
    np.testing.assert_allclose(t, [0.0, 0.1, 0.2])


def test_read_tum_reports_line(tmp_path):
    f = tmp_path / "bad.txt"
    f.write_text("# header\n0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 1\n")
    with pytest.raises(TumFormatError, match=r"bad.txt:3"):
        read_tum(f)
    f.write_text("0 0 0 nan 0 0 0 1\n")
    with pytest.raises(TumFormatError, match=r"bad.txt:1: NaN"):
        read_tum(f)


def test_atomic_write_permissions_and_no_partial_file(tmp_path):
    import os
    import stat

    from odometry.shared.atomic_io import atomic_path, atomic_write_text

    f = tmp_path / "out.txt"
    atomic_write_text(f, "hello\n")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(f.stat().st_mode) == 0o666 & ~umask
    with pytest.raises(RuntimeError):
        with atomic_path(f) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash while writing")
    assert f.read_text() == "hello\n" and sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]
