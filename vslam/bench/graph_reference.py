"""The converged clean reference of a graph for `vslam bench graph`, cached next to the bench's JSON output.

Plain LM at its default tolerances (relative and absolute error decrease 1e-5, 100 iterations) stops early on the
large graphs: on w10000 it ends 0.24 m from the optimum it converges to, so a method that reaches the optimum was
counted as 0.24 m off. The reference here is the same least-squares problem (LAGO / chordal start, every loop, LM)
run to convergence: REF_TOL relative and absolute decrease, at most REF_MAX_ITERATIONS iterations. Its poses are
cached per graph in `<out folder>/graph-reference/<graph>.npz`, keyed by the graph file's size and modification
time and by the reference settings, so a resumed run reuses them.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from graph import GraphParams, optimize
from graph.model import PoseGraphData
from odometry.shared.atomic_io import atomic_path

REF_TOL = 1e-12            # relative and absolute error decrease (gtsam error units): far below any solver noise
REF_MAX_ITERATIONS = 2000  # the largest graph here converges in well under this (iterations are reported)


@dataclass
class Reference:
    poses: np.ndarray
    iterations: int
    final_cost: float
    seconds: float


def reference_params() -> GraphParams:
    return GraphParams.preset("least_squares", solver={"lm_relative_tol": REF_TOL, "lm_absolute_tol": REF_TOL,
                                                       "lm_max_iterations": REF_MAX_ITERATIONS})


def _key(path: Path) -> str:
    st = path.stat()
    blob = json.dumps([str(path), st.st_size, st.st_mtime_ns, REF_TOL, REF_MAX_ITERATIONS])
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def converged_reference(name: str, path: Path, data: PoseGraphData, cache_dir: Path | None) -> Reference:
    """Plain LM on the clean graph to convergence; read from / written to `cache_dir` when given."""
    key = _key(path)
    cached = cache_dir / f"{name}.npz" if cache_dir else None
    if cached is not None and cached.exists():
        z = np.load(cached)
        if str(z["key"]) == key:
            return Reference(z["poses"], int(z["iterations"]), float(z["final_cost"]), float(z["seconds"]))
    res = optimize(data, reference_params())
    ref = Reference(res.poses, int(res.iterations), float(res.final_cost), float(res.seconds))
    if cached is not None:
        with atomic_path(cached) as tmp:
            np.savez(tmp, key=key, poses=ref.poses, iterations=ref.iterations, final_cost=ref.final_cost,
                     seconds=ref.seconds)
    return ref
