"""Image front end of the downward VO: input checks, photometric normalisation, corner detection, LK tracking.

Why these choices (measured by `vslam bench odometry`, see docs/benchmarks.md): ORB detectAndCompute alone costs more
than the whole frame budget at 640x480, and its keypoints are about 6x less precise than LK's (inlier RMS
0.64 px against 0.10 px). Instead, corners are detected only when a keyframe starts (Shi-Tomasi on a
half-resolution image, spread over a grid). Every frame tracks the keyframe's corners directly with Lucas-Kanade,
started from the motion prediction: sub-pixel, about half a millisecond, and no drift between keyframes because
the template is always the keyframe. A pyramid is used only when the prediction turns out wrong.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from odometry.errors import OdometryError


class BadImage(OdometryError):
    """A frame that cannot be used (missing, wrong size or type, non-finite, constant)."""


def to_gray(image: np.ndarray | None, size: tuple[int, int] | None = None) -> np.ndarray:
    """Validate a frame and return it as a contiguous uint8 grey image; raises BadImage with the reason."""
    if image is None:
        raise BadImage("no image (missing or undecodable frame)")
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        if img.dtype != np.uint8:
            img = _to_uint8(img)
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    elif img.ndim != 2:
        raise BadImage(f"image has shape {img.shape}; expected HxW or HxWx3")
    if img.dtype != np.uint8:
        img = _to_uint8(img)
    if size is not None and (img.shape[1], img.shape[0]) != tuple(size):
        raise BadImage(f"image is {img.shape[1]}x{img.shape[0]}, the camera is {size[0]}x{size[1]}")
    return np.ascontiguousarray(img)


def _to_uint8(img: np.ndarray) -> np.ndarray:
    if not np.issubdtype(img.dtype, np.number):
        raise BadImage(f"image dtype {img.dtype} is not numeric")
    f = img.astype(np.float32)
    if not np.all(np.isfinite(f)):
        raise BadImage("image has NaN or infinite pixels")
    if img.dtype == np.uint16:
        f = f / 257.0
    elif np.issubdtype(img.dtype, np.floating) and f.max() <= 1.0:
        f = f * 255.0
    return np.clip(f, 0, 255).astype(np.uint8)


def contrast(gray: np.ndarray) -> float:
    """Standard deviation of a subsampled image: ~0 for blank or saturated frames."""
    return float(cv2.meanStdDev(gray[::4, ::4])[1][0, 0])


def normalize(gray: np.ndarray, target_std: float = 40.0) -> np.ndarray:
    """Gain/offset normalisation (mean 128, fixed spread) so LK's brightness constancy survives lighting changes."""
    mean, std = cv2.meanStdDev(gray[::4, ::4])
    s = float(std[0, 0])
    alpha = target_std / max(s, 1e-3)
    return cv2.convertScaleAbs(gray, alpha=alpha, beta=128.0 - alpha * float(mean[0, 0]))


def normalize_local(gray: np.ndarray, radius: int = 8, target_std: float = 40.0) -> np.ndarray:
    """Local contrast normalisation: (I - local mean) / local std over a (2 radius + 1)^2 box.

    Vignetting and uneven light are smooth multiplicative/additive fields that stay put in the image while the
    floor moves under them; LK's brightness constancy then breaks, biasing the flow (the more, the weaker the
    texture). Dividing them out locally makes LK's template match again.
    """
    f = gray.astype(np.float32)
    k = (2 * radius + 1, 2 * radius + 1)
    mu = cv2.boxFilter(f, -1, k, borderType=cv2.BORDER_REFLECT)
    var = cv2.boxFilter(f * f, -1, k, borderType=cv2.BORDER_REFLECT) - mu * mu
    out = (f - mu) * (target_std / np.sqrt(np.maximum(var, 4.0))) + 128.0
    return np.clip(out, 0, 255).astype(np.uint8)


def highpass(gray: np.ndarray, radius: int = 8, target_std: float = 40.0) -> np.ndarray:
    """I - box mean(I) over a (2 radius + 1)^2 window, rescaled to a fixed spread around 128 (uint8 throughout,
    ~10x cheaper than `normalize_local`): removes smooth additive light fields and the low-frequency part of
    vignetting, which stay put in the image while the floor moves under them."""
    k = 2 * radius + 1
    mean = cv2.blur(gray, (k, k), borderType=cv2.BORDER_REFLECT)
    sub = gray[::4, ::4].astype(np.float32) - mean[::4, ::4]
    alpha = target_std / max(float(sub.std()), 1e-3)
    return cv2.addWeighted(gray, alpha, mean, -alpha, 128.0)


