"""Local pairwise consistency of loop closures: how many nearby loops agree with each loop.

Two loops p (a_p -> b_p) and q (a_q -> b_q) are neighbours when both ends are within `window` nodes of each other
(|a_p - a_q| <= W and |b_p - b_q| <= W). They agree when the cycle
    a_q -> a_p (odometry) -> b_p (loop p) -> b_q (odometry) -> a_q (loop q, inverted)
closes within the chi-square test of its stated covariance (both loops plus the odometry steps in the cycle).
The odometry in the cycle is short (at most 2W steps), so accumulated drift - however large over the whole
trajectory - does not enter the test: this is what makes it drift-proof, unlike a test of a loop against the
drifted estimate at its arrival. A true loop closure event usually yields several consecutive loops (a revisited
stretch) that support each other; a random false loop has no support. Groups of mutually consistent false loops
(the same aliasing repeated along a stretch) do support each other: the global robust solve must settle those.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from graph.model import PoseGraphData


def _matrices(dim: int, rows: np.ndarray) -> np.ndarray:
    """(N, 3|4, 3|4) homogeneous matrices from (x, y, theta) or (x, y, z, qx, qy, qz, qw) rows."""
    rows = np.asarray(rows, float)
    n = len(rows)
    if dim == 2:
        c, s = np.cos(rows[:, 2]), np.sin(rows[:, 2])
        m = np.zeros((n, 3, 3))
        m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = c, -s, s, c
        m[:, :2, 2] = rows[:, :2]
        m[:, 2, 2] = 1.0
        return m
    m = np.zeros((n, 4, 4))
    m[:, :3, :3] = Rotation.from_quat(rows[:, 3:7]).as_matrix()
    m[:, :3, 3] = rows[:, :3]
    m[:, 3, 3] = 1.0
    return m


def _inverse(m: np.ndarray) -> np.ndarray:
    d = m.shape[-1] - 1
    out = np.zeros_like(m)
    rt = np.swapaxes(m[:, :d, :d], 1, 2)
    out[:, :d, :d] = rt
    out[:, :d, d] = -np.einsum("nij,nj->ni", rt, m[:, :d, d])
    out[:, d, d] = 1.0
    return out


def _tangent(dim: int, m: np.ndarray) -> np.ndarray:
    """(translation, rotation) error vectors in the file's information order."""
    if dim == 2:
        return np.column_stack([m[:, 0, 2], m[:, 1, 2], np.arctan2(m[:, 1, 0], m[:, 0, 0])])
    return np.column_stack([m[:, :3, 3], Rotation.from_matrix(m[:, :3, :3]).as_rotvec()])


def chain_poses(data: PoseGraphData) -> np.ndarray:
    """Dead-reckoning matrices: odometry composed along node order (position k -> k+1, either direction)."""
    a, b = data.edge_index_pairs()
    odo = np.flatnonzero(~data.is_loop & (np.abs(a - b) == 1))
    z = _matrices(data.dim, data.measurements[odo])
    step = np.repeat(np.eye(data.dim + 1)[None], max(data.num_nodes - 1, 0), axis=0)
    fwd = a[odo] < b[odo]
    lo = np.minimum(a[odo], b[odo])
    step[lo[fwd]] = z[fwd]
    step[lo[~fwd]] = _inverse(z[~fwd])
    out = np.empty((data.num_nodes, data.dim + 1, data.dim + 1))
    out[0] = np.eye(data.dim + 1)
    for k in range(1, data.num_nodes):
        out[k] = out[k - 1] @ step[k - 1]
    return out


