"""The pipeline's pose graph: a `graph.RobustPoseGraph` over keyframes (node id = frame index), batch or iSAM2."""
from __future__ import annotations

import numpy as np

from graph import GraphParams, RobustPoseGraph, Solver


def floored(cov: np.ndarray) -> np.ndarray:
    """The covariance plus a tiny floor: a degenerate one (e.g. an exactly repeated fallback) stays invertible."""
    return np.asarray(cov, float) + np.eye(3) * 1e-12


def backend_graph(params: GraphParams, incremental: bool) -> RobustPoseGraph:
    """Batch (`params.solver.method` LM) or iSAM2 (`--incremental`) back end.

    Online, loops reach the graph already verified (geometry + P(loop) threshold) and a run may close only a few:
    the iSAM2 strategy admits those that fit the stated model at once instead of waiting for the gate's 20-loop
    warm-up (`gate_warmup_stated`).
    """
    if incremental:
        return RobustPoseGraph(2, params.replace(robust={"gate_warmup_stated": True}), strategy=Solver.ISAM2)
    return RobustPoseGraph(2, params)
