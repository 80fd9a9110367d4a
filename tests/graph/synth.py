"""Small synthetic planar pose graphs with known truth, for the graph tests."""
from __future__ import annotations

import numpy as np

from graph import PoseGraphData
from odometry.shared.poses import between, compose, integrate


def square_laps(laps: int = 2, side: int = 5, step: float = 1.0) -> np.ndarray:
    """True poses (N, 3) driving `laps` times around a square of `side` steps per edge (turning on the spot)."""
    motions = []
    for _ in range(laps):
        for _ in range(4):
            motions += [[step, 0.0, 0.0]] * (side - 1) + [[step, 0.0, np.pi / 2]]
    return integrate(np.asarray(motions))


def noisy_graph(truth: np.ndarray, rng: np.random.Generator, sigma_xy: float = 0.02, sigma_th: float = 0.01,
                loop_every: int = 1, ids: np.ndarray | None = None) -> tuple[PoseGraphData, np.ndarray]:
    """Odometry between consecutive poses and loops between revisits of the same place (same position, later lap),
    all with Gaussian noise of the stated sigmas. Returns (graph, true poses)."""
    n = len(truth)
    ids = np.arange(n) if ids is None else np.asarray(ids)
    cov = np.diag([sigma_xy ** 2, sigma_xy ** 2, sigma_th ** 2])
    info = np.linalg.inv(cov)
    noise = lambda m: rng.normal(0.0, [sigma_xy, sigma_xy, sigma_th], size=(m, 3))   # noqa: E731
    odo = between(truth[:-1], truth[1:])
    z_odo = compose(odo, noise(len(odo)))
    pairs = []
    for j in range(n):
        for i in range(j - 2):
            if np.linalg.norm(truth[i, :2] - truth[j, :2]) < 1e-6:
                pairs.append((i, j))
    pairs = pairs[::loop_every]
    pi = np.array([p[0] for p in pairs], int)
    pj = np.array([p[1] for p in pairs], int)
    z_loop = compose(between(truth[pj], truth[pi]), noise(len(pairs)))     # loops point newer -> older
    guess = integrate(z_odo)
    m = len(odo) + len(pairs)
    data = PoseGraphData(2, ids, guess, np.concatenate([ids[:-1], ids[pj]]), np.concatenate([ids[1:], ids[pi]]),
                         np.vstack([z_odo, z_loop]), np.broadcast_to(info, (m, 3, 3)).copy(),
                         np.concatenate([np.zeros(len(odo), bool), np.ones(len(pairs), bool)]), np.ones(m))
    data.probability[data.is_loop] = np.nan
    return data, truth


def ate(ref: np.ndarray, est: np.ndarray) -> float:
    """RMSE of planar positions after a rigid 2D alignment."""
    x, y = est[:, :2], ref[:, :2]
    mx, my = x.mean(0), y.mean(0)
    u, _, vt = np.linalg.svd((y - my).T @ (x - mx))
    d = np.diag([1.0, np.sign(np.linalg.det(u @ vt))])
    r = u @ d @ vt
    return float(np.sqrt(np.mean(np.sum((y - ((x - mx) @ r.T + my)) ** 2, axis=1))))
