"""Sequence directory format: exact schema, validation errors, writers and public-format readers."""
from pathlib import Path

import cv2
import numpy as np
import pytest

from odometry.shared.camera import CameraModel
from vslam.errors import (
    CalibrationError,
    CsvFormatError,
    EmptySequenceError,
    ImageReadError,
    MissingFileError,
    NonFiniteValueError,
    TimestampOrderError,
    UnknownColumnError,
)
from vslam.io import open_sequence, read_camera_yaml, write_sequence
from vslam.sequence import Trajectory

CAMERA_YAML = """width: 64
height: 48
fx: 50.0
fy: 50.0
cx: 31.5
cy: 23.5
distortion: [0.0, 0.0, 0.0, 0.0, 0.0]   # k1 k2 p1 p2 k3, OpenCV order
camera_height: 0.5
mount: [0.0, 0.0, 0.0]
"""


def make_sequence(root: Path, n: int = 5, with_streams: bool = True) -> Path:
    """A sequence written by hand in the exact DESIGN.md schema (as another tool would)."""
    (root / "img").mkdir(parents=True)
    (root / "camera.yaml").write_text(CAMERA_YAML)
    rng = np.random.default_rng(0)
    rows = ["timestamp,image"]
    for i in range(n):
        cv2.imwrite(str(root / "img" / f"{i}.png"), rng.integers(0, 255, (48, 64), dtype=np.uint8))
        rows.append(f"{0.1 * i:.1f},img/{i}.png")
    (root / "frames.csv").write_text("\n".join(rows) + "\n")
    if with_streams:
        (root / "odometry.csv").write_text("timestamp,v,omega\n0.0,0.1,0.0\n0.05,0.1,0.01\n0.1,0.1,0.02\n")
        (root / "imu.csv").write_text("timestamp,gyro_z\n0.0,0.001\n0.01,0.002\n")
        (root / "groundtruth.txt").write_text("# t tx ty tz qx qy qz qw\n0.0 0 0 0 0 0 0 1\n0.4 0.04 0 0 0 0 0 1\n")
    return root


def test_design_schema_loads(tmp_path):
    seq = open_sequence(make_sequence(tmp_path / "s"))
    assert len(seq) == 5 and seq.format == "sequence"
    assert seq.camera == CameraModel(64, 48, 50.0, 50.0, 31.5, 23.5, camera_height=0.5)
    assert seq.odometry.v.tolist() == [0.1, 0.1, 0.1] and seq.imu.gyro_z[1] == 0.002
    np.testing.assert_allclose(seq.groundtruth_planar()[:, 0], [0, 0.01, 0.02, 0.03, 0.04], atol=1e-12)
    frames = list(seq.frames(gray=True))
    assert [f.index for f in frames] == list(range(5)) and frames[2].image.shape == (48, 64)
    assert seq.path_length() == pytest.approx(0.04)


def test_frames_are_lazy_and_bounded(tmp_path):
    root = make_sequence(tmp_path / "s", n=3, with_streams=False)
    seq = open_sequence(root)
    it = seq.frames()
    first = next(it)
    (root / "img" / "2.png").write_bytes(b"broken")         # damaged after opening: found when read, not before
    assert first.index == 0
    next(it)
    with pytest.raises(ImageReadError, match="2.png"):
        next(it)


def test_write_read_round_trip(tmp_path):
    seq = open_sequence(make_sequence(tmp_path / "s"))
    out = write_sequence(seq, tmp_path / "copy")
    again = open_sequence(out)
    np.testing.assert_array_equal(again.timestamps, seq.timestamps)
    assert again.camera == seq.camera
    np.testing.assert_array_equal(again.odometry.omega, seq.odometry.omega)
    np.testing.assert_array_equal(again.groundtruth.poses, seq.groundtruth.poses)
    for i in range(len(seq)):
        np.testing.assert_array_equal(again.image(i), seq.image(i))   # lossless: files copied byte for byte
    with pytest.raises(FileExistsError):
        write_sequence(seq, out)


@pytest.mark.parametrize("field", ["fx", "cy", "width", "distortion"])
def test_missing_calibration_field(tmp_path, field):
    root = make_sequence(tmp_path / "s")
    text = "\n".join(l for l in CAMERA_YAML.splitlines() if not l.startswith(field + ":"))
    (root / "camera.yaml").write_text(text)
    with pytest.raises(CalibrationError, match=rf"camera.yaml: field '{field}': missing"):
        open_sequence(root)


@pytest.mark.parametrize("line,match", [
    ("fx: .nan", r"camera.yaml:3: field 'fx': nan is not a finite"),
    ("fx: -5", r"camera.yaml:3: field 'fx': focal length must be positive"),
    ("fx: fifty", r"camera.yaml:3: field 'fx': expected a number"),
    ("fx: 50\nfocal: 3", r"field 'focal': unknown calibration field"),
])
def test_bad_calibration_values(tmp_path, line, match):
    root = make_sequence(tmp_path / "s")
    (root / "camera.yaml").write_text(CAMERA_YAML.replace("fx: 50.0", line))
    with pytest.raises(CalibrationError, match=match):
        open_sequence(root)


