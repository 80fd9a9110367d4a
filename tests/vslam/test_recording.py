"""The Rerun recording is a 3D scene written without a viewer; read back from the .rrd: the entity tree, the camera
(Pinhole + mount) agreeing with the camera model's floor geometry, the downscaled images, loops and trajectories."""
import cv2
import numpy as np
import pytest

from odometry.shared.camera import CameraModel
from odometry.shared.rotations import quat_to_rotmat
from vslam import recording_layout as lay
from vslam.recording import RunRecorder

rrchunk = pytest.importorskip("rerun.chunk")

CAM = CameraModel(64, 48, 50.0, 52.0, 31.5, 23.5, camera_height=0.5, mount=(0.1, -0.05, 0.3), tilt=(0.02, -0.03))


def _rows(path, entity, column, static=None):
    """[(frame or None, value)] of one column of one entity, in file order."""
    out = []
    for ch in rrchunk.RrdReader(str(path)).stream().to_chunks():
        if ch.entity_path != entity or (static is not None and ch.is_static != static):
            continue
        rb = ch.to_record_batch()
        if column in rb.schema.names:
            frames = rb.column("frame").to_pylist() if "frame" in rb.schema.names else [None] * rb.num_rows
            out += list(zip(frames, rb.column(column).to_pylist()))
    return out


def _values(path, entity, column):
    return [v for _, v in _rows(path, entity, column) if v is not None]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "recording.rrd"
    rec = RunRecorder(out, CAM, image_every=3, image_scale=0.5, jpeg_quality=90)
    img = np.tile(np.arange(64, dtype=np.uint8) * 4, (48, 1))
    for i in range(130):
        rec.set_frame(i, 0.05 * i)
        rec.log_image(i, img, keypoints=np.array([[10.0, 12.0], [63.0, 47.0]]),
                      matches=(np.array([[10.0, 12.0]]), np.array([[12.0, 12.0]])))
        rec.log_pose(np.array([0.01 * i, 0.0, 0.0]), "vo")
        rec.log_pose(np.array([0.01 * i, 0.001 * i, 0.0]), "slam")
        rec.log_scalars(**{"vo/inliers": float(i), "timing/vo_ms": 1.0})
        if i == 100:   # an optimisation moved the SLAM trajectory
            rec.replace_trajectory("slam", np.column_stack([0.01 * np.arange(101), np.zeros((101, 2))]))
    rec.log_loop(np.array([1.0, 0, 0]), np.array([0.0, 0, 0]), accepted=True)
    rec.set_loops(kept=[np.array([[1.0, 0], [0, 0]])], rejected=[np.array([[1.2, 0], [0.3, 0]])],
                  candidates=[np.array([[0.5, 0], [0.1, 0]]), np.array([[0.6, 0], [0.2, 0]])])
    rec.log_text("loop closed 129 -> 0")
    assert not out.exists()                          # written under a temporary name until finalised
    rec.close()
    return out


def test_entity_tree_and_blueprint(recording):
    paths = rrchunk.RrdReader(str(recording)).store().schema().entity_paths()
    for p in (lay.IMAGE, lay.KEYPOINTS, lay.MATCHES, lay.ROBOT, lay.CAMERA, lay.FOOTPRINT, lay.FLOOR,
              "/world/trajectory/vo/0", "/world/trajectory/slam/0", "/world/loops/kept", "/world/loops/rejected",
              "/world/loops/candidates", "/metrics/vo/inliers", "/metrics/timing/vo_ms", "/log"):
        assert p in paths, p
    assert not any(p.startswith("/camera") or p.startswith("/map") for p in paths)   # one scene, no 2D copy
    assert len(rrchunk.RrdReader(str(recording)).blueprints()) == 1
    assert [v[0] for v in _values(recording, "/metrics/vo/inliers", "Scalars:scalars")] == [float(i) for i in
                                                                                            range(130)]


def test_pinhole_and_mount_reproduce_the_camera_models_floor_geometry(recording):
    (_, k), = _rows(recording, lay.IMAGE, "Pinhole:image_from_camera", static=True)
    (_, res), = _rows(recording, lay.IMAGE, "Pinhole:resolution", static=True)
    assert res == [[32.0, 24.0]]                                   # logged at half resolution
    K = np.asarray(k[0], float).reshape(3, 3).T                     # stored column-major
    assert K[0, 0] == pytest.approx(25.0) and K[1, 1] == pytest.approx(26.0)
    (_, t), = _rows(recording, lay.CAMERA, "Transform3D:translation", static=True)
    (_, q), = _rows(recording, lay.CAMERA, "Transform3D:quaternion", static=True)
    R, t = quat_to_rotmat(np.asarray(q[0])), np.asarray(t[0])
    # a pixel of the logged image, cast through the Pinhole and the mount onto the floor (z = 0), lands where the
    # camera model puts the matching full-resolution pixel
    uv_small = np.array([[3.0, 4.0], [20.0, 15.0], [31.0, 0.0]])
    rays = np.column_stack([(uv_small[:, 0] - K[0, 2]) / K[0, 0], (uv_small[:, 1] - K[1, 2]) / K[1, 1],
                            np.ones(3)]) @ R.T
    floor = t + rays * (-t[2] / rays[:, 2:3])
    undistorted = CAM.denormalize(CAM.normalize((uv_small + 0.5) * 2 - 0.5))   # no distortion: the same pixels
    np.testing.assert_allclose(floor[:, :2], CAM.pixel_to_floor(undistorted), atol=1e-6)


