"""Test fixture: views of a flat textured floor for a downward camera at known poses (remap through the camera
model, so distortion, height and mount are exact). Not a simulator: no blur, lighting or noise unless a test
adds them."""
from __future__ import annotations

import cv2
import numpy as np

from odometry.shared.camera import CameraModel
from odometry.shared.poses import between, wrap_angle


def texture(shared_data, name="gazebo_models_ccby3/robocup09_spl_field__carpet.jpg") -> np.ndarray:
    img = cv2.imread(str(shared_data / "textures" / name), cv2.IMREAD_GRAYSCALE)
    assert img is not None, name
    return img


def synthetic_texture(size=1024, seed=0) -> np.ndarray:
    """Band-limited random texture (multi-scale noise): always available, no data files."""
    rng = np.random.default_rng(seed)
    acc = np.zeros((size, size), np.float32)
    for scale, weight in ((4, 1.0), (16, 0.7), (64, 0.5)):
        n = rng.normal(0, 1, (size // scale + 2, size // scale + 2)).astype(np.float32)
        acc += weight * cv2.resize(n, (size, size), interpolation=cv2.INTER_CUBIC)[:size, :size]
    acc = cv2.GaussianBlur(acc, (0, 0), 1.0)
    return np.clip(128 + 40 * acc / acc.std(), 0, 255).astype(np.uint8)


class FloorRenderer:
    """Render camera views of `tex` laid on the floor, `m_per_texel` metres per texel, texel (0, 0) at world
    (x0, y0); columns grow along +x, rows along -y."""

    def __init__(self, camera: CameraModel, tex: np.ndarray, m_per_texel: float, origin=(-0.5, 0.5)):
        self.camera, self.tex, self.s, self.origin = camera, tex, m_per_texel, np.asarray(origin, float)
        u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
        self._base = camera.pixel_to_floor(np.column_stack([u.ravel(), v.ravel()]))

    def render(self, pose) -> np.ndarray:
        # element-wise rather than a (N, 2) @ (2, 2) matmul: multi-threaded BLAS on a busy machine is very slow
        x, y, th = (float(v) for v in pose)
        c, s = np.cos(th), np.sin(th)
        bx, by = self._base[:, 0], self._base[:, 1]
        w = np.column_stack([x + c * bx - s * by, y + s * bx + c * by])
        col = (w[:, 0] - self.origin[0]) / self.s
        row = (self.origin[1] - w[:, 1]) / self.s
        shape = (self.camera.height, self.camera.width)
        return cv2.remap(self.tex, col.reshape(shape).astype(np.float32), row.reshape(shape).astype(np.float32),
                         cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT_101)


def camera(distortion=(0.0, 0.0, 0.0, 0.0, 0.0), mount=(0.0, 0.0, 0.0), size=(640, 480)) -> CameraModel:
    w, h = size
    f = 500.0 * w / 640
    return CameraModel(width=w, height=h, fx=f, fy=f, cx=(w - 1) / 2, cy=(h - 1) / 2, distortion=distortion,
                       camera_height=0.5, mount=mount)


def step_errors(ests: list, gt: np.ndarray, frames: list[int]) -> np.ndarray:
    """|error| (x, y, theta) of each VO step `ests[k].delta` against the true motion from frame frames[k-1] to
    frames[k] (`gt`: true planar poses per frame)."""
    idx = np.asarray(frames)
    e = np.array([est.delta for est in ests[1:]]) - between(gt[idx[:-1]], gt[idx[1:]])
    e[:, 2] = wrap_angle(e[:, 2])
    return np.abs(e)
