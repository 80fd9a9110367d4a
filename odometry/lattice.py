"""The periods of a self-similar floor view (a printed photograph tiled): the floor translations under which the
view repeats, measured from its features matched against themselves. The VO's alias guard
(`VOConfig.alias_guard`) uses them to enumerate the copies of a motion a periodic floor cannot tell apart."""

from __future__ import annotations

import cv2
import numpy as np


def view_lattice(floor: np.ndarray, desc: np.ndarray, tol: float, min_step: float, min_count: int) -> np.ndarray:
    """(K, 2) lattice generators (floor units), K = 0 (not self-similar), 1 or 2.

    floor: (N, 2) the features' floor points; desc: (N, B) their binary descriptors; tol: how far apart two
    displacements may be and still be the same step (floor units, ~ the matcher's inlier distance); min_step:
    displacements shorter than this are the same corner at two octaves or along an edge, not a period; min_count:
    look-alike pairs a step needs. The displacements to each feature's nearest look-alikes (self excluded) scatter
    on an ordinary floor and pile up at the lattice steps on a periodic one."""
    none = np.zeros((0, 2))
    if len(desc) < min_count:
        return none
    knn = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(desc, desc, k=min(4, len(desc)))
    pairs = np.array([(m.queryIdx, m.trainIdx) for ms in knn for m in ms if m.trainIdx != m.queryIdx])
    if len(pairs) == 0:
        return none
    d = floor[pairs[:, 1]] - floor[pairs[:, 0]]
    d = d[np.hypot(d[:, 0], d[:, 1]) > min_step]
    found: list[np.ndarray] = []
    while len(d) >= min_count and len(found) < 2:
        keys, counts = np.unique(np.round(d / tol).astype(np.int64), axis=0, return_counts=True)
        centre = keys[np.argmax(counts)] * tol
        near = np.hypot(*(d - centre).T) <= 1.5 * tol
        if near.sum() < min_count:
            break
        p = d[near].mean(axis=0)
        found.append(p)
        # everything on its line (-p, 2p: the same generator) is done with; the next pile is a second generator
        d = d[np.abs(d[:, 0] * p[1] - d[:, 1] * p[0]) / float(np.hypot(*p)) > 1.5 * tol]
    return np.array(found).reshape(-1, 2)
