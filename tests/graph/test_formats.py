import numpy as np
import pytest

from graph import GraphFormatError, PoseGraphData, classify_edges, read_g2o, read_graph, read_toro, write_graph

G2O_2D = """# a comment that must survive
VERTEX_SE2 10 0 0 0
VERTEX_SE2 20 1 0 0.1
FIX 10
VERTEX_SE2 35 2 0.5 0.2
EDGE_SE2 10 20 1 0 0.1 100 2 3 200 4 50
# between the edges
EDGE_SE2 20 35 1 0.5 0.1 100 0 0 100 0 10
EDGE_SE2 35 10 -2 -0.1 -0.2 10 0 0 10 0 1
"""

G2O_3D = """VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 1 1 0 0 0 0 0.0998334 0.9950042
EDGE_SE3:QUAT 0 1 1 0 0 0 0 0.0998334 0.9950042 100 1 2 3 4 5 100 6 7 8 9 100 10 11 12 400 13 14 400 15 400
"""


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_g2o_2d_read_keeps_ids_order_information_and_fix(tmp_path):
    d = read_g2o(_write(tmp_path, "a.g2o", G2O_2D))
    assert d.dim == 2
    assert d.node_ids.tolist() == [10, 20, 35]
    assert d.fixed.tolist() == [10]
    assert d.edge_from.tolist() == [10, 20, 35] and d.edge_to.tolist() == [20, 35, 10]
    # upper triangle row by row: I11 I12 I13 I22 I23 I33
    np.testing.assert_array_equal(d.information[0], [[100, 2, 3], [2, 200, 4], [3, 4, 50]])
    # 10-20 and 20-35 are consecutive in vertex order (odometry), 35-10 is a loop, whatever the id values
    assert d.is_loop.tolist() == [False, False, True]


@pytest.mark.parametrize("text,suffix", [(G2O_2D, ".g2o"), (G2O_3D, ".g2o")])
def test_g2o_round_trip_is_exact_and_keeps_comments(tmp_path, text, suffix):
    a = read_graph(_write(tmp_path, "in" + suffix, text))
    out = tmp_path / ("out" + suffix)
    write_graph(out, a)
    b = read_graph(out)
    assert a.equals(b, atol=0.0)
    written = out.read_text().splitlines()
    assert written[0] == "# a comment that must survive" or text is G2O_3D
    if text is G2O_2D:
        # comment stays between the edges, FIX stays after vertex 20
        assert written.index("# between the edges") == written.index(next(w for w in written if w.startswith("EDGE_SE2 10"))) + 1
        assert written[3] == "FIX 10"


def test_g2o_3d_information_is_full_symmetric(tmp_path):
    d = read_g2o(_write(tmp_path, "b.g2o", G2O_3D))
    assert d.dim == 3
    info = d.information[0]
    np.testing.assert_array_equal(info, info.T)
    assert info[0, 1] == 1 and info[0, 5] == 5 and info[4, 5] == 15 and info[5, 5] == 400
    np.testing.assert_allclose(np.linalg.norm(d.measurements[0, 3:]), 1.0, atol=1e-6)


def test_toro_information_order_differs_from_g2o(tmp_path):
    # TORO EDGE2: Ixx Ixy Iyy Itt Ixt Iyt
    p = _write(tmp_path, "t.graph", "VERTEX2 0 0 0 0\nVERTEX2 1 1 0 0\nEDGE2 0 1 1 0 0 10 1 20 30 2 3\nEQUIV 0 1\n")
    d = read_toro(p)
    np.testing.assert_array_equal(d.information[0], [[10, 1, 2], [1, 20, 3], [2, 3, 30]])
    # TORO -> g2o -> TORO keeps the matrix, and the g2o file stores it in g2o order
    g2o = tmp_path / "t.g2o"
    write_graph(g2o, d)
    assert "EDGE_SE2 0 1 1 0 0 10 1 2 20 3 30" in g2o.read_text()
    back = tmp_path / "back.graph"
    write_graph(back, read_g2o(g2o))
    assert "EDGE2 0 1 1 0 0 10 1 20 30 2 3" in back.read_text()
    # EQUIV is TORO-only: kept in TORO output, dropped from g2o
    write_graph(tmp_path / "again.graph", d)
    assert "EQUIV 0 1" in (tmp_path / "again.graph").read_text()
    assert "EQUIV" not in g2o.read_text()


def test_toro_round_trip_of_a_real_file_is_byte_identical(tmp_path):
    from pathlib import Path

    import gtsam

    src = Path(gtsam.__file__).parent / "Data" / "w100.graph"
    if not src.exists():
        pytest.skip("gtsam wheel without Data/w100.graph")
    d = read_graph(src)
    out = tmp_path / "w100.graph"
    write_graph(out, d)
    assert out.read_text() == src.read_text()
    assert read_graph(out).equals(d, atol=0.0)


