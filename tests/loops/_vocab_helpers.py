"""Synthetic textured images for the vocabulary tests (fast, deterministic)."""
from __future__ import annotations

import cv2
import numpy as np


def texture(seed: int, h: int = 160, w: int = 200, color: bool = True) -> np.ndarray:
    """A random scene of blurred noise plus filled shapes: plenty of FAST corners, distinct per seed."""
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.random((h, w, 3)).astype(np.float32), (0, 0), 2.0)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    for _ in range(25):
        c = tuple(int(v) for v in rng.integers(0, 256, 3))
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        if rng.random() < 0.5:
            cv2.rectangle(img, (x, y), (x + int(rng.integers(6, 30)), y + int(rng.integers(6, 30))), c, -1)
        else:
            cv2.circle(img, (x, y), int(rng.integers(3, 12)), c, -1)
    return img if color else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


def perturb(img: np.ndarray, seed: int, shift: int = 3, noise: float = 4.0) -> np.ndarray:
    """The same place seen again: a small translation and sensor noise."""
    rng = np.random.default_rng(seed)
    m = np.float32([[1, 0, shift], [0, 1, -shift]])
    out = cv2.warpAffine(img, m, (img.shape[1], img.shape[0]), borderMode=cv2.BORDER_REFLECT)
    return np.clip(out.astype(np.float32) + rng.normal(0, noise, out.shape), 0, 255).astype(np.uint8)