def test_calibration_not_yaml(tmp_path):
    root = make_sequence(tmp_path / "s")
    (root / "camera.yaml").write_text("width: [64\nheight: 48\n")
    with pytest.raises(CalibrationError, match="not valid YAML"):
        read_camera_yaml(root / "camera.yaml")


def test_missing_image(tmp_path):
    root = make_sequence(tmp_path / "s")
    (root / "img" / "3.png").unlink()
    with pytest.raises(ImageReadError, match=r"frames.csv:5: field 'image': image file .*3.png is missing"):
        open_sequence(root)


def test_corrupt_image_found_by_decode_check(tmp_path):
    root = make_sequence(tmp_path / "s")
    (root / "img" / "1.png").write_bytes(b"\x89PNG garbage")
    seq = open_sequence(root)                                     # default check: files exist
    with pytest.raises(ImageReadError, match="1.png: image cannot be decoded"):
        seq.image(1)
    with pytest.raises(ImageReadError, match=r"frames.csv:3: field 'image'.*cannot be decoded"):
        open_sequence(root, check_images="decode")


def test_non_monotonic_timestamps(tmp_path):
    root = make_sequence(tmp_path / "s")
    (root / "frames.csv").write_text("timestamp,image\n0.0,img/0.png\n0.2,img/1.png\n0.1,img/2.png\n")
    with pytest.raises(TimestampOrderError, match=r"frames.csv:4: field 'timestamp'"):
        open_sequence(root)
    root2 = make_sequence(tmp_path / "s2")
    (root2 / "groundtruth.txt").write_text("0.5 0 0 0 0 0 0 1\n0.4 0 0 0 0 0 0 1\n")
    with pytest.raises(TimestampOrderError, match="groundtruth.txt"):
        open_sequence(root2)


@pytest.mark.parametrize("name,text,err,match", [
    ("odometry.csv", "timestamp,v,omega\n0.0,nan,0.0\n", NonFiniteValueError, r"odometry.csv:2: field 'v'"),
    ("imu.csv", "timestamp,gyro_z\n0.0,inf\n", NonFiniteValueError, r"imu.csv:2: field 'gyro_z'"),
    ("odometry.csv", "timestamp,v,omega,temperature\n0,0,0,20\n", UnknownColumnError,
     r"odometry.csv:1: field 'temperature': unknown column"),
    ("frames.csv", "time,image\n0,img/0.png\n", UnknownColumnError, r"frames.csv:1: field 'time'"),
    ("imu.csv", "timestamp\n0.0\n", CsvFormatError, r"imu.csv:1: field 'gyro_z': missing column"),
    ("odometry.csv", "timestamp,v,omega\n0.0,0.1\n", CsvFormatError, r"odometry.csv:2: expected 3 values"),
    ("odometry.csv", "timestamp,v,omega\n0.0,fast,0\n", CsvFormatError, r"odometry.csv:2: field 'v': not a number"),
])
def test_bad_streams(tmp_path, name, text, err, match):
    root = make_sequence(tmp_path / "s")
    (root / name).write_text(text)
    with pytest.raises(err, match=match):
        open_sequence(root)


def test_empty_sequence(tmp_path):
    root = make_sequence(tmp_path / "s")
    (root / "frames.csv").write_text("timestamp,image\n")
    with pytest.raises(EmptySequenceError, match="frames.csv: no frames"):
        open_sequence(root)
    empty = tmp_path / "empty_folder"
    empty.mkdir()
    with pytest.raises(EmptySequenceError, match="no images"):
        open_sequence(empty)


def test_missing_path():
    with pytest.raises(MissingFileError, match="no such file"):
        open_sequence("/nonexistent/sequence")


def test_image_folder_and_video(tmp_path):
    folder = tmp_path / "imgs"
    folder.mkdir()
    rng = np.random.default_rng(1)
    frames = [rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in range(12)]
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / f"frame{i}.png"), f)   # natural sort: frame2 before frame10
    seq = open_sequence(folder, fps=4.0)
    assert seq.format == "folder" and seq.camera is None and len(seq) == 12
    np.testing.assert_array_equal(seq.image(10), frames[10])
    assert seq.timestamps[4] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="no calibration"):
        seq.require_camera()
    (folder / "camera.yaml").write_text(CAMERA_YAML)
    assert open_sequence(folder).camera.fx == 50.0

    video = tmp_path / "clip.mp4"
    w = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (64, 48))
    for f in frames:
        w.write(f)
    w.release()
    vs = open_sequence(video, camera=folder / "camera.yaml")
    assert vs.format == "video" and len(vs) == 12 and vs.camera.fx == 50.0
    assert vs.timestamps[1] == pytest.approx(0.1)
    imgs = [fr.image for fr in vs.frames()]
    assert len(imgs) == 12 and imgs[0].shape == (48, 64, 3)
    assert np.abs(vs.image(5).astype(int) - imgs[5]).max() == 0          # seeking gives the same frame


