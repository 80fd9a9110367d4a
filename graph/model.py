"""The pose graph as plain arrays: nodes with ids and initial guesses, edges with measurements and information.

One structure serves the file formats (g2o, TORO), the Python API and the solvers.

Conventions
- Planar graphs (dim 2): poses and measurements are (x, y, theta); information matrices are 3x3 in that order.
- 3D graphs (dim 3): poses and measurements are (x, y, z, qx, qy, qz, qw) (TUM / g2o order); information
  matrices are 6x6 over (x, y, z, rx, ry, rz), translation first, as in g2o files. The solver permutes them to
  gtsam's (rotation, translation) tangent order.
- An edge (i, j, z) measures pose j in the frame of pose i: z = inverse(x_i) * x_j.
- Node ids are arbitrary integers; `node_ids` keeps them in input order (file order of the vertices, then ids
  that appear only on edges, ascending). Solvers map them to gtsam keys 0..N-1 by position and back.
- Odometry / loop: an edge between nodes at consecutive positions in that order (|pos(i) - pos(j)| == 1) is
  odometry, any other edge a loop closure. `classify_edges` applies that rule to file graphs; the API marks
  edges explicitly.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from graph.ids import common_ids, id_array

POSE_WIDTH = {2: 3, 3: 7}
TANGENT_DIM = {2: 3, 3: 6}


@dataclass
class PoseGraphData:
    dim: int
    node_ids: np.ndarray                  # (N,) int64, input order (object of Python ints past int64: graph.ids)
    poses: np.ndarray                     # (N, 3|7) initial guesses; NaN rows where none was given
    edge_from: np.ndarray                 # (M,) int64 node ids
    edge_to: np.ndarray                   # (M,) int64 node ids
    measurements: np.ndarray              # (M, 3|7)
    information: np.ndarray               # (M, 3|6, 3|6)
    is_loop: np.ndarray                   # (M,) bool
    probability: np.ndarray               # (M,) float: P(loop) for loops, 1 for odometry
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))   # ids of FIX vertices
    comments: list[str] = field(default_factory=list)     # full comment lines, without the newline
    extras: list[str] = field(default_factory=list)       # lines kept verbatim (g2o FIX, TORO EQUIV)
    layout: list[tuple[str, int]] = field(default_factory=list)   # file order: ('V'|'E'|'#'|'X', index)

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise ValueError(f"dim must be 2 or 3, got {self.dim}")
        w, d = POSE_WIDTH[self.dim], TANGENT_DIM[self.dim]
        self.poses = np.asarray(self.poses, dtype=float).reshape(-1, w)
        self.measurements = np.asarray(self.measurements, dtype=float).reshape(-1, w)
        self.information = np.asarray(self.information, dtype=float).reshape(-1, d, d)
        self.is_loop = np.asarray(self.is_loop, dtype=bool).reshape(-1)
        self.probability = np.asarray(self.probability, dtype=float).reshape(-1)
        self.node_ids, self.edge_from, self.edge_to, self.fixed = common_ids(
            id_array(self.node_ids), id_array(self.edge_from), id_array(self.edge_to), id_array(self.fixed))
        m = len(self.edge_from)
        if len(self.poses) != len(self.node_ids):
            raise ValueError(f"{len(self.poses)} poses for {len(self.node_ids)} node ids")
        for name in ("edge_to", "measurements", "information", "is_loop", "probability"):
            if len(getattr(self, name)) != m:
                raise ValueError(f"{name} has {len(getattr(self, name))} rows for {m} edges")

    # ------------------------------------------------------------------------------------------- sizes
    @property
    def num_nodes(self) -> int:
        return len(self.node_ids)

    @property
    def num_edges(self) -> int:
        return len(self.edge_from)

    @property
    def num_loops(self) -> int:
        return int(self.is_loop.sum())

    @property
    def has_pose(self) -> np.ndarray:
        return ~np.isnan(self.poses).any(axis=1)

    def index_of(self, ids: np.ndarray) -> np.ndarray:
        """Positions (0..N-1) of node ids; raises KeyError naming an unknown id."""
        shape = np.shape(ids)
        ids, node_ids = common_ids(id_array(ids), self.node_ids)
        order = np.argsort(node_ids, kind="stable")
        sorted_ids = node_ids[order]
        pos = np.searchsorted(sorted_ids, ids)
        pos_c = np.clip(pos, 0, max(len(sorted_ids) - 1, 0))
        ok = (pos < len(sorted_ids)) & (sorted_ids[pos_c] == ids) if len(sorted_ids) else np.zeros(ids.shape, bool)
        if not np.all(ok):
            bad = ids[~ok].reshape(-1)[0]
            raise KeyError(f"unknown node id {int(bad)}")
        return order[pos_c].reshape(shape)

    def edge_index_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """Edges as node positions (a, b)."""
        return self.index_of(self.edge_from), self.index_of(self.edge_to)

    def loop_edges(self) -> np.ndarray:
        """Indices of the loop edges (their order defines loop indices)."""
        return np.flatnonzero(self.is_loop)

    def copy(self) -> "PoseGraphData":
        return PoseGraphData(self.dim, self.node_ids.copy(), self.poses.copy(), self.edge_from.copy(),
                             self.edge_to.copy(), self.measurements.copy(), self.information.copy(),
                             self.is_loop.copy(), self.probability.copy(), self.fixed.copy(), list(self.comments),
                             list(self.extras), list(self.layout))

    def with_edges(self, keep: np.ndarray) -> "PoseGraphData":
        """A copy keeping only the edges selected by a boolean mask or index array (layout dropped)."""
        k = np.asarray(keep)
        return PoseGraphData(self.dim, self.node_ids.copy(), self.poses.copy(), self.edge_from[k], self.edge_to[k],
                             self.measurements[k], self.information[k], self.is_loop[k], self.probability[k],
                             self.fixed.copy(), list(self.comments), list(self.extras), [])

    def append_edges(self, i: np.ndarray, j: np.ndarray, z: np.ndarray, info: np.ndarray, is_loop: np.ndarray,
                     probability: np.ndarray | None = None) -> "PoseGraphData":
        """A copy with edges appended after the existing ones (layout dropped)."""
        i = id_array(i)
        p = np.ones(len(i)) if probability is None else np.asarray(probability, float).reshape(-1)
        w, d = POSE_WIDTH[self.dim], TANGENT_DIM[self.dim]
        return PoseGraphData(self.dim, self.node_ids.copy(), self.poses.copy(), np.concatenate([self.edge_from, i]),
                             np.concatenate([self.edge_to, id_array(j)]),
                             np.concatenate([self.measurements, np.asarray(z, float).reshape(-1, w)]),
                             np.concatenate([self.information, np.asarray(info, float).reshape(-1, d, d)]),
                             np.concatenate([self.is_loop, np.broadcast_to(np.asarray(is_loop, bool), len(i))]),
                             np.concatenate([self.probability, p]), self.fixed.copy(), list(self.comments),
                             list(self.extras), [])

    def equals(self, other: "PoseGraphData", rtol: float = 0.0, atol: float = 1e-9) -> bool:
        """Same nodes, edges, measurements, information, labels (NaN guesses compare equal)."""
        if self.dim != other.dim or self.num_nodes != other.num_nodes or self.num_edges != other.num_edges:
            return False
        if not (np.array_equal(self.node_ids, other.node_ids) and np.array_equal(self.edge_from, other.edge_from)
                and np.array_equal(self.edge_to, other.edge_to) and np.array_equal(self.is_loop, other.is_loop)
                and np.array_equal(self.fixed, other.fixed)):
            return False
        return (np.allclose(self.poses, other.poses, rtol=rtol, atol=atol, equal_nan=True)
                and np.allclose(self.measurements, other.measurements, rtol=rtol, atol=atol)
                and np.allclose(self.information, other.information, rtol=rtol, atol=atol)
                and np.allclose(self.probability, other.probability, rtol=rtol, atol=atol, equal_nan=True))


def checked_edge(i, j, delta, known, dim: int) -> tuple[int, int, np.ndarray]:
    """(i, j, delta as a float pose vector) of a new edge, after the checks every graph front end makes: both
    nodes added (`known` supports `in`), no self-edge, a finite delta of the right width."""
    i, j = int(i), int(j)
    for n in (i, j):
        if n not in known:
            raise KeyError(f"unknown node id {n}: add_node first")
    if i == j:
        raise ValueError(f"edge from node {i} to itself")
    z = np.asarray(delta, float).reshape(POSE_WIDTH[dim])
    if not np.all(np.isfinite(z)):
        raise ValueError("delta must be finite")
    return i, j, z


def information_from(cov: np.ndarray | None, information: np.ndarray | None, d: int) -> np.ndarray:
    """The information matrix from exactly one of a covariance or an information matrix (d x d, symmetric,
    positive definite); ValueError naming the problem otherwise."""
    if (cov is None) == (information is None):
        raise ValueError("give exactly one of cov and information")
    name = "information" if cov is None else "cov"
    m = np.asarray(information if cov is None else cov, float)
    if m.shape != (d, d):
        raise ValueError(f"{name} must be {d}x{d}, got shape {m.shape}")
    if not np.all(np.isfinite(m)) or np.abs(m - m.T).max() > 1e-9 * max(np.abs(m).max(), 1e-300):
        raise ValueError(f"{name} must be finite and symmetric")
    if np.linalg.eigvalsh(m)[0] <= 0:
        raise ValueError(f"{name} must be positive definite")
    return m if cov is None else np.linalg.inv(m)


def classify_edges(node_ids: np.ndarray, edge_from: np.ndarray, edge_to: np.ndarray) -> np.ndarray:
    """The file rule: True (loop) unless the two nodes are consecutive in input order."""
    node_ids, edge_from, edge_to = common_ids(id_array(node_ids), id_array(edge_from), id_array(edge_to))
    order = np.argsort(node_ids, kind="stable")
    sorted_ids = node_ids[order]
    # sorted_ids[r] == node_ids[order[r]], so order[rank] is the position in input order
    a = order[np.searchsorted(sorted_ids, edge_from)]
    b = order[np.searchsorted(sorted_ids, edge_to)]
    return np.abs(a - b) != 1


def empty(dim: int) -> PoseGraphData:
    w, d = POSE_WIDTH[dim], TANGENT_DIM[dim]
    return PoseGraphData(dim, np.zeros(0, np.int64), np.zeros((0, w)), np.zeros(0, np.int64), np.zeros(0, np.int64),
                         np.zeros((0, w)), np.zeros((0, d, d)), np.zeros(0, bool), np.zeros(0))
