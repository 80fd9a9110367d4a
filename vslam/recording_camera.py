"""The camera in the recording's 3D scene: its mount on the robot, its Pinhole, and the downscaled JPEG image.

The project's downward camera frame (odometry.shared.camera) has x along image u, y along image v and z along the
optical axis, which is exactly Rerun's default Pinhole frame (RDF: right, down, forward). In the robot base frame
(x forward, y left, z up) that frame is turned half a revolution about x (u -> forward, v -> right, optical axis ->
down), tilted by the camera's (roll, pitch), yawed by the mount yaw and lifted to camera_height.
"""
from __future__ import annotations

import cv2
import numpy as np

from odometry.shared.camera import CameraModel
from odometry.shared.rotations import rotmat_to_quat, tilt_matrix

_FLIP_X = np.diag([1.0, -1.0, -1.0])   # camera (u, v, optical) -> robot (forward, left, up)


def mount_rotation(camera: CameraModel) -> np.ndarray:
    """Rotation (3, 3) taking camera-frame vectors into the robot base frame."""
    c, s = np.cos(camera.mount[2]), np.sin(camera.mount[2])
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return rz @ _FLIP_X @ tilt_matrix(*camera.tilt)


def mount_transform(camera: CameraModel):
    """The camera's static Transform3D under the robot."""
    import rerun as rr

    h = camera.camera_height if camera.camera_height is not None else 0.0
    q = rotmat_to_quat(mount_rotation(camera))
    return rr.Transform3D(translation=[camera.mount[0], camera.mount[1], h], quaternion=[float(v) for v in q])


def scaled_size(camera: CameraModel, scale: float) -> tuple[int, int]:
    """(width, height) of the logged image at `scale`, at least one pixel each."""
    return max(1, int(round(camera.width * scale))), max(1, int(round(camera.height * scale)))


def pinhole(camera: CameraModel, scale: float):
    """The Pinhole of the logged (downscaled) image. Its image plane is drawn just above the floor, so the 3D view
    shows the image where it lies on the floor (the footprint) at the end of the frustum."""
    import rerun as rr

    w, h = scaled_size(camera, scale)
    sx, sy = w / camera.width, h / camera.height
    # pixel centres: a pixel u in the full image is at (u + 0.5) * s - 0.5 in the scaled one
    cx, cy = (camera.cx + 0.5) * sx - 0.5, (camera.cy + 0.5) * sy - 0.5
    plane = 0.98 * camera.camera_height if camera.camera_height else None   # 2 % above the floor: no z-fighting
    return rr.Pinhole(focal_length=[camera.fx * sx, camera.fy * sy], principal_point=[cx, cy], resolution=[w, h],
                      image_plane_distance=plane, color=(250, 200, 0), line_width=0.004)


def encode_image(image: np.ndarray, size: tuple[int, int], quality: int) -> bytes | None:
    """The image resized to `size` (area averaging) and JPEG-encoded; None if encoding failed."""
    if image.shape[1] != size[0] or image.shape[0] != size[1]:
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    return buf.tobytes() if ok else None


def scale_pixels(uv: np.ndarray, sx: float, sy: float) -> np.ndarray:
    """Full-resolution pixel coordinates -> coordinates in the downscaled image (pixel centres kept)."""
    uv = np.asarray(uv, np.float32).reshape(-1, 2)
    return np.column_stack([(uv[:, 0] + 0.5) * sx - 0.5, (uv[:, 1] + 0.5) * sy - 0.5]).astype(np.float32)
