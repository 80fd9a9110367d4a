"""graph.support.loop_support (pairs from a k-d tree, planar cycles composed from angles) against the definition:
every pair of loops with both ends within the window, the cycle composed as homogeneous matrices."""
import numpy as np
from scipy.stats import chi2

from graph.support import chain_poses, loop_support
from tests.graph.synth import noisy_graph, square_laps


def _matrix(x, y, t):
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def _reference(data, window, threshold):
    a_all, b_all = data.edge_index_pairs()
    li = data.loop_edges()
    a, b = a_all[li], b_all[li]
    z = [_matrix(*m) for m in data.measurements[li]]
    z = [np.linalg.inv(m) if s else m for m, s in zip(z, a > b)]
    a, b = np.minimum(a, b), np.maximum(a, b)
    cov = np.linalg.inv(data.information[li])
    odo = np.linalg.inv(data.information[~data.is_loop]).mean(axis=0)
    x = chain_poses(data)
    order = np.argsort(a, kind="stable")
    out = []
    for i, p in enumerate(order):
        for q in order[i + 1:]:
            if abs(a[p] - a[q]) > window or abs(b[p] - b[q]) > window:
                continue
            m = np.linalg.inv(z[q]) @ np.linalg.inv(x[a[q]]) @ x[a[p]] @ z[p] @ np.linalg.inv(x[b[p]]) @ x[b[q]]
            e = np.array([m[0, 2], m[1, 2], np.arctan2(m[1, 0], m[0, 0])])
            s = cov[p] + cov[q] + (abs(a[p] - a[q]) + abs(b[p] - b[q])) * odo
            r2 = float(e @ np.linalg.solve(s, e))
            if r2 <= threshold:
                out.append((p, q, r2))
    return out


def test_loop_support_matches_the_pairwise_definition():
    data, _ = noisy_graph(square_laps(3, 12), np.random.default_rng(4))
    rng = np.random.default_rng(5)
    # false loops, some mutually close, claimed in either direction
    i = rng.integers(0, data.num_nodes - 12, 30)
    j = np.clip(i + rng.integers(3, 40, 30), 0, data.num_nodes - 1)
    src, dst = np.where(rng.random(30) < 0.5, i, j), np.where(rng.random(30) < 0.5, j, i)
    z = np.column_stack([rng.normal(0, 0.3, (30, 2)), rng.normal(0, 0.2, 30)])
    data = data.append_edges(data.node_ids[src], data.node_ids[dst], z,
                             np.broadcast_to(data.information[0], (30, 3, 3)), True, np.full(30, np.nan))
    threshold = float(chi2.ppf(0.99, 3))
    for window in (3, 10):
        want = _reference(data, window, threshold)
        P, Q, r2 = loop_support(data, window, threshold)
        assert len(want) > 10
        assert [(p, q) for p, q, _ in want] == list(zip(P.tolist(), Q.tolist()))
        np.testing.assert_allclose(r2, [r for _, _, r in want], rtol=1e-9, atol=1e-12)