@dataclass(frozen=True)
class CycleSupport:
    """The agreeing neighbour pairs of `cycle_support` with what their test computed, so the noise calibration
    (graph.calibration) reads the same cycles: P, Q (loop indices in loop order, P before Q in time), r2 (squared
    Mahalanobis error on the stated covariances), errors (n, d) and covariances (n, d, d) of each cycle in the
    file's information order (planar: x, y, theta; 3D: translation, rotation)."""

    P: np.ndarray
    Q: np.ndarray
    r2: np.ndarray
    errors: np.ndarray
    covariances: np.ndarray
    # 3D with `decompose`: the first-order covariance of each cycle error from the translation noise of its
    # measurements alone and from their rotation noise alone (graph.calibration scales the two apart)
    from_translation: np.ndarray | None = None
    from_rotation: np.ndarray | None = None
    decomposed: np.ndarray | None = None          # which agreeing pairs those are (indices into P)

    @property
    def pairs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.P, self.Q, self.r2


def loop_support(data: PoseGraphData, window: int, threshold: float, odometry_cov: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Agreeing neighbour pairs (see the module doc): (P, Q, r2): loop indices (loop order), P before Q in time,
    and the squared Mahalanobis error of their cycle on the stated covariances (`cycle_support`'s pairs)."""
    return cycle_support(data, window, threshold, odometry_cov).pairs


def cycle_support(data: PoseGraphData, window: int, threshold: float, odometry_cov: np.ndarray | None = None,
                  decompose: int = 0) -> CycleSupport:
    """The agreeing neighbour pairs (see the module doc) with their cycle errors and covariances; with `decompose`
    > 0 (3D) also the propagated covariance of up to that many agreeing cycles (evenly spaced in pair order),
    split by the source of the noise (`CycleSupport`).

    threshold: chi-square bound on the cycle's squared Mahalanobis error. odometry_cov: covariance of one
    odometry step (default: the mean of the graph's odometry covariances; each step's own in the decomposed
    covariances), added once per step in the cycle. The test sums the covariances: propagated to first order
    through the cycle (`_cycle_covariances_3d`) it rejected 38 true loops of clean parking-garage (docs/graph.md);
    the decomposed covariances are propagated.
    """
    L = data.num_loops
    d = 3 if data.dim == 2 else 6
    none = CycleSupport(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, d)),
                        np.zeros((0, d, d)))
    if L < 2 or window <= 0:
        return none
    a_all, b_all = data.edge_index_pairs()
    li = data.loop_edges()
    a, b = a_all[li], b_all[li]
    z = _matrices(data.dim, data.measurements[li])
    swap = a > b                      # orient every loop from the earlier node to the later one
    z[swap] = _inverse(z[swap])
    a, b = np.minimum(a, b), np.maximum(a, b)
    cov = np.linalg.inv(data.information[li])
    given_odometry = odometry_cov is not None
    if odometry_cov is None:
        odo_info = data.information[~data.is_loop]
        odometry_cov = np.linalg.inv(odo_info).mean(axis=0) if len(odo_info) else np.zeros(cov.shape[1:])
    x = chain_poses(data)
    P, Q = _neighbour_pairs(a, b, window)
    if len(P) == 0:
        return none
    e = _cycle_errors(data.dim, x, z, a, b, P, Q)
    steps = (np.abs(a[P] - a[Q]) + np.abs(b[P] - b[Q]))[:, None, None]
    s = cov[P] + cov[Q] + steps * odometry_cov[None]
    r2 = np.einsum("ni,ni->n", e, np.linalg.solve(s, e[..., None])[..., 0])
    ok = r2 <= threshold
    parts = [None, None, None]
    if decompose > 0 and data.dim == 3 and ok.any():
        # propagated, a step's rotation noise reaches the cycle's translation through its lever arm: that share of
        # the translation error scales with the rotation noise, not the translation noise (sphere2500: summed,
        # its cycles put the translation factor at 4x what its loops show against ground truth)
        # (the cross blocks of the stated covariances, zero in the public graphs, are left out of both)
        # (a median needs no more than a few 10^4 cycles; propagating garage's 1.2e5 took seconds)
        t_only = np.zeros((6, 6))
        t_only[:3, :3] = 1.0
        n_ok = int(ok.sum())
        sel = np.unique(np.linspace(0, n_ok - 1, min(n_ok, decompose)).round().astype(np.int64))
        p_sel, q_sel = P[ok][sel], Q[ok][sel]
        parts = [_cycle_covariances_3d(data, z, cov * m, swap, a, b, p_sel, q_sel,
                                       odometry_cov * m if given_odometry else None, mask=m)
                 for m in (t_only, t_only[::-1, ::-1])] + [sel]
    return CycleSupport(P[ok], Q[ok], r2[ok], e[ok], s[ok], *parts)


