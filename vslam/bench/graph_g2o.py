"""The g2o peer of `vslam bench graph`: g2o's Levenberg-Marquardt with its DCS robust kernel, in a child process.

g2o runs through the `g2opy` wheel (2.3.0, the bindings built from g2o's own sources; `g2o-python` 0.0.12, the
wheel issue 14 names, segfaults in `EdgeSE2.set_information` under numpy 2.x). A native crash must lose one row,
not the run: the parent writes the graph to an .npz file, `python -m vslam.bench.graph_g2o IN OUT` solves it, and a
child killed by a signal raises `PeerCrashed` (the row is reported as "crashed").

Setup, as Agarwal et al. (2013) and g2o's own examples use DCS: every vertex started from the odometry chain (the
same start as the GTSAM DCS run), the first node fixed, odometry edges plain, every loop edge with
`RobustKernelDCS(phi)`, phi = 1; g2o's LM (sparse Eigen Cholesky) in one `optimize(G2O_ITERATIONS)` call, as the
`g2o` command line runs it (it stops early when LM finds no step that lowers chi^2). A loop is kept when its DCS scale
s = min(1, 2 phi / (phi + chi^2)) is at least 0.5 (the same rule as the GTSAM DCS run).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from odometry.shared.rotations import quat_to_rotmat, rotmat_to_quat

G2O_ITERATIONS = 100        # LM iterations at most (g2o's examples and Agarwal et al. use 10-100)
G2O_TIMEOUT_S = 3600.0      # a hung child loses its row, not the run


class PeerCrashed(RuntimeError):
    """The g2o child process died (signal or error): the row is reported as crashed, the run goes on."""


def solve_in_child(dim: int, init: np.ndarray, a: np.ndarray, b: np.ndarray, z: np.ndarray, info: np.ndarray,
                   is_loop: np.ndarray, anchors: np.ndarray, phi: float, module: str = "vslam.bench.graph_g2o"
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """(poses, per-loop DCS chi^2, seconds inside the child) of g2o LM + DCS, solved in a child process running
    `python -m module IN OUT` (this module; tests substitute one that crashes)."""
    with tempfile.TemporaryDirectory(prefix="vslam-g2o-") as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(src, dim=dim, init=init, a=a, b=b, z=z, info=info, is_loop=is_loop, anchors=anchors, phi=phi)
        try:
            proc = subprocess.run([sys.executable, "-m", module, str(src), str(dst)],
                                  capture_output=True, text=True, timeout=G2O_TIMEOUT_S,
                                  env={**os.environ, "OMP_NUM_THREADS": "1"})
        except subprocess.TimeoutExpired as e:
            raise PeerCrashed(f"g2o child timed out after {G2O_TIMEOUT_S:.0f} s") from e
        if proc.returncode != 0 or not dst.exists():
            rc = proc.returncode
            why = f"signal {signal.Signals(-rc).name}" if rc < 0 else f"exit code {rc}"
            tail = (proc.stderr or "").strip().splitlines()[-1:] or [""]
            raise PeerCrashed(f"g2o child died ({why}) {tail[0]}".strip())
        out = np.load(dst)
        return out["poses"], out["chi2"], float(out["seconds"])


def g2o_information(dim: int, info: np.ndarray) -> np.ndarray:
    """The project's information matrices (file order; GTSAM reads the 3D rotation block per radian of rotation
    vector) in g2o's 3D error units: EdgeSE3's rotation error is the quaternion's vector part, half the rotation
    vector for small angles, so the rotation rows and columns scale by 2 and both libraries solve one problem."""
    if dim == 2:
        return info
    s = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])
    return info * s[:, None] * s[None, :]


def _solve(d: dict) -> tuple[np.ndarray, np.ndarray]:
    # imported only in the child: the optional wheel may be absent, and a crash in it must not take the bench down
    import g2opy as g2o

    dim, init, phi = int(d["dim"]), d["init"], float(d["phi"])
    opt = g2o.SparseOptimizer()
    if dim == 2:
        solver = g2o.BlockSolverSE2(g2o.LinearSolverEigenSE2())
    else:
        solver = g2o.BlockSolverSE3(g2o.LinearSolverEigenSE3())
    opt.set_algorithm(g2o.OptimizationAlgorithmLevenberg(solver))
    keep = []                  # the bindings do not own vertices, edges, kernels: hold them until the end
    fixed = set(np.asarray(d["anchors"], np.int64).tolist())
    for k, p in enumerate(init.tolist()):
        v = g2o.VertexSE2() if dim == 2 else g2o.VertexSE3()
        v.set_id(k)
        v.set_estimate(_pose(g2o, dim, p))
        v.set_fixed(k in fixed)
        opt.add_vertex(v)
        keep.append(v)
    loops = []
    infos = g2o_information(dim, d["info"])
    for i, j, z, info, lp in zip(d["a"].tolist(), d["b"].tolist(), d["z"].tolist(), infos, d["is_loop"].tolist()):
        e = g2o.EdgeSE2() if dim == 2 else g2o.EdgeSE3()
        e.set_vertex(0, opt.vertex(int(i)))
        e.set_vertex(1, opt.vertex(int(j)))
        e.set_measurement(_pose(g2o, dim, z))
        e.set_information(np.ascontiguousarray(info, dtype=np.float64))
        if lp:
            kern = g2o.RobustKernelDCS(phi)
            e.set_robust_kernel(kern)
            keep.append(kern)
            loops.append(e)
        opt.add_edge(e)
        keep.append(e)
    opt.initialize_optimization()
    opt.optimize(G2O_ITERATIONS)
    poses = np.array([_vector(opt.vertex(k).estimate(), dim) for k in range(len(init))])
    chi2 = np.empty(len(loops))
    for n, e in enumerate(loops):
        e.compute_error()
        chi2[n] = e.chi2()                 # r' info r, before the kernel
    return poses, chi2


def _pose(g2o, dim: int, p):
    if dim == 2:
        return g2o.SE2(float(p[0]), float(p[1]), float(p[2]))
    m = np.eye(4)
    m[:3, :3] = quat_to_rotmat(np.array(p[3:7], float))     # (qx, qy, qz, qw), normalised there
    m[:3, 3] = p[:3]
    return g2o.Isometry3d(m)


def _vector(est, dim: int) -> np.ndarray:
    if dim == 2:
        return np.asarray(est.vector(), float)
    m = np.asarray(est.matrix(), float)
    return np.r_[m[:3, 3], rotmat_to_quat(m[None, :3, :3])[0]]


def main(argv: list[str]) -> int:
    src, dst = argv
    d = dict(np.load(src))
    t0 = time.perf_counter()
    poses, chi2 = _solve(d)
    seconds = time.perf_counter() - t0
    tmp = Path(dst).with_suffix(".tmp.npz")
    np.savez(tmp, poses=poses, chi2=chi2, seconds=seconds)
    os.replace(tmp, dst)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
