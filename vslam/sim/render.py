"""Render what the downward camera sees of a procedural floor, with the camera effects of a real robot.

The map from undistorted image pixels to floor pixels is one homography per frame (pinhole, small tilt, floor
plane, robot pose), so a frame is a `warpPerspective` of a floor window, then a fixed remap for lens distortion.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from odometry.shared.camera import CameraModel
from odometry.shared.config import Config, setting
from odometry.shared.poses import rot2, to_matrix
from odometry.shared.rotations import tilt_matrix
from vslam.errors import VslamError
from vslam.sim.floor import Floor


@dataclass(frozen=True)
class Effects(Config):
    """Camera effects; each can be switched off. Amplitudes are mild and realistic by default."""

    PRESETS = {"none": {"motion_blur": False, "lighting": False, "vignetting": False, "sensor_noise": False,
                        "wobble": False}}

    motion_blur: bool = True
    exposure: float = setting(0.008, range="[0, inf)", unit="s", doc="exposure time for motion blur")
    lighting: bool = True
    gain_amplitude: float = setting(0.15, range="[0, 1]", doc="slow global brightness change (+-)")
    gain_period: float = setting(23.0, range="(0, inf)", unit="s")
    light_gradient: float = setting(0.25, range="[0, inf)",
                                    doc="brightness gradient across the image from an off-centre light")
    vignetting: bool = True
    vignetting_strength: float = setting(0.30, range="[0, 1]")
    sensor_noise: bool = True
    noise_std: float = setting(2.0, range="[0, inf)", unit="grey levels", doc="plus shot noise")
    wobble: bool = True
    height_wobble: float = setting(0.002, range="[0, inf)", unit="m")
    tilt_wobble: float = setting(0.004, range="[0, inf)", unit="rad", doc="about 0.2 deg")
    dropped_frames: float = setting(0.0, range="[0, 1]", doc="probability per frame")
    corrupt_frames: float = setting(0.0, range="[0, 1]", doc="probability per frame")
    dropped_run: int = setting(1, range="[1, inf)", doc="frames lost at each drop (a run of dropped frames)")
    exposure_jumps: float = setting(0.0, range="[0, 1]", doc="probability per frame of an auto-exposure step")
    exposure_jump_size: float = setting(0.5, range="[0, inf)", doc="step of log gain, uniform in +-this")


def pixel_to_world_homography(camera: CameraModel, pose: np.ndarray, height: float, tilt: tuple[float, float]
                              ) -> np.ndarray:
    """3x3 H mapping undistorted pixels [u, v, 1] to world floor points (homogeneous), for a camera at `height`
    with `tilt` on a robot at planar `pose`. Same conventions as CameraModel.rays_to_floor."""
    K_inv = np.linalg.inv(camera.K)
    H_cam = np.diag([1.0, 1.0, 1.0 / height]) @ tilt_matrix(*tilt) @ K_inv   # -> camera FRD floor point
    flip = np.diag([1.0, -1.0, 1.0])                                          # FRD (y right) -> base (y left)
    mount = to_matrix(np.asarray(camera.mount))
    return to_matrix(np.asarray(pose, dtype=float)) @ mount @ flip @ H_cam


class FrameRenderer:
    def __init__(self, floor: Floor, camera: CameraModel, effects: Effects, seed: int = 0):
        if camera.camera_height is None:
            raise VslamError("the simulator needs a downward camera (camera_height)")
        self.floor = floor
        self.camera = camera
        self.effects = effects
        self.seed = seed
        self._noise_bank: np.ndarray | None = None
        w, h = camera.width, camera.height
        self._distort_maps = None
        if camera.has_distortion:
            uu, vv = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
            und = camera.undistort(np.column_stack([uu.ravel(), vv.ravel()]))
            self._distort_maps = (und[:, 0].reshape(h, w).astype(np.float32), und[:, 1].reshape(h, w).astype(np.float32))
        u = (np.arange(w, dtype=np.float32) - camera.cx) / w
        v = (np.arange(h, dtype=np.float32) - camera.cy) / h
        self._u, self._v = np.meshgrid(u, v)
        r2 = (self._u ** 2 + self._v ** 2) / 0.25
        self._vignette = (1.0 - effects.vignetting_strength * np.clip(r2, 0, 2) * 0.5).astype(np.float32)
        # extra undistorted margin so distortion and blur never sample outside the rendered window
        self._corners = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
        if self._distort_maps is not None:
            mx, my = self._distort_maps
            self._corners = np.array([[mx.min() - 1, my.min() - 1], [mx.max() + 1, my.min() - 1],
                                      [mx.max() + 1, my.max() + 1], [mx.min() - 1, my.max() + 1]])

    def _noise(self, shape: tuple, rng: np.random.Generator) -> np.ndarray:
        """Unit Gaussian noise for one frame: a window at a random offset into a bank drawn once (drawing 300k
        normals per frame was half the rendering time). Shifted noise cannot fake a consistent scene motion."""
        n = int(np.prod(shape))
        if self._noise_bank is None or len(self._noise_bank) < 2 * n:
            self._noise_bank = np.random.default_rng([self.seed, 0x5E5]).standard_normal(8 * n + 4096, dtype=np.float32)
        start = int(rng.integers(0, len(self._noise_bank) - n))
        return self._noise_bank[start:start + n].reshape(shape)

    def render(self, pose: np.ndarray, t: float, blur_px: np.ndarray | None = None,
               height: float | None = None, tilt: tuple[float, float] = (0.0, 0.0),
               rng: np.random.Generator | None = None) -> np.ndarray:
        """The uint8 image at planar `pose`. `blur_px` is the image-space motion over the exposure (2,)."""
        cam, fx = self.camera, self.effects
        h = cam.camera_height if height is None else height
        H = pixel_to_world_homography(cam, pose, h, tilt)
        res = self.floor.res
        corners = np.column_stack([self._corners, np.ones(4)]) @ H.T
        corners = corners[:, :2] / corners[:, 2:3]
        margin = 4 + (0 if blur_px is None else int(np.ceil(np.abs(blur_px).max())))
        c0 = int(math.floor(corners[:, 0].min() / res)) - margin
        r0 = int(math.floor(corners[:, 1].min() / res)) - margin
        c1 = int(math.ceil(corners[:, 0].max() / res)) + margin
        r1 = int(math.ceil(corners[:, 1].max() / res)) + margin
        canvas = self.floor.region(c0, r0, c1 - c0, r1 - r0)
        to_canvas = np.array([[1 / res, 0, -c0 - 0.5], [0, 1 / res, -r0 - 0.5], [0, 0, 1]])
        Hc = to_canvas @ H
        size = (cam.width, cam.height)
        if self._distort_maps is not None:
            # render the undistorted view over the range the distortion map samples, then apply the lens
            mx, my = self._distort_maps
            ox, oy = math.floor(mx.min()) - 2, math.floor(my.min()) - 2
            ow, oh = math.ceil(mx.max()) + 3 - ox, math.ceil(my.max()) + 3 - oy
            shift = np.array([[1, 0, ox], [0, 1, oy], [0, 0, 1]], dtype=float)
            und = cv2.warpPerspective(canvas, Hc @ shift, (ow, oh), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                      borderMode=cv2.BORDER_REPLICATE)
            if fx.motion_blur and blur_px is not None:
                und = _motion_blur(und, blur_px)
            img = cv2.remap(und, mx - ox, my - oy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        else:
            img = cv2.warpPerspective(canvas, Hc, size, flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                      borderMode=cv2.BORDER_REPLICATE)
            if fx.motion_blur and blur_px is not None:
                img = _motion_blur(img, blur_px)
        gain = None
        if fx.lighting:
            g = 1.0 + fx.gain_amplitude * math.sin(2 * math.pi * t / fx.gain_period + 0.7)
            # a light fixed in the world: its gradient turns in the image as the robot turns
            a = -pose[2] + 0.9
            gain = g * (1.0 + fx.light_gradient * (math.cos(a) * self._u + math.sin(a) * self._v))
        if fx.vignetting:
            gain = self._vignette if gain is None else gain * self._vignette
        if gain is not None:
            img = img * (gain if img.ndim == 2 else gain[..., None])
        if fx.sensor_noise and rng is not None:
            sd = np.sqrt(fx.noise_std ** 2 + 0.02 * np.clip(img, 0, 255))
            img = img + sd * self._noise(img.shape, rng)
        return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def _motion_blur(img: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Linear motion blur along image displacement d (2,) in pixels."""
    length = float(np.hypot(d[0], d[1]))
    if length < 0.75:
        return img
    n = int(math.ceil(length)) | 1
    k = np.zeros((n, n), np.float32)
    c = n // 2
    steps = max(2 * n, 8)
    for s in np.linspace(-0.5, 0.5, steps):
        x, y = c + s * d[0], c + s * d[1]
        x0, y0 = int(math.floor(x)), int(math.floor(y))
        fx_, fy_ = x - x0, y - y0
        for dx, dy, w in ((0, 0, (1 - fx_) * (1 - fy_)), (1, 0, fx_ * (1 - fy_)), (0, 1, (1 - fx_) * fy_), (1, 1, fx_ * fy_)):
            if 0 <= x0 + dx < n and 0 <= y0 + dy < n:
                k[y0 + dy, x0 + dx] += w
    k /= k.sum()
    return cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REPLICATE)


def image_motion(camera: CameraModel, pose_a: np.ndarray, pose_b: np.ndarray) -> np.ndarray:
    """Image displacement (2,) of the floor point seen at the image centre, from pose_a to pose_b."""
    centre = np.array([[camera.cx, camera.cy]])
    world = camera.pixel_to_floor(centre) @ rot2(pose_a[2]).T + pose_a[:2]
    local_b = (world - pose_b[:2]) @ rot2(pose_b[2])
    return (camera.floor_to_pixel(local_b) - centre)[0]
