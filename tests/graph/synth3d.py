"""Small synthetic 3D pose graphs with known truth whose stated rotation and translation noise are off by different
factors (as sphere2500's and parking-garage's are), for the calibration tests."""
from __future__ import annotations

import gtsam
import numpy as np
from scipy.spatial.transform import Rotation

from graph import PoseGraphData


def _row(p: gtsam.Pose3) -> np.ndarray:
    return np.r_[p.translation(), Rotation.from_matrix(p.rotation().matrix()).as_quat()]


def laps(num_laps: int = 3, per_lap: int = 60, radius: float = 5.0) -> list[gtsam.Pose3]:
    """True poses driving `num_laps` times around a tilted circle (the same places every lap)."""
    out = []
    for k in range(num_laps * per_lap):
        t = 2.0 * np.pi * (k % per_lap) / per_lap
        rot = gtsam.Rot3.Ypr(t + np.pi / 2, 0.05 * np.sin(2 * t), 0.0)
        out.append(gtsam.Pose3(rot, gtsam.Point3(radius * np.cos(t), radius * np.sin(t), 0.5 * np.sin(t))))
    return out


def mis_stated_graph(rng: np.random.Generator, sigma_t: float = 0.02, sigma_r: float = 0.002,
                     stated_t: float = 10.0, stated_r: float = 2.0, num_false: int = 0, num_laps: int = 3,
                     per_lap: int = 60, local_offset: float | None = None,
                     ) -> tuple[PoseGraphData, list[gtsam.Pose3], np.ndarray]:
    """Odometry and loops (every pose to the same place one lap earlier) with noise of the true sigmas (m, rad), the
    information stating sigmas `stated_t` and `stated_r` times larger, and `num_false` false loops: between random
    poses more than a lap's quarter apart claiming a random relative pose, or with `local_offset` (m) between a
    pose and one within 3 nodes of its place a lap earlier, claiming their true relative pose moved by that
    distance in a random direction (a near miss, as Vertigo's local policy draws them). Returns (graph, truth,
    false-loop mask over the graph's loops in loop order)."""
    truth = laps(num_laps, per_lap)
    n = len(truth)
    true_sd = np.r_[np.full(3, sigma_r), np.full(3, sigma_t)]                 # gtsam (rotation, translation) order

    def noisy(p: gtsam.Pose3) -> np.ndarray:
        return _row(p.compose(gtsam.Pose3.Expmap(rng.normal(0.0, true_sd))))

    src = list(range(n - 1))
    dst = list(range(1, n))
    z = [noisy(truth[k].between(truth[k + 1])) for k in range(n - 1)]
    for j in range(per_lap, n):
        src.append(j)
        dst.append(j - per_lap)
        z.append(noisy(truth[j].between(truth[j - per_lap])))
    false = []
    while local_offset is not None and len(false) < num_false:
        j = int(rng.integers(per_lap, n))
        i = j - per_lap + int(rng.integers(-3, 4))
        u = rng.normal(size=3)
        claim = truth[j].between(truth[i]).compose(
            gtsam.Pose3(gtsam.Rot3(), gtsam.Point3(*(local_offset * u / np.linalg.norm(u)))))
        false.append((i, j))
        src.append(j)
        dst.append(i)
        z.append(_row(claim))
    while len(false) < num_false:
        i, j = sorted(rng.integers(0, n, 2).tolist())
        if j - i < per_lap // 4 or (j - i) % per_lap < per_lap // 4 or (j - i) % per_lap > per_lap - per_lap // 4:
            continue                        # far from any true revisit: a false claim, not a coincidental truth
        false.append((i, j))
        claim = gtsam.Pose3(gtsam.Rot3.Expmap(rng.uniform(-0.5, 0.5, 3)), gtsam.Point3(*rng.uniform(-3, 3, 3)))
        src.append(j)
        dst.append(i)
        z.append(_row(claim))
    m = len(src)
    info = np.diag(np.r_[np.full(3, (stated_t * sigma_t) ** -2), np.full(3, (stated_r * sigma_r) ** -2)])
    loop = np.arange(m) >= n - 1
    data = PoseGraphData(3, np.arange(n), np.full((n, 7), np.nan), np.array(src), np.array(dst), np.array(z),
                         np.broadcast_to(info, (m, 6, 6)).copy(), loop, np.ones(m))
    data.probability[data.is_loop] = np.nan
    is_false = np.r_[np.zeros(int(loop.sum()) - num_false, bool), np.ones(num_false, bool)]
    return data, truth, is_false


def position_rmse(truth: list[gtsam.Pose3], poses: np.ndarray) -> float:
    """RMSE of positions, both trajectories anchored at their first pose (the solve anchors node 0 where it is)."""
    t = np.array([truth[0].between(p).translation() for p in truth])
    first = gtsam.Pose3(gtsam.Rot3.Quaternion(poses[0, 6], *poses[0, 3:6]), gtsam.Point3(*poses[0, :3]))
    e = np.array([first.between(gtsam.Pose3(gtsam.Rot3.Quaternion(r[6], *r[3:6]), gtsam.Point3(*r[:3])))
                  .translation() for r in poses])
    return float(np.sqrt(np.mean(np.sum((t - e) ** 2, axis=1))))