def detect_corners(gray: np.ndarray, max_corners: int, grid: tuple[int, int], quality: float, min_distance: float,
                   border: int, half_resolution: bool = True) -> np.ndarray:
    """Shi-Tomasi corners spread over a grid: at most ceil(max / cells) per cell, strongest first.

    Detection runs on a half-resolution image when `half_resolution` (4x fewer pixels); the positions are mapped
    back to full resolution, where LK refines them implicitly (a keyframe point is just a patch centre).
    Returns (N, 2) float32 pixel coordinates, inside the image by `border` pixels.
    """
    h, w = gray.shape
    scale = 2.0 if half_resolution else 1.0
    img = cv2.pyrDown(gray) if half_resolution else gray
    pts = cv2.goodFeaturesToTrack(img, maxCorners=max_corners * 3, qualityLevel=quality,
                                  minDistance=max(1.0, min_distance / scale), blockSize=3)
    if pts is None:
        return np.zeros((0, 2), np.float32)
    pts = pts.reshape(-1, 2) * scale + (scale - 1.0) * 0.5  # pyrDown pixel centres
    inside = ((pts[:, 0] >= border) & (pts[:, 0] < w - border) & (pts[:, 1] >= border) & (pts[:, 1] < h - border))
    pts = pts[inside]
    # goodFeaturesToTrack returns corners strongest first: keep the first `per_cell` of each cell
    gx, gy = grid
    cell = (np.minimum((pts[:, 1] * gy / h).astype(int), gy - 1) * gx
            + np.minimum((pts[:, 0] * gx / w).astype(int), gx - 1))
    per_cell = max(1, math.ceil(max_corners / (gx * gy)))
    order = np.argsort(cell, kind="stable")
    sc = cell[order]
    first = np.searchsorted(sc, sc, side="left")
    rank = np.arange(len(sc)) - first
    keep = order[rank < per_cell]
    keep.sort()  # back to strength order
    return np.ascontiguousarray(pts[keep][:max_corners], dtype=np.float32)


def track_lk(prev: np.ndarray, cur: np.ndarray, pts: np.ndarray, guess: np.ndarray | None, window: int,
             levels: int, iterations: int, epsilon: float, min_eig: float) -> tuple[np.ndarray, np.ndarray]:
    """Pyramidal Lucas-Kanade from `prev` to `cur`, started at `guess` (predicted positions) when given.

    Returns (tracked (N, 2) float32, ok (N,) bool); points that left the image are not ok.
    """
    if len(pts) == 0:
        return np.zeros((0, 2), np.float32), np.zeros(0, bool)
    p0 = np.ascontiguousarray(pts, dtype=np.float32).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, epsilon)
    flags = 0
    p1 = None
    if guess is not None:
        p1 = np.ascontiguousarray(guess, dtype=np.float32).reshape(-1, 1, 2).copy()
        flags = cv2.OPTFLOW_USE_INITIAL_FLOW
    p1, st, _ = cv2.calcOpticalFlowPyrLK(prev, cur, p0, p1, winSize=(window, window), maxLevel=levels,
                                         criteria=crit, flags=flags, minEigThreshold=min_eig)
    p1 = p1.reshape(-1, 2)
    h, w = cur.shape
    ok = (st.reshape(-1) == 1) & np.all(np.isfinite(p1), axis=1)
    ok &= (p1[:, 0] >= 0) & (p1[:, 0] <= w - 1) & (p1[:, 1] >= 0) & (p1[:, 1] <= h - 1)
    return p1, ok


def _coarse(gray: np.ndarray) -> np.ndarray:
    return cv2.pyrDown(cv2.pyrDown(gray)).astype(np.float32)


def coarse_shift(ref: np.ndarray, cur: np.ndarray) -> tuple[np.ndarray, float]:
    """Global image translation ref -> cur by phase correlation at quarter resolution (full-res pixels).

    A motion prior for LK when there is none (first frames without odometry, recovery after a failure).
    Returns (shift (2,), response in [0, 1]; low responses mean no clear peak).
    """
    a, b = _coarse(ref), _coarse(cur)
    win = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate(a, b, win)
    return np.array([dx * 4.0, dy * 4.0]), float(response)



def structure_tensors(gray: np.ndarray, window: int) -> np.ndarray:
    """(3, H, W) the structure tensor (gx gx, gx gy, gy gy) of every pixel summed over an LK window (box mean);
    computed once per template image, then looked up at its points by `aperture_weights`."""
    g = gray.astype(np.float32)
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3)
    k = (int(window), int(window))
    return np.stack([cv2.boxFilter(gx * gx, -1, k), cv2.boxFilter(gx * gy, -1, k), cv2.boxFilter(gy * gy, -1, k)])


def aperture_weights(tensors: np.ndarray, pts: np.ndarray, floor: float = 0.05) -> np.ndarray:
    """(N, 2, 2) shape of each point's LK information in floor axes (x = u, y = -v): its structure tensor over the
    LK window (`structure_tensors`) divided by half its trace, so every point weighs 1 on average and an
    edge-like window (the aperture problem: LK fixes only the component across the edge) weighs little along
    the edge. Eigenvalues are kept above `floor` (an edge still says a little along itself: its ends)."""
    p = np.rint(np.asarray(pts, float)).astype(int).reshape(-1, 2)
    p[:, 0] = np.clip(p[:, 0], 0, tensors.shape[2] - 1)
    p[:, 1] = np.clip(p[:, 1], 0, tensors.shape[1] - 1)
    a, b, c = (tensors[k][p[:, 1], p[:, 0]].astype(float) for k in range(3))
    b = -b   # y = -v flips the cross term
    half = np.maximum((a + c) / 2.0, 1e-12)
    w = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2) / half[:, None, None]
    vals, vecs = np.linalg.eigh(w)
    return np.einsum("nij,nj,nkj->nik", vecs, np.maximum(vals, floor), vecs)
