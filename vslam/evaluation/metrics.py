"""Trajectory error metrics with evo's conventions (so figures agree with `evo_ape` / `evo_rpe` to 1e-6).

- association: nearest timestamps within `max_diff`, starting from the shorter trajectory (evo's
  `associate_trajectories` with `SyncMethod.nearest_time`);
- alignment: Umeyama least squares on positions - SE(3), Sim(3) - plus SE(2) (rotation about z and an xy
  translation), the natural choice for ground robots;
- APE: per-pose error after alignment; RPE: error of relative poses (i, i + delta) with delta in frames or
  metres, consecutive non-overlapping pairs unless all_pairs.
Poses are (N, 4, 4) SE(3) matrices.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from odometry.shared.poses import between, wrap_angle
from vslam.errors import VslamError


class Alignment(str, enum.Enum):
    NONE = "none"
    SE2 = "se2"
    SE3 = "se3"
    SIM3 = "sim3"


class PoseRelation(str, enum.Enum):
    TRANSLATION = "trans"          # metres
    ROTATION_DEG = "rot_deg"       # rotation angle of the error, degrees


class DeltaUnit(str, enum.Enum):
    FRAMES = "f"
    METERS = "m"


STAT_NAMES = ("rmse", "mean", "median", "std", "min", "max", "sse")


def statistics(err: np.ndarray) -> dict[str, float]:
    e = np.asarray(err, dtype=float)
    if e.size == 0:
        return {k: float("nan") for k in STAT_NAMES}
    return {"rmse": float(np.sqrt(np.mean(e * e))), "mean": float(np.mean(e)), "median": float(np.median(e)),
            "std": float(np.std(e)), "min": float(np.min(e)), "max": float(np.max(e)), "sse": float(np.sum(e * e))}


def associate(t_a: np.ndarray, t_b: np.ndarray, max_diff: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    """Index arrays (ia, ib) pairing timestamps within max_diff, as evo does (from the shorter list, nearest match)."""
    t_a = np.asarray(t_a, dtype=float)
    t_b = np.asarray(t_b, dtype=float)
    swap = len(t_a) > len(t_b)          # evo starts from the trajectory with fewer poses (ties: the second one)
    short, long_ = (t_b, t_a) if swap else (t_a, t_b)
    if len(short) == 0 or len(long_) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    if np.any(np.diff(long_) < 0):
        raise VslamError("timestamps must be sorted")
    idx = np.clip(np.searchsorted(long_, short, side="right"), 0, len(long_) - 1)
    diff_ub = long_[idx] - short
    diff_lb = np.where(idx > 0, short - long_[np.maximum(idx - 1, 0)], np.inf)
    inside = (short >= long_[0] - max_diff) & (short <= long_[-1] + max_diff)
    take_ub = (diff_ub <= max_diff) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_diff)
    keep = inside & (take_ub | take_lb)
    j = np.where(take_ub, idx, idx - 1)
    i_short, i_long = np.nonzero(keep)[0], j[keep]
    return (i_long, i_short) if swap else (i_short, i_long)


def umeyama(x: np.ndarray, y: np.ndarray, with_scale: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """R, t, s minimising sum |y_i - (s R x_i + t)|^2; x, y are (N, m)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    m = x.shape[1]
    mx, my = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mx, y - my
    sigma_x = np.sum(xc * xc) / len(x)
    cov = yc.T @ xc / len(x)
    u, d, vt = np.linalg.svd(cov)
    if np.count_nonzero(d > np.finfo(d.dtype).eps) < m - 1:
        raise VslamError("degenerate point set: alignment is not possible (fewer than 2 distinct positions?)")
    s_mat = np.eye(m)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s_mat[m - 1, m - 1] = -1
    r = u @ s_mat @ vt
    c = float(np.trace(np.diag(d) @ s_mat) / sigma_x) if with_scale else 1.0
    t = my - c * r @ mx
    return r, t, c