def test_images_are_downscaled_jpeg_every_nth_frame(recording):
    rows = _rows(recording, lay.IMAGE, "EncodedImage:blob")
    assert [f for f, _ in rows] == list(range(0, 130, 3))
    back = cv2.imdecode(np.asarray(rows[0][1][0], np.uint8), cv2.IMREAD_GRAYSCALE)
    full = np.tile(np.arange(64, dtype=np.uint8) * 4, (48, 1))
    assert back.shape == (24, 32)
    assert np.abs(back.astype(int) - cv2.resize(full, (32, 24), interpolation=cv2.INTER_AREA)).mean() < 3
    kp = _rows(recording, lay.KEYPOINTS, "Points2D:positions")
    assert [f for f, _ in kp] == list(range(0, 130, 3))              # overlays only with their image
    np.testing.assert_allclose(kp[0][1], [[4.75, 5.75], [31.25, 23.25]])  # pixel centres kept: (u + 0.5) / 2 - 0.5


def test_trajectories_cover_every_pose_and_slam_is_redrawn(recording):
    xs = [p[0] for k in range(20) for strip in _values(recording, f"/world/trajectory/vo/{k}", "LineStrips3D:strips")
          for p in strip[0]]
    assert min(xs) == 0.0 and max(xs) == pytest.approx(1.29)
    slam0 = _rows(recording, "/world/trajectory/slam/0", "LineStrips3D:strips")
    assert [f for f, _ in slam0] == [9, 100]                       # first segment, then the whole redrawn strip
    redrawn = np.asarray(slam0[1][1][0])
    assert len(redrawn) == 101 and np.abs(redrawn[:, 1]).max() == 0.0


def test_loops_by_verdict_with_candidates_apart(recording):
    kept = _values(recording, "/world/loops/kept", "LineStrips3D:strips")[-1]
    rejected = _values(recording, "/world/loops/rejected", "LineStrips3D:strips")[-1]
    candidates = _values(recording, "/world/loops/candidates", "LineStrips3D:strips")[-1]
    assert (len(kept), len(rejected), len(candidates)) == (2, 2, 2)   # arc + ring; candidates: arcs only
    arc = np.asarray(kept[0])
    np.testing.assert_allclose(arc[0, :2], [1.0, 0.0], atol=1e-6)    # from the query pose ...
    np.testing.assert_allclose(arc[-1, :2], [0.0, 0.0], atol=1e-6)   # ... to the match pose
    assert arc[:, 2].max() > 0.1                                     # rises off the floor: visible from any side
    colours = _values(recording, "/world/loops/rejected", "LineStrips3D:colors")[-1]
    assert colours != _values(recording, "/world/loops/kept", "LineStrips3D:colors")[-1]


def test_a_pipeline_run_redraws_slam_when_optimised_and_splits_loops_by_verdict(tmp_path):
    from vslam.io import open_sequence
    from vslam.pipeline import Pipeline, PipelineConfig
    from vslam.sim import SimConfig, simulate

    simulate(SimConfig(width=320, height=240, focal=250.0, length=4.0, laps=2, turn_radius=0.6, fps=10.0, seed=4),
             tmp_path / "seq")
    seq = open_sequence(tmp_path / "seq")
    out = tmp_path / "recording.rrd"
    rec = RunRecorder(out, seq.camera)
    result = Pipeline(PipelineConfig(), recorder=rec).run(seq)
    rec.close()
    kept = [l for l in result.loops if l.accepted and l.inlier]
    candidates = [l for l in result.loops if not l.accepted]
    assert len(kept) >= 10                      # optimize_every = 10: the graph was optimised during the run
    redraws = [f for f, _ in _rows(out, "/world/trajectory/slam/0", "LineStrips3D:strips")]
    assert len(redraws) >= 3 and redraws[-1] == len(seq) - 1 and any(f < len(seq) - 1 for f in redraws[1:])
    final = {kind: _values(out, f"/world/loops/{kind}", "LineStrips3D:strips") for kind in ("kept", "candidates")}
    assert len(final["kept"][-1]) == 2 * len(kept)                # an arc and a ring per kept loop
    assert len(final["candidates"][-1]) == len(candidates)        # candidates apart, not among the kept/rejected
    assert out.stat().st_size / len(seq) <= 10_000
