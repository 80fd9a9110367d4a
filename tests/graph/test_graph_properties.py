"""Property tests of the g2o / TORO reader and writer (hypothesis): any graph round-trips exactly, ids of any size
included; any corruption of a valid file is read or rejected with a GraphFormatError naming the file and a line of
it; whatever is read either optimises or raises a GraphError. The long version: `python -m vslam.bench.fuzz_graphs`.
"""
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from graph import GraphParams, PoseGraphData, optimize, read_graph, write_graph
from graph.errors import GraphError
from graph.formats import GraphFormatError
from graph.model import classify_edges

FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
ids_any = st.integers(-(2 ** 70), 2 ** 70)


@st.composite
def graphs(draw, dim=None):
    dim = draw(st.sampled_from([2, 3])) if dim is None else dim
    n = draw(st.integers(2, 8))
    ids = draw(st.lists(ids_any, min_size=n, max_size=n, unique=True))
    w, d = (3, 3) if dim == 2 else (7, 6)

    def pose():
        if dim == 2:
            return [draw(finite), draw(finite), draw(st.floats(-3.1, 3.1))]
        q = np.array([draw(st.floats(-1, 1)) for _ in range(4)])
        if np.linalg.norm(q) < 0.1:
            q = np.array([0.0, 0.0, 0.0, 1.0])
        return [draw(finite), draw(finite), draw(finite), *(q / np.linalg.norm(q)).tolist()]

    def info():
        a = np.array([[draw(st.floats(-10, 10)) for _ in range(d)] for _ in range(d)])
        m = a @ a.T + np.eye(d) * draw(st.floats(0.5, 100))
        return 0.5 * (m + m.T)

    pairs = [(k, k + 1) for k in range(n - 1)]
    pairs += [p for p in draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=4))
              if p[0] != p[1]]
    ei = [ids[a] for a, _ in pairs]
    ej = [ids[b] for _, b in pairs]
    m = len(pairs)
    poses = np.array([pose() for _ in range(n)]).reshape(n, w)
    meas = np.array([pose() for _ in range(m)]).reshape(m, w)
    infos = np.array([info() for _ in range(m)]).reshape(m, d, d)
    comments = draw(st.lists(st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp")), max_size=12)
                             .map(lambda t: "# " + t.strip()), max_size=2))
    return PoseGraphData(dim, ids, poses, ei, ej, meas, infos, classify_edges(ids, ei, ej), np.ones(m),
                         comments=comments)


@contextmanager
def _scratch(name: str) -> Iterator[Path]:
    # Hypothesis runs each test hundreds of times: every example's directory is removed after it.
    with tempfile.TemporaryDirectory(prefix="graphprop-") as d:
        yield Path(d) / name


@FAST
@given(graphs())
def test_g2o_round_trip_is_exact_for_any_graph(data):
    with _scratch("g.g2o") as out:
        write_graph(out, data)
        back = read_graph(out)
        assert back.node_ids.tolist() == data.node_ids.tolist()            # Python ints, any size, exact
        assert back.edge_from.tolist() == data.edge_from.tolist() and back.edge_to.tolist() == data.edge_to.tolist()
        assert back.equals(data, atol=0.0)
        assert back.comments == data.comments


@FAST
@given(graphs())
def test_toro_round_trip_keeps_ids_and_values(data):
    with _scratch("g.graph") as out:
        write_graph(out, data)
        back = read_graph(out)
        assert back.node_ids.tolist() == data.node_ids.tolist()
        if data.dim == 2:
            assert back.equals(data, atol=0.0)
        else:   # roll / pitch / yaw on the way: the same rotation, sign of the quaternion aside
            np.testing.assert_allclose(back.poses[:, :3], data.poses[:, :3], rtol=1e-12, atol=1e-9)
            dots = np.abs(np.sum(back.poses[:, 3:] * data.poses[:, 3:], axis=1))
            np.testing.assert_allclose(dots, 1.0, atol=1e-9)