def test_isam_style_edge2_in_g2o_order_is_detected(tmp_path):
    # iSAM writes EDGE2 with g2o-ordered values; in TORO order "50 0 0 50 0 100" is not positive definite
    p = _write(tmp_path, "i.txt", "EDGE2 0 1 1 0 0 50 0 0 50 0 100\nEDGE2 1 2 1 0 0 50 0 0 50 0 100\n")
    d = read_graph(p)
    np.testing.assert_array_equal(np.diag(d.information[0]), [50, 50, 100])
    assert np.isnan(d.poses).all() and d.node_ids.tolist() == [0, 1, 2]
    with pytest.raises(GraphFormatError, match="not positive definite"):
        read_toro(p, info_order="toro")


def test_toro_3d_rpy_round_trip(tmp_path):
    line = "EDGE3 0 1 1 2 3 0.1 -0.2 0.3 " + " ".join(["10 0 0 0 0 0", "10 0 0 0 0", "10 0 0 0", "100 0 0", "100 0", "25"])
    d = read_toro(_write(tmp_path, "s.txt", "VERTEX3 0 0 0 0 0 0 0\nVERTEX3 1 1 2 3 0.1 -0.2 0.3\n" + line + "\n"))
    out = tmp_path / "s.graph"
    write_graph(out, d)
    again = read_toro(out)
    assert again.equals(d, atol=1e-12)
    np.testing.assert_allclose(d.poses[1], d.measurements[0], atol=1e-12)


@pytest.mark.parametrize("text,line,message", [
    ("VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 1 1 0 x 1 0 0 1 0 1\n", 2, "non-numeric value 'x'"),
    ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 0 0\n", 2, "needs 4 fields"),
    ("VERTEX_SE2 0 0 0 0\nLANDMARK 1 0 0\n", 2, "unknown record type 'LANDMARK'"),
    ("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 1 0 0\n", 2, "duplicate vertex id 0"),
    ("\n# c\nEDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n", 3, "not positive definite"),
    ("VERTEX_SE2 0 0 0 0\nVERTEX_SE3:QUAT 1 0 0 0 0 0 0 1\n", 2, "2D and 3D mixed"),
    ("VERTEX_SE3:QUAT 1 0 0 0 0 0 0 0\n", 1, "zero quaternion"),
    ("VERTEX_SE2 0 0 0 nan\n", 1, "NaN or infinite"),
    ("VERTEX_SE2 a 0 0 0\n", 1, "vertex ids must be integers"),
    ("EDGE_SE2 3 3 1 0 0 1 0 0 1 0 1\n", 1, "to itself"),
    ("VERTEX_SE2 0 0 0 0\nFIX 7\n", 2, "FIX names vertex 7"),
])
def test_malformed_g2o_names_file_and_line(tmp_path, text, line, message):
    p = _write(tmp_path, "bad.g2o", text)
    with pytest.raises(GraphFormatError) as err:
        read_graph(p)
    assert str(err.value).startswith(f"{p}:{line}: ")
    assert message in str(err.value)
    assert err.value.line == line
    assert isinstance(err.value, ValueError)


def test_empty_file_is_an_error(tmp_path):
    with pytest.raises(GraphFormatError, match="empty"):
        read_graph(_write(tmp_path, "e.g2o", "# nothing\n\n"))


def test_classify_edges_uses_input_order_not_id_values():
    ids = np.array([5, 100, 7, 42])
    is_loop = classify_edges(ids, np.array([5, 100, 7, 5, 42]), np.array([100, 7, 42, 7, 100]))
    assert is_loop.tolist() == [False, False, False, True, True]


def test_edges_only_file_orders_nodes_by_id_and_writes_every_vertex(tmp_path):
    d = read_graph(_write(tmp_path, "e.g2o", "EDGE_SE2 2 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"))
    assert d.node_ids.tolist() == [0, 1, 2] and not d.is_loop.any()
    out = tmp_path / "o.g2o"
    write_graph(out, d, np.zeros((3, 3)))
    assert [ln.split()[1] for ln in out.read_text().splitlines() if ln.startswith("VERTEX")] == ["0", "1", "2"]


def test_data_validation():
    with pytest.raises(ValueError, match="dim"):
        PoseGraphData(4, [], [], [], [], [], [], [], [])
    with pytest.raises(ValueError, match="rows"):
        PoseGraphData(2, [0, 1], np.zeros((2, 3)), [0], [1], np.zeros((2, 3)), np.zeros((1, 3, 3)), [False], [1.0])