def align(ref: np.ndarray, est: np.ndarray, mode: Alignment | str = Alignment.SE3) -> tuple[np.ndarray, dict]:
    """The estimate aligned to the reference (new array) and the transform {'R', 't', 's'}."""
    mode = Alignment(mode)
    R, t, s = np.eye(3), np.zeros(3), 1.0
    if mode in (Alignment.SE3, Alignment.SIM3):
        R, t, s = umeyama(est[:, :3, 3], ref[:, :3, 3], with_scale=mode == Alignment.SIM3)
    elif mode == Alignment.SE2:
        r2, t2, _ = umeyama(est[:, :2, 3], ref[:, :2, 3])
        R[:2, :2] = r2
        t[:2] = t2
    out = est.copy()
    out[:, :3, :3] = R @ est[:, :3, :3]
    out[:, :3, 3] = (s * (R @ est[:, :3, 3].T)).T + t
    return out, {"R": R, "t": t, "s": s}


def _rotation_angles(r: np.ndarray) -> np.ndarray:
    """Angles (rad) of rotation matrices (N, 3, 3), accurate near 0 and pi."""
    # atan2 form: robust everywhere, same value as |so3 log|
    cos = (np.trace(r, axis1=1, axis2=2) - 1) / 2
    skew = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]], -1)
    sin = np.linalg.norm(skew, axis=1) / 2
    return np.arctan2(sin, cos)


def _relation_error(E: np.ndarray, relation: PoseRelation) -> np.ndarray:
    if relation == PoseRelation.TRANSLATION:
        return np.linalg.norm(E[:, :3, 3], axis=1)
    return np.degrees(_rotation_angles(E[:, :3, :3]))


def inverse_se3(m: np.ndarray) -> np.ndarray:
    out = np.zeros_like(m)
    rt = np.transpose(m[..., :3, :3], (0, 2, 1)) if m.ndim == 3 else m[:3, :3].T
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, m[..., :3, 3])
    out[..., 3, 3] = 1
    return out


def ape(ref: np.ndarray, est: np.ndarray, relation: PoseRelation | str = PoseRelation.TRANSLATION) -> np.ndarray:
    """Absolute pose errors per pose (already associated and aligned)."""
    relation = PoseRelation(relation)
    if relation == PoseRelation.TRANSLATION:
        return np.linalg.norm(ref[:, :3, 3] - est[:, :3, 3], axis=1)
    E = np.einsum("nij,njk->nik", inverse_se3(ref), est)
    return _relation_error(E, relation)


def rpe_pairs(poses: np.ndarray, delta: float, unit: DeltaUnit | str = DeltaUnit.FRAMES, all_pairs: bool = False,
              rel_tol: float = 0.1) -> np.ndarray:
    """(K, 2) index pairs for RPE, as evo builds them (delta in frames, or in metres along the reference path)."""
    unit = DeltaUnit(unit)
    n = len(poses)
    if unit == DeltaUnit.FRAMES:
        d = int(delta)
        if d < 1:
            raise VslamError("RPE delta in frames must be >= 1")
        if all_pairs:
            i = np.arange(0, max(n - d, 0))
            return np.column_stack([i, i + d])
        ids = np.arange(0, n, d)
        return np.column_stack([ids[:-1], ids[1:]])
    # metres along the path (evo's filter_pairs_by_path): consecutive pairs start a new pair each time the
    # travelled distance reaches delta; all_pairs takes, from every pose, the pose closest to delta ahead
    steps = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    pairs = []
    if all_pairs:
        acc = np.concatenate([[0.0], np.cumsum(steps)])
        for i in range(n - 1):
            ahead = acc[i + 1:] - acc[i]
            k = int(np.argmin(np.abs(ahead - delta)))
            if abs(ahead[k] - delta) <= delta * rel_tol:
                pairs.append((i, i + 1 + k))
    else:
        ids = [0]
        travelled = 0.0
        for j in range(1, n):
            travelled += float(steps[j - 1])
            if travelled >= delta:
                ids.append(j)
                travelled = 0.0
        pairs = list(zip(ids[:-1], ids[1:]))
    return np.asarray(pairs, dtype=int).reshape(-1, 2)


