"""The naive visual-odometry baseline benchmarks put beside ours: ORB between consecutive frames, Lowe's ratio test,
cv2.estimateAffinePartial2D with RANSAC on the matched points back-projected onto the floor, chained."""
from __future__ import annotations

import cv2
import numpy as np

from odometry.shared.poses import compose, from_matrix

N_FEATURES = 2000       # ORB keypoints per frame
RATIO = 0.8             # Lowe's ratio test
RANSAC_M = 0.005        # inlier distance on the floor (m): about 5 px at the default camera's 1 mm/px


def orb_affine_chain(seq, n_features: int = N_FEATURES, ratio: float = RATIO) -> np.ndarray:
    """(N, 3) planar poses x, y, theta of the camera chained from consecutive-frame floor motions. A pair with too
    few matches or no RANSAC model repeats the previous motion (the chain never breaks)."""
    camera = seq.require_camera()
    orb = cv2.ORB_create(n_features)
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    poses = [np.zeros(3)]
    step = np.zeros(3)
    prev = orb.detectAndCompute(seq.image(0, gray=True), None)
    for i in range(1, len(seq)):
        cur = orb.detectAndCompute(seq.image(i, gray=True), None)
        motion = _floor_motion(camera, bf, prev, cur, ratio)
        step = step if motion is None else motion
        poses.append(compose(poses[-1], step))
        prev = cur
    return np.array(poses)


def _floor_motion(camera, bf, prev, cur, ratio: float) -> np.ndarray | None:
    """Planar motion of the camera from the previous frame to the current one, or None."""
    (kp0, d0), (kp1, d1) = prev, cur
    if d0 is None or d1 is None or len(kp0) < 3 or len(kp1) < 3:
        return None
    pairs = [p for p in bf.knnMatch(d0, d1, k=2) if len(p) == 2 and p[0].distance < ratio * p[1].distance]
    if len(pairs) < 3:
        return None
    a = camera.pixel_to_floor(np.array([kp0[p[0].queryIdx].pt for p in pairs]))
    b = camera.pixel_to_floor(np.array([kp1[p[0].trainIdx].pt for p in pairs]))
    m, inl = cv2.estimateAffinePartial2D(b, a, method=cv2.RANSAC, ransacReprojThreshold=RANSAC_M)
    if m is None:
        return None
    # m maps floor points seen from the current camera into the previous camera's frame: the camera's motion
    s = np.hypot(m[0, 0], m[1, 0])
    rigid = np.array([[m[0, 0] / s, m[0, 1] / s, m[0, 2]], [m[1, 0] / s, m[1, 1] / s, m[1, 2]], [0, 0, 1]])
    return from_matrix(rigid)