_VALID = ("# header\nVERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0.1\nVERTEX_SE2 1700000000123456789 2 0 0.2\nFIX 0\n"
          "EDGE_SE2 0 1 1 0 0.1 100 0 0 100 0 400\nEDGE_SE2 1 1700000000123456789 1 0 0.1 100 0 0 100 0 400\n"
          "EDGE_SE2 1700000000123456789 0 -2 0 -0.2 10 0 0 10 0 40\n")
_TOKENS = st.sampled_from(["nan", "inf", "-1", "0", "1e308", "1e400", "x", "", "VERTEX_SE2", "EDGE_SE2", "FIX",
                           "EDGE2", "VERTEX_XY", "PARAMS_SE3OFFSET", "\x00", "\ufeff", "#", "\r", str(2 ** 64),
                           "1700000000123456788", "0.5", "-0", "1_0"])


@st.composite
def corrupted(draw):
    text = _VALID
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["cut", "insert", "token", "delete"]))
        pos = draw(st.integers(0, len(text)))
        if kind == "cut":
            text = text[:pos]
        elif kind == "insert":
            text = text[:pos] + draw(st.one_of(_TOKENS, st.text(max_size=8))) + text[pos:]
        elif kind == "delete":
            text = text[:pos] + text[pos + draw(st.integers(1, 20)):]
        else:
            toks = text.split(" ")
            toks[draw(st.integers(0, len(toks) - 1))] = draw(_TOKENS)
            text = " ".join(toks)
    return text


_IDS = ["0", "1", "1700000000123456789", "1700000000123456788", "7", str(2 ** 64)]


@st.composite
def degenerate(draw):
    """The valid file with well-formed records changed: lines dropped or repeated, ids re-pointed (missing vertices,
    other components, self-edges), values replaced by any finite number."""
    lines = _VALID.splitlines()
    for _ in range(draw(st.integers(1, 4))):
        k = draw(st.integers(0, len(lines) - 1))
        kind = draw(st.sampled_from(["drop", "repeat", "id", "value"]))
        toks = lines[k].split()
        if kind == "drop" and len(lines) > 1:
            del lines[k]
        elif kind == "repeat":
            lines.insert(k, lines[k])
        elif kind == "id" and len(toks) > 1 and toks[0] != "#":
            toks[draw(st.integers(1, 2 if toks[0].startswith("EDGE") else 1))] = draw(st.sampled_from(_IDS))
            lines[k] = " ".join(toks)
        elif kind == "value" and len(toks) > 3 and toks[0] != "FIX":
            toks[draw(st.integers(3 if toks[0].startswith("EDGE") else 2, len(toks) - 1))] = repr(
                draw(st.floats(-1e12, 1e12, allow_nan=False)))
            lines[k] = " ".join(toks)
    return "\n".join(lines) + "\n"


def _read_or_reject(path: Path, n_lines: int):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return read_graph(path)
    except GraphFormatError as exc:
        assert str(exc).startswith(str(path))
        assert exc.line is None or 1 <= exc.line <= n_lines
        return None


@FAST
@given(corrupted())
def test_any_corruption_is_read_or_rejected_naming_file_and_line(text):
    with _scratch("c.g2o") as p:
        p.write_text(text, encoding="utf-8", errors="surrogatepass")
        _read_or_reject(p, max(1, len(p.read_bytes().splitlines()) + 1))


@FAST
@given(st.binary(max_size=300))
def test_any_bytes_are_read_or_rejected(blob):
    with _scratch("b.g2o") as p:
        p.write_bytes(blob)
        _read_or_reject(p, len(blob.splitlines()) + 1)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(degenerate(), degenerate(), corrupted()), st.sampled_from(["gnc", "none"]))
def test_whatever_is_read_optimises_or_raises_a_graph_error(text, robust):
    with _scratch("c.g2o") as p:
        p.write_text(text, encoding="utf-8", errors="surrogatepass")
        data = _read_or_reject(p, len(text.splitlines()) + 1)
        event("read" if data is not None else "rejected")
        if data is None:
            return
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                res = optimize(data, GraphParams(), robust=robust)
            except GraphError:
                event("graph error")
                return
        assert res.poses.shape == data.poses.shape
        assert res.node_ids.tolist() == data.node_ids.tolist()