def rpe(ref: np.ndarray, est: np.ndarray, delta: float = 1, unit: DeltaUnit | str = DeltaUnit.FRAMES,
        relation: PoseRelation | str = PoseRelation.TRANSLATION, all_pairs: bool = False,
        pairs_from_reference: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Relative pose errors and their (i, j) pairs. Like evo, pairs for a delta in metres are chosen along the
    estimate's path unless pairs_from_reference."""
    pairs = rpe_pairs(ref if pairs_from_reference else est, delta, unit, all_pairs)
    if len(pairs) == 0:
        return np.zeros(0), pairs
    i, j = pairs[:, 0], pairs[:, 1]
    q_rel = np.einsum("nij,njk->nik", inverse_se3(ref[i]), ref[j])
    p_rel = np.einsum("nij,njk->nik", inverse_se3(est[i]), est[j])
    E = np.einsum("nij,njk->nik", inverse_se3(q_rel), p_rel)
    return _relation_error(E, PoseRelation(relation)), pairs


@dataclass(frozen=True)
class TrajectoryReport:
    """APE / RPE of one estimate against a reference."""

    matched: int
    alignment: str
    scale: float
    ape: dict
    ape_rot_deg: dict
    rpe: dict
    rpe_rot_deg: dict
    path_length: float
    ape_errors: np.ndarray
    timestamps: np.ndarray

    def to_dict(self) -> dict:
        return {"matched": self.matched, "alignment": self.alignment, "scale": self.scale, "ape_m": self.ape,
                "ape_rot_deg": self.ape_rot_deg, "rpe_m": self.rpe, "rpe_rot_deg": self.rpe_rot_deg,
                "path_length_m": self.path_length,
                "ape_rmse_percent_of_path": 100.0 * self.ape["rmse"] / self.path_length if self.path_length > 0
                else float("nan")}


def evaluate(t_ref: np.ndarray, ref: np.ndarray, t_est: np.ndarray, est: np.ndarray,
             alignment: Alignment | str = Alignment.SE3, max_diff: float = 0.01, delta: float = 1,
             delta_unit: DeltaUnit | str = DeltaUnit.FRAMES) -> TrajectoryReport:
    """Associate, align and compute APE and RPE (translation and rotation)."""
    ir, ie = associate(t_ref, t_est, max_diff)
    if len(ir) < 2:
        raise VslamError(f"only {len(ir)} timestamps of the estimate match the reference within {max_diff} s")
    r, e = ref[ir], est[ie]
    aligned, tf = align(r, e, alignment)
    ape_t = ape(r, aligned)
    rpe_t, _ = rpe(r, aligned, delta, delta_unit)
    rpe_r, _ = rpe(r, aligned, delta, delta_unit, PoseRelation.ROTATION_DEG)
    length = float(np.sum(np.linalg.norm(np.diff(r[:, :3, 3], axis=0), axis=1)))
    return TrajectoryReport(matched=len(ir), alignment=Alignment(alignment).value, scale=tf["s"],
                            ape=statistics(ape_t), ape_rot_deg=statistics(ape(r, aligned, PoseRelation.ROTATION_DEG)),
                            rpe=statistics(rpe_t), rpe_rot_deg=statistics(rpe_r), path_length=length,
                            ape_errors=ape_t, timestamps=np.asarray(t_ref)[ir])


def start_to_end_error(est_planar: np.ndarray, gt_planar: np.ndarray | None = None) -> dict:
    """Seed 001 Table IV: the estimated pose of the end relative to the start (ideally zero on a closed path).
    With ground truth, also the error of that relative pose against the true one (the robot may not stop exactly
    where it started)."""
    d = between(est_planar[0], est_planar[-1])
    out = {"dx": float(d[0]), "dy": float(d[1]), "dtheta": float(d[2]), "distance": float(math.hypot(d[0], d[1]))}
    if gt_planar is not None:
        g = between(gt_planar[0], gt_planar[-1])
        e = between(g, d)
        out.update({"error_dx": float(e[0]), "error_dy": float(e[1]), "error_dtheta": float(wrap_angle(e[2])),
                    "error_distance": float(math.hypot(e[0], e[1])), "true_distance": float(math.hypot(g[0], g[1]))})
    return out
