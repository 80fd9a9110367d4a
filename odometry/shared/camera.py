"""Camera model and floor geometry: the one place for pinhole + distortion and pixel <-> floor mapping.

Conventions (DESIGN.md): the downward camera frame has x forward (image u), y to the right (image v),
z down (optical axis). With mount yaw 0 the floor point seen at undistorted pixel (u, v) is, in the robot
base frame, mount_xy + R(mount_yaw) [(u - cx) h / fx, -(v - cy) h / fy], h = camera_height.
An optional small tilt (roll about the camera x axis, pitch about its y axis) rotates the viewing rays
before they meet the floor.

All functions take and return (N, 2) float arrays and are vectorised.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from odometry.shared.poses import rot2
from odometry.shared.rotations import tilt_matrix

# Newton iterations for undistortion: OpenCV's default of 5 leaves ~0.1 px error with strong distortion.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-12)


@dataclass(frozen=True)
class CameraModel:
    """Pinhole camera with radial-tangential distortion (OpenCV order k1 k2 p1 p2 k3).

    `camera_height` (metres, optical centre above the floor) is set for a downward-facing camera and None
    otherwise; `mount` is the optical centre (x, y) and yaw in the robot base frame; `tilt` is (roll, pitch)
    in radians, zero for a perfectly downward camera.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    camera_height: float | None = None
    mount: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tilt: tuple[float, float] = (0.0, 0.0)
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        if self.camera_height is not None:
            object.__setattr__(self, "camera_height", float(self.camera_height))
        for name in ("fx", "fy", "cx", "cy"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"camera {name} must be finite, got {v}")
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"camera focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        if self.width <= 0 or self.height <= 0:
            raise ValueError(f"camera image size must be positive, got {self.width}x{self.height}")
        if len(self.distortion) != 5 or not all(math.isfinite(d) for d in self.distortion):
            raise ValueError(f"camera distortion must be 5 finite numbers (k1 k2 p1 p2 k3), got {self.distortion}")
        if self.camera_height is not None and not (self.camera_height > 0 and math.isfinite(self.camera_height)):
            raise ValueError(f"camera_height must be a positive number of metres, got {self.camera_height}")
        if len(self.mount) != 3 or len(self.tilt) != 2:
            raise ValueError("camera mount must be [x, y, yaw] and tilt [roll, pitch]")
        # normalise to plain floats so equality and serialisation are exact
        object.__setattr__(self, "distortion", tuple(float(d) for d in self.distortion))
        object.__setattr__(self, "mount", tuple(float(m) for m in self.mount))
        object.__setattr__(self, "tilt", tuple(float(t) for t in self.tilt))

    # ------------------------------------------------------------------ basics
    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist(self) -> np.ndarray:
        return np.asarray(self.distortion, dtype=float)

    @property
    def has_distortion(self) -> bool:
        return any(d != 0.0 for d in self.distortion)

    @property
    def is_downward(self) -> bool:
        return self.camera_height is not None

    @property
    def size(self) -> tuple[int, int]:
        return self.width, self.height

    def scaled(self, factor: float) -> "CameraModel":
        """The same camera for an image resized by `factor` (pixel-centre convention of cv2.resize)."""
        return replace(self, width=int(round(self.width * factor)), height=int(round(self.height * factor)),
                       fx=self.fx * factor, fy=self.fy * factor,
                       cx=(self.cx + 0.5) * factor - 0.5, cy=(self.cy + 0.5) * factor - 0.5)

    # ------------------------------------------------------------------ pixels <-> normalised rays
    def normalize(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) -> undistorted normalised coordinates (N, 2)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        if not self.has_distortion:
            return np.column_stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy])
        if len(uv) == 0:
            return np.zeros((0, 2))
        return cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, self.dist, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)

    def denormalize(self, xn: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (N, 2) -> distorted pixels (N, 2)."""
        xn = np.asarray(xn, dtype=np.float64).reshape(-1, 2)
        x, y = xn[:, 0], xn[:, 1]
        if self.has_distortion:
            k1, k2, p1, p2, k3 = self.distortion
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
            x, y = xd, yd
        return np.column_stack([self.fx * x + self.cx, self.fy * y + self.cy])

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels -> undistorted pixels of the same pinhole K."""
        xn = self.normalize(uv)
        return np.column_stack([self.fx * xn[:, 0] + self.cx, self.fy * xn[:, 1] + self.cy])

    # ------------------------------------------------------------------ floor plane
    def _tilt_matrix(self) -> np.ndarray:
        return tilt_matrix(*self.tilt)

    def _require_height(self) -> float:
        if self.camera_height is None:
            raise ValueError("this camera has no camera_height: floor mapping needs a downward-facing camera")
        return self.camera_height

    def rays_to_floor(self, xn: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (N, 2) -> floor points (N, 2) in the robot base frame."""
        h = self._require_height()
        xn = np.asarray(xn, dtype=np.float64).reshape(-1, 2)
        if self.tilt == (0.0, 0.0):
            cam = xn * h
        else:
            d = np.column_stack([xn, np.ones(len(xn))]) @ self._tilt_matrix().T
            if np.any(d[:, 2] <= 1e-9):
                raise ValueError("a viewing ray does not meet the floor (tilt too large)")
            cam = d[:, :2] * (h / d[:, 2:3])
        # camera FRD (x forward, y right) -> base (x forward, y left), then the mount
        local = np.column_stack([cam[:, 0], -cam[:, 1]])
        mx, my, myaw = self.mount
        if myaw != 0.0:
            local = local @ rot2(myaw).T
        return local + np.array([mx, my])

    def rays_to_floor_batch(self, xn: np.ndarray, heights: np.ndarray, tilts: np.ndarray) -> np.ndarray:
        """Floor points (K, N, 2) of rays xn (N, 2) for K hypotheses of camera height (K,) and tilt (K, 2).

        The same mapping as `rays_to_floor` with `camera_height` and `tilt` replaced, vectorised over the
        hypotheses: what an estimator of the camera's momentary height and tilt needs (robots pitch and bounce).
        """
        xn = np.asarray(xn, dtype=np.float64).reshape(-1, 2)
        heights = np.asarray(heights, dtype=np.float64).reshape(-1)
        tilts = np.asarray(tilts, dtype=np.float64).reshape(-1, 2)
        cr, sr = np.cos(tilts[:, 0]), np.sin(tilts[:, 0])
        cp, sp = np.cos(tilts[:, 1]), np.sin(tilts[:, 1])
        z = np.zeros_like(cr)
        # tilt_matrix(roll, pitch) = Ry(pitch) Rx(roll), for all hypotheses at once
        rots = np.stack([np.stack([cp, sp * sr, sp * cr], -1), np.stack([z, cr, -sr], -1),
                         np.stack([-sp, cp * sr, cp * cr], -1)], -2)                  # (K, 3, 3)
        d = np.column_stack([xn, np.ones(len(xn))]) @ np.swapaxes(rots, 1, 2)        # (K, N, 3)
        if np.any(d[..., 2] <= 1e-9):
            raise ValueError("a viewing ray does not meet the floor (tilt too large)")
        cam = d[..., :2] * (heights[:, None, None] / d[..., 2:3])
        local = np.stack([cam[..., 0], -cam[..., 1]], -1)
        mx, my, myaw = self.mount
        if myaw != 0.0:
            local = local @ rot2(myaw).T
        return local + np.array([mx, my])

    def floor_to_rays(self, xy: np.ndarray) -> np.ndarray:
        """Floor points (N, 2) in the base frame -> undistorted normalised coordinates (N, 2)."""
        h = self._require_height()
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        mx, my, myaw = self.mount
        local = xy - np.array([mx, my])
        if myaw != 0.0:
            local = local @ rot2(-myaw).T
        cam = np.column_stack([local[:, 0], -local[:, 1], np.full(len(local), h)])
        if self.tilt != (0.0, 0.0):
            cam = cam @ self._tilt_matrix()  # R^T applied to row vectors
        return cam[:, :2] / cam[:, 2:3]

    def pixel_to_floor(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) -> floor points (N, 2) in metres in the robot base frame."""
        return self.rays_to_floor(self.normalize(uv))

    def floor_to_pixel(self, xy: np.ndarray) -> np.ndarray:
        """Floor points (N, 2) in the base frame -> distorted pixels (N, 2)."""
        return self.denormalize(self.floor_to_rays(xy))

    def footprint(self, samples_per_side: int = 8) -> np.ndarray:
        """The image border mapped onto the floor: a polygon (M, 2) in the base frame, counter-clockwise.

        The border is sampled `samples_per_side` times per edge so that distortion bends the outline.
        Pixel edges (-0.5 ... width - 0.5) are used, so the polygon covers the whole image.
        """
        key = ("footprint", samples_per_side)
        if key not in self._cache:
            n = max(1, samples_per_side)
            u0, u1, v0, v1 = -0.5, self.width - 0.5, -0.5, self.height - 0.5
            t = np.linspace(0.0, 1.0, n, endpoint=False)
            border = np.concatenate([
                np.column_stack([u0 + (u1 - u0) * t, np.full(n, v0)]),
                np.column_stack([np.full(n, u1), v0 + (v1 - v0) * t]),
                np.column_stack([u1 - (u1 - u0) * t, np.full(n, v1)]),
                np.column_stack([np.full(n, u0), v1 - (v1 - v0) * t]),
            ])
            poly = self.pixel_to_floor(border)
            x, y = poly[:, 0], poly[:, 1]
            if 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0:  # make it counter-clockwise
                poly = poly[::-1].copy()
            poly.setflags(write=False)
            self._cache[key] = poly
        return self._cache[key]

    def ground_resolution(self) -> float:
        """Metres per pixel at the image centre (downward camera)."""
        return self._require_height() / math.sqrt(self.fx * self.fy)

    # ------------------------------------------------------------------ (de)serialisation
    REQUIRED = ("width", "height", "fx", "fy", "cx", "cy")

    def to_dict(self) -> dict:
        d = {"width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy, "cx": self.cx,
             "cy": self.cy, "distortion": list(self.distortion)}
        if self.camera_height is not None:
            d["camera_height"] = self.camera_height
        d["mount"] = list(self.mount)
        if self.tilt != (0.0, 0.0):
            d["tilt"] = list(self.tilt)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "CameraModel":
        """Build from camera.yaml keys; raises KeyError naming a missing field and ValueError for bad values."""
        missing = [k for k in cls.REQUIRED if k not in d]
        if missing:
            raise KeyError(missing[0])
        dist = d.get("distortion", [0.0] * 5)
        if dist is None:
            dist = [0.0] * 5
        dist = list(dist) + [0.0] * (5 - len(dist)) if len(dist) in (4, 5) else dist
        return cls(width=int(d["width"]), height=int(d["height"]), fx=float(d["fx"]), fy=float(d["fy"]),
                   cx=float(d["cx"]), cy=float(d["cy"]), distortion=tuple(float(x) for x in dist),
                   camera_height=None if d.get("camera_height") is None else float(d["camera_height"]),
                   mount=tuple(float(x) for x in d.get("mount", (0.0, 0.0, 0.0))),
                   tilt=tuple(float(x) for x in d.get("tilt", (0.0, 0.0))))
