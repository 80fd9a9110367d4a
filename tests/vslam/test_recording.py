"""The Rerun recording is written without a viewer and holds what was logged (read back from the .rrd)."""
import cv2
import numpy as np
import pytest

from odometry.shared.camera import CameraModel
from vslam.recording import RunRecorder

rrchunk = pytest.importorskip("rerun.chunk")


def _column(path, entity, column):
    rows = []
    for ch in rrchunk.RrdReader(str(path)).stream().to_chunks():
        if ch.entity_path == entity:
            rb = ch.to_record_batch()
            if column in rb.schema.names:
                rows += rb.column(column).to_pylist()
    return rows


def test_recorder_round_trip(tmp_path):
    cam = CameraModel(64, 48, 50.0, 50.0, 31.5, 23.5, camera_height=0.5)
    out = tmp_path / "recording.rrd"
    rec = RunRecorder(out, cam)
    img = np.tile(np.arange(64, dtype=np.uint8) * 4, (48, 1))
    for i in range(130):
        rec.set_frame(i, 0.05 * i)
        rec.log_image(i, img, keypoints=np.array([[10.0, 12.0]]))
        rec.log_pose(np.array([0.01 * i, 0.0, 0.0]), "vo")
        rec.log_scalars(**{"vo/inliers": float(i)})
    rec.log_loop(np.array([1.0, 0, 0]), np.array([0.0, 0, 0]), accepted=True)
    rec.log_loop(np.array([1.2, 0, 0]), np.array([0.3, 0, 0]), accepted=False)
    rec.log_text("loop closed 129 -> 0")
    assert not out.exists()                          # written under a temporary name until finalised
    rec.close()
    assert out.is_file()
    store = rrchunk.RrdReader(str(out)).store()
    paths = store.schema().entity_paths()
    for p in ("/camera/image", "/camera/image/keypoints", "/world/robot", "/metrics/vo/inliers", "/world/loops/accepted",
              "/map/loops/rejected", "/log", "/world/trajectory/vo/0", "/map/footprint"):
        assert p in paths, p
    assert [v[0] for v in _column(out, "/metrics/vo/inliers", "Scalars:scalars")] == [float(i) for i in range(130)]
    blob = _column(out, "/camera/image", "EncodedImage:blob")[0]
    back = cv2.imdecode(np.asarray(blob, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert back.shape == (48, 64) and np.abs(back.astype(int) - img).mean() < 3
    assert len(rrchunk.RrdReader(str(out)).blueprints()) == 1
    # trajectory segments cover every logged pose
    xs = [p[0] for k in range(3) for strip in _column(out, f"/world/trajectory/vo/{k}", "LineStrips3D:strips")
          for p in strip[0]]
    assert min(xs) == 0.0 and max(xs) == pytest.approx(1.29)