def own_cycle_r2(data: PoseGraphData, loops: np.ndarray, propagate: bool = False) -> np.ndarray:
    """Squared Mahalanobis error of the cycle each loop of `loops` (indices, loop order) closes with the odometry
    chain between its ends, under `data`'s information: the loop's covariance plus the mean odometry step's per
    step (as the cycle test sums them), or with `propagate` (3D) propagated to first order through the cycle."""
    loops = np.asarray(loops, np.int64)
    if not len(loops):
        return np.zeros(0)
    a_all, b_all = data.edge_index_pairs()
    li = data.loop_edges()[loops]
    a, b = a_all[li], b_all[li]
    z = _matrices(data.dim, data.measurements[li])
    swap = a > b                      # oriented from the earlier node, as in the cycle test
    z[swap] = _inverse(z[swap])
    a, b = np.minimum(a, b), np.maximum(a, b)
    cov = np.linalg.inv(data.information[li])
    n, d = len(loops), cov.shape[1]
    # the cycle test's pair cycle with a second "loop" of zero length and no noise at (a, a): the cycle is then
    # the loop and the odometry from its far end back to a (graph.support._cycle_errors), and the same code
    # propagates its covariance
    eye = np.repeat(np.eye(data.dim + 1)[None], n, axis=0)
    z2 = np.concatenate([z, eye])
    a2, b2 = np.concatenate([a, a]), np.concatenate([b, a])
    p, q = np.arange(n), np.arange(n, 2 * n)
    e = _cycle_errors(data.dim, chain_poses(data), z2, a2, b2, p, q)
    if propagate and data.dim == 3:
        s = _cycle_covariances_3d(data, z2, np.concatenate([cov, np.zeros((n, d, d))]),
                                  np.concatenate([swap, np.zeros(n, bool)]), a2, b2, p, q, None)
    else:
        odo = np.linalg.inv(data.information[~data.is_loop]).mean(axis=0)
        s = cov + (b - a)[:, None, None] * odo[None]
    return np.einsum("ni,ni->n", e, np.linalg.solve(s, e[..., None])[..., 0])


_PERM = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])   # (t, r) <-> (r, t)


def _adjoint(m: np.ndarray) -> np.ndarray:
    """Adjoint maps (N, 6, 6) of (N, 4, 4) poses in gtsam's (rotation, translation) order: T exp(xi) T^-1 =
    exp(Ad_T xi)."""
    r, t = m[:, :3, :3], m[:, :3, 3]
    tx = np.zeros_like(r)
    tx[:, 0, 1], tx[:, 0, 2], tx[:, 1, 2] = -t[:, 2], t[:, 1], -t[:, 0]
    tx[:, 1, 0], tx[:, 2, 0], tx[:, 2, 1] = t[:, 2], -t[:, 1], t[:, 0]
    out = np.zeros((len(m), 6, 6))
    out[:, :3, :3] = r
    out[:, 3:, 3:] = r
    out[:, 3:, :3] = tx @ r
    return out


def _congruence(a: np.ndarray, s: np.ndarray) -> np.ndarray:
    return a @ s @ np.swapaxes(a, 1, 2)


