"""BRIEF (Calonder et al. 2010) with a rotatable test pattern, vectorised over keypoints.

OpenCV's contrib BRIEF is not in our build. The pattern is 256 point pairs drawn once from an isotropic Gaussian
(sigma = S/5, clipped to the S x S patch; BRIEF's G II) with a fixed seed; each bit compares two pixels of the
Gaussian-smoothed image. Rotating the pattern by theta (BRIEFROT) is what a keypoint seen in an image rotated by
-theta would give with the plain pattern.
"""
from __future__ import annotations

import cv2
import numpy as np

N_BITS = 256


def brief_pattern(patch: int, seed: int, n_bits: int = N_BITS) -> np.ndarray:
    """(n_bits, 2, 2) float test-point offsets (x, y) in pixels, centred on the keypoint."""
    rng = np.random.default_rng(seed)
    half = patch / 2.0 - 1.0
    pts = np.clip(rng.normal(0.0, patch / 5.0, size=(n_bits, 2, 2)), -half, half)
    return pts


def rotated_offsets(pattern: np.ndarray, angle_deg: float) -> np.ndarray:
    """Integer offsets of the pattern rotated counter-clockwise (in image coordinates, y down) by angle_deg."""
    a = np.deg2rad(angle_deg)
    c, s = np.cos(a), np.sin(a)
    x, y = pattern[..., 0], pattern[..., 1]
    rot = np.stack([c * x + s * y, -s * x + c * y], axis=-1)
    return np.rint(rot).astype(np.int32)


def pattern_radius(pattern: np.ndarray) -> int:
    """Largest distance of a test point from the centre: keypoints closer to the border are dropped (for every
    angle, so the three BRIEFROT descriptor sets describe the same keypoints)."""
    return int(np.ceil(np.linalg.norm(pattern, axis=-1).max())) + 1


def smooth_for_brief(gray: np.ndarray, sigma: float) -> np.ndarray:
    return cv2.GaussianBlur(gray, (0, 0), sigma) if sigma > 0 else gray


def brief_describe(smoothed: np.ndarray, xy: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """BRIEF bits at integer keypoint positions xy (N, 2) -> (N, n_bits/8) uint8, bit i = I(p1_i) < I(p2_i).
    The caller guarantees that every test point lies inside the image."""
    x = xy[:, 0:1].astype(np.int32)
    y = xy[:, 1:2].astype(np.int32)
    a = smoothed[y + offsets[None, :, 0, 1], x + offsets[None, :, 0, 0]]
    b = smoothed[y + offsets[None, :, 1, 1], x + offsets[None, :, 1, 0]]
    return np.packbits(a < b, axis=1)


def inside(xy: np.ndarray, shape: tuple[int, int], radius: int) -> np.ndarray:
    h, w = shape[:2]
    return (xy[:, 0] >= radius) & (xy[:, 0] < w - radius) & (xy[:, 1] >= radius) & (xy[:, 1] < h - radius)
