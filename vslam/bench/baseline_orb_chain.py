"""The naive visual-odometry baseline the benchmarks put beside ours, and the planar ATE they report it with:
ORB(2000) between consecutive frames, Lowe's ratio test 0.8, cv2.estimateAffinePartial2D (RANSAC) on the pixels,
the image similarity turned into a floor motion through the camera, chained."""
from __future__ import annotations

import time

import cv2
import numpy as np

from odometry.rigid import kabsch_2d
from odometry.shared.poses import compose


def naive_orb_chain(seq, cam) -> tuple[np.ndarray, int, float]:
    """ORB(2000) + ratio 0.8 + estimateAffinePartial2D between consecutive frames. Returns poses, the number of
    pairs it tracked and its median seconds per frame."""
    orb = cv2.ORB_create(nfeatures=2000)
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    w, h = cam.size
    grid = np.array([[u, v] for u in np.linspace(0, w - 1, 5) for v in np.linspace(0, h - 1, 4)], float)
    poses, ok, secs = [np.zeros(3)], 0, []
    prev = None
    for i in range(len(seq)):
        img = seq.image(i, gray=True)
        t0 = time.perf_counter()
        cur = orb.detectAndCompute(img, None) if img is not None else (None, None)
        motion = np.zeros(3)
        if i > 0 and prev is not None and prev[1] is not None and cur[1] is not None:
            good = [p[0] for p in bf.knnMatch(cur[1], prev[1], k=2) if len(p) == 2 and p[0].distance < 0.8 * p[1].distance]
            if len(good) >= 3:
                a = np.float32([cur[0][g.queryIdx].pt for g in good])
                b = np.float32([prev[0][g.trainIdx].pt for g in good])
                m, _ = cv2.estimateAffinePartial2D(a, b, method=cv2.RANSAC, ransacReprojThreshold=3.0)
                if m is not None:
                    # the image similarity cur -> prev, as a planar motion: floor points of a pixel grid
                    mapped = grid @ m[:, :2].T + m[:, 2]
                    motion = kabsch_2d(cam.pixel_to_floor(grid), cam.pixel_to_floor(mapped))
                    ok += 1
        if i > 0:
            secs.append(time.perf_counter() - t0)
            poses.append(compose(poses[-1], motion))
        prev = cur
    return np.asarray(poses), ok, float(np.median(secs)) if secs else float("nan")


def planar_ate(est: np.ndarray, gt: np.ndarray) -> float:
    """RMS position error after the best planar rigid alignment (Kabsch on positions)."""
    a = est[:, :2] - est[:, :2].mean(0)
    b = gt[:, :2] - gt[:, :2].mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    r = vt.T @ np.diag([1.0, d]) @ u.T
    return float(np.sqrt(np.mean(np.sum((a @ r.T - b) ** 2, axis=1))))