def _cycle_covariances_3d(data: PoseGraphData, z: np.ndarray, cov: np.ndarray, swap: np.ndarray, a: np.ndarray,
                          b: np.ndarray, P: np.ndarray, Q: np.ndarray, odometry_cov: np.ndarray | None,
                          chunk: int = 20000, mask: np.ndarray | float = 1.0) -> np.ndarray:
    """First-order covariance (file order: translation, rotation) of each 3D cycle error of `_cycle_errors`.

    The cycle is a product T_1 ... T_n of measured poses (inv(z_q), the odometry steps from a_q to a_p, z_p, the
    steps from b_p to b_q), each with noise on the right, T_i exp(xi_i). To first order the product is
    C exp(sum_i Ad(inv(C) P_i) xi_i) with P_i = T_1 ... T_i, so its covariance is
    Ad(inv(C)) [sum_i Ad(P_i) S_i Ad(P_i)^T] Ad(inv(C))^T: a rotation error of a step displaces the rest of the
    cycle by its lever arm. An inverted measurement inv(T exp(xi)) = inv(T) exp(-Ad_T xi) has covariance
    Ad_T S Ad_T^T. `z`: loops oriented from the earlier node (`swap`: inverted), `cov`: their stated covariances
    as in the file (before the inversion). `mask` (file order) multiplies each odometry step's covariance."""
    n = data.num_nodes
    ea, eb = data.edge_index_pairs()
    odo = np.flatnonzero(~data.is_loop & (np.abs(ea - eb) == 1))
    lo = np.minimum(ea[odo], eb[odo])
    fwd = ea[odo] < eb[odo]
    zo = _matrices(3, data.measurements[odo])
    co = _PERM @ ((np.linalg.inv(data.information[odo]) if odometry_cov is None
                   else np.broadcast_to(odometry_cov, (len(odo), 6, 6))) * mask) @ _PERM
    step = np.repeat(np.eye(4)[None], max(n - 1, 0), axis=0)
    scov = np.zeros((max(n - 1, 0), 6, 6))
    step[lo[fwd]], scov[lo[fwd]] = zo[fwd], co[fwd]
    step[lo[~fwd]], scov[lo[~fwd]] = _inverse(zo[~fwd]), _congruence(_adjoint(zo[~fwd]), co[~fwd])
    istep, iscov = _inverse(step), _congruence(_adjoint(step), scov)
    cl = _PERM @ cov @ _PERM                      # loop covariances in the oriented loops' tangent
    cl[swap] = _congruence(_adjoint(_inverse(z[swap])), cl[swap])    # inv(T exp(xi)): Ad_T with T as measured
    span = int(max(np.abs(a[P] - a[Q]).max(), np.abs(b[P] - b[Q]).max())) if len(P) else 0
    out = np.zeros((len(P), 6, 6))
    for c0 in range(0, len(P), chunk):
        p, q = P[c0:c0 + chunk], Q[c0:c0 + chunk]
        k = len(p)
        acc = np.zeros((k, 6, 6))
        prod = np.repeat(np.eye(4)[None], k, axis=0)

        def take(t: np.ndarray, sc: np.ndarray) -> None:
            nonlocal acc, prod
            prod = prod @ t
            acc = acc + _congruence(_adjoint(prod), sc)

        zq = z[q]
        take(_inverse(zq), _congruence(_adjoint(zq), cl[q]))
        for i, j in ((a[q], a[p]), (None, None), (b[p], b[q])):
            if i is None:
                take(z[p], cl[p])
                continue
            for m in range(span):
                t = np.repeat(np.eye(4)[None], k, axis=0)
                sc = np.zeros((k, 6, 6))
                up = (j > i) & (m < j - i)
                t[up], sc[up] = step[(i + m)[up]], scov[(i + m)[up]]
                down = (j < i) & (m < i - j)
                t[down], sc[down] = istep[(i - 1 - m)[down]], iscov[(i - 1 - m)[down]]
                take(t, sc)
        out[c0:c0 + chunk] = _PERM @ _congruence(_adjoint(_inverse(prod)), acc) @ _PERM
    return out