def test_kitti_layout(tmp_path):
    root = tmp_path / "sequences" / "07"
    (root / "image_0").mkdir(parents=True)
    for i in range(3):
        cv2.imwrite(str(root / "image_0" / f"{i:06d}.png"), np.full((30, 40), i * 50, np.uint8))
    (root / "times.txt").write_text("0.0\n0.1\n0.2\n")
    (root / "calib.txt").write_text("P0: 700 0 20 0 0 700 15 0 0 0 1 0\nP1: 700 0 20 -380 0 700 15 0 0 0 1 0\n")
    poses = tmp_path / "poses"
    poses.mkdir()
    (poses / "07.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 0 0 1 0 0 0 0 1 1\n1 0 0 0 0 1 0 0 0 0 1 2\n")
    seq = open_sequence(root)
    assert seq.format == "kitti" and seq.camera.fx == 700 and seq.camera.cx == 20
    np.testing.assert_allclose(seq.groundtruth.poses[:, 2], [0, 1, 2])   # camera z forward
    (poses / "07.txt").write_text("1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(ValueError, match=r"07.txt:1: expected 12 numbers"):
        open_sequence(root)


def test_tum_rgbd_layout(tmp_path):
    root = tmp_path / "rgbd_dataset_freiburg1_xyz"
    (root / "rgb").mkdir(parents=True)
    names = []
    for i, t in enumerate([1305031102.175304, 1305031102.211214]):
        n = f"rgb/{t:.6f}.png"
        cv2.imwrite(str(root / n), np.zeros((480, 640, 3), np.uint8))
        names.append(f"{t:.6f} {n}")
    (root / "rgb.txt").write_text("# color images\n# file: 'x'\n# timestamp filename\n" + "\n".join(names) + "\n")
    (root / "groundtruth.txt").write_text("1305031102.1758 1.3405 0.6266 1.6575 0.6574 0.6126 -0.2949 -0.3248\n")
    seq = open_sequence(root)
    assert seq.format == "tum-rgbd" and len(seq) == 2
    assert seq.camera.fx == 517.3 and seq.camera.distortion[0] == 0.2624      # freiburg1 published calibration
    assert seq.groundtruth.poses[0, 0] == pytest.approx(1.3405)


def test_real_kitti_snippet(shared_data):
    root = shared_data / "places" / "kitti_snippets" / "KITTI_sequence_1_kitti06_f0000-0050"
    if not root.is_dir():
        pytest.skip("KITTI snippet not present in this copy of the shared data")
    seq = open_sequence(root)
    assert len(seq) == 51 and seq.camera.fx == pytest.approx(707.0912)
    assert seq.image(0, gray=True).shape == (370, 1226)
    assert 55 < seq.path_length() < 65                                     # ~60 m of driving (SOURCE.txt)


def test_ground_truth_at_low_rate_frames_written_with_six_decimals():
    """A 0.14 Hz sequence: frames.csv keeps 7.142857142857 s, the TUM ground truth 7.142857 s, and the next pose is
    7 s away (beyond max_gap): the frame still gets its pose (it was NaN, so evaluation had no ground truth)."""
    t_frames = np.arange(5) / 0.14
    t_gt = np.round(t_frames, 6)
    poses = np.zeros((5, 7))
    poses[:, 0] = 14.0 * np.arange(5)
    poses[:, 6] = 1.0
    gt = Trajectory(t_gt, poses).planar_at(t_frames, max_gap=0.5)
    assert np.allclose(gt[:, 0], 14.0 * np.arange(5))
    assert np.isnan(Trajectory(t_gt, poses).planar_at(t_frames + 1.0, max_gap=0.5)[:4, 0]).all()   # gaps stay NaN


def test_ground_truth_at_low_rate_frames_written_with_three_decimals():
    """One fix per photograph written in milliseconds (7.143 s for a frame at 7.142857 s): within the 10 ms ATE
    association tolerance the frame takes that fix although the gap to the next is wider than max_gap."""
    t_frames = np.arange(5) / 0.14
    poses = np.zeros((5, 7))
    poses[:, 0] = 14.0 * np.arange(5)
    poses[:, 6] = 1.0
    gt = Trajectory(np.round(t_frames, 3), poses).planar_at(t_frames, max_gap=0.5)
    assert np.allclose(gt[:, 0], 14.0 * np.arange(5))
    late = Trajectory(np.round(t_frames, 3) + 0.02, poses).planar_at(t_frames, max_gap=0.5)   # 20 ms off: no pose
    assert np.isnan(late[:, 0]).all()