def _neighbour_pairs(a: np.ndarray, b: np.ndarray, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Loop pairs (P, Q) with |a_P - a_Q| <= window and |b_P - b_Q| <= window, P before Q in the stable order of
    a, pairs sorted by the rank of P then of Q (the order of a loop over the loops, which w10000's 54k loops and
    10^6 pairs made the slowest step of its solve): a k-d tree in the max norm finds them."""
    order = np.argsort(a, kind="stable")
    rank = np.empty(len(a), np.int64)
    rank[order] = np.arange(len(a))
    pairs = cKDTree(np.column_stack([a, b]).astype(float)).query_pairs(r=window, p=np.inf, output_type="ndarray")
    if not len(pairs):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ri, rj = rank[pairs[:, 0]], rank[pairs[:, 1]]
    rp, rq = np.minimum(ri, rj), np.maximum(ri, rj)
    sort = np.lexsort((rq, rp))
    return order[rp[sort]], order[rq[sort]]


def _cycle_errors(dim: int, x: np.ndarray, z: np.ndarray, a: np.ndarray, b: np.ndarray, P: np.ndarray,
                  Q: np.ndarray) -> np.ndarray:
    """Error of each cycle inv(z_q) * inv(x_aq) x_ap * z_p * inv(x_bp) x_bq (identity when both loops and the
    odometry agree), in the file's information order. Planar cycles are composed from angles and translations
    (batched 3x3 products of 10^6 pairs took most of w10000's solve)."""
    if dim != 2:
        xi = _inverse(x)
        return _tangent(dim, _inverse(z[Q]) @ (xi[a[Q]] @ x[a[P]]) @ z[P] @ (xi[b[P]] @ x[b[Q]]))
    th = np.arctan2(x[:, 1, 0], x[:, 0, 0])
    tx, ty = x[:, 0, 2], x[:, 1, 2]
    zt = np.arctan2(z[:, 1, 0], z[:, 0, 0])
    zx, zy = z[:, 0, 2], z[:, 1, 2]

    def rel(i, j):           # inv(x_i) x_j
        c, s = np.cos(th[i]), np.sin(th[i])
        dx, dy = tx[j] - tx[i], ty[j] - ty[i]
        return c * dx + s * dy, -s * dx + c * dy, th[j] - th[i]

    def compose(p, q):       # p * q
        c, s = np.cos(p[2]), np.sin(p[2])
        return p[0] + c * q[0] - s * q[1], p[1] + s * q[0] + c * q[1], p[2] + q[2]

    zq = (zx[Q], zy[Q], zt[Q])
    c, s = np.cos(zq[2]), np.sin(zq[2])
    zq_inv = (-(c * zq[0] + s * zq[1]), -(-s * zq[0] + c * zq[1]), -zq[2])
    m = compose(compose(compose(zq_inv, rel(a[Q], a[P])), (zx[P], zy[P], zt[P])), rel(b[P], b[Q]))
    return np.column_stack([m[0], m[1], np.arctan2(np.sin(m[2]), np.cos(m[2]))])


def revisits(data: PoseGraphData, window: int, which: np.ndarray) -> np.ndarray:
    """Label per loop: connected components of the neighbour relation of the cycle test (both ends within
    `window` nodes, either orientation) among the loops selected by `which`; -1 for the others.

    One revisit of a stretch, whether its loops agree pairwise or not: a group of false loops along a bend agrees
    only in short runs (the cycle test compares the odometry at both ends), so its agreeing clusters are pieces of
    one claim, and a piece left out alone is held in place by the others."""
    a_all, b_all = data.edge_index_pairs()
    li = data.loop_edges()
    lo, hi = np.minimum(a_all[li], b_all[li]), np.maximum(a_all[li], b_all[li])
    out = np.full(len(li), -1, np.int64)
    sel = np.flatnonzero(which)
    if not len(sel):
        return out
    pts = np.column_stack([lo[sel], hi[sel]]).astype(float)
    pairs = cKDTree(pts).query_pairs(r=max(window, 0), p=np.inf, output_type="ndarray")
    out[sel] = clusters(len(sel), pairs[:, 0], pairs[:, 1])
    return out


def clusters(num_loops: int, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Cluster label per loop: connected components of the agreeing pairs (a loop without support: its own)."""
    adj = coo_matrix((np.ones(len(p)), (p, q)), shape=(num_loops, num_loops))
    return connected_components(adj, directed=False)[1]
