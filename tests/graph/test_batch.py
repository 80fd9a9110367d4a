import numpy as np
import pytest

from graph import GraphParams, PoseGraph, inject_false_loops, loop_scores, optimize
from odometry.shared.poses import between
from tests.graph.synth import ate, noisy_graph, square_laps

COV = np.diag([0.01 ** 2, 0.01 ** 2, 0.005 ** 2])


def square_graph(turn_error: float = 0.0) -> PoseGraph:
    g = PoseGraph()
    g.add_node(0, [0.0, 0.0, 0.0])
    for k in range(1, 4):
        g.add_node(k)                                    # placed by odometry
    for k in range(3):
        g.add_odometry(k, k + 1, [1.0, 0.0, np.pi / 2 + turn_error], COV)
    g.add_loop(3, 0, [1.0, 0.0, np.pi / 2], COV)
    return g


@pytest.mark.parametrize("robust", ["none", "gnc", "huber", "cauchy"])
@pytest.mark.parametrize("init", ["lago", "odometry"])
def test_square_loop_is_solved_exactly(robust, init):
    res = square_graph().optimize(robust=robust, init=init)
    expect = np.array([[0, 0, 0], [1, 0, np.pi / 2], [1, 1, np.pi], [0, 1, -np.pi / 2]])
    d = res.poses - expect
    d[:, 2] = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(d).max() < 1e-7
    assert res.final_cost < 1e-10
    assert res.loop_inlier.tolist() == [True]


def test_square_loop_spreads_a_consistent_error():
    # every turn over-measured by 0.02 rad: the loop pulls the heading back, spreading the error
    g = square_graph(turn_error=0.02)
    res = g.optimize(robust="none")
    assert 0 < res.final_cost < res.initial_cost
    closing = between(res.poses[3], res.poses[0])
    assert abs(closing[2] - np.pi / 2) < 0.03                    # the loop is (nearly) satisfied


def two_lap_graph(seed=0):
    rng = np.random.default_rng(seed)
    data, truth = noisy_graph(square_laps(laps=3, side=6), rng)
    return data, truth


def test_injected_false_loop_is_rejected_and_does_not_bend_the_map():
    data, truth = two_lap_graph()
    clean = optimize(data, GraphParams.preset("least_squares"))
    # one false loop: nodes 3 and 40 claimed to be 0.5 m apart (they are far apart)
    bad = data.append_edges([data.node_ids[40]], [data.node_ids[3]], [[0.5, 0.0, 0.3]], [data.information[0]], True)
    plain = optimize(bad, GraphParams.preset("least_squares"))
    robust = optimize(bad, GraphParams())
    is_false = np.zeros(bad.num_loops, bool)
    is_false[-1] = True
    assert ate(clean.poses, plain.poses) > 0.2                   # least squares bends the map
    assert ate(clean.poses, robust.poses) < 1e-3
    assert robust.loop_inlier.tolist() == (~is_false).tolist()
    assert robust.loop_weight[-1] == 0.0 and robust.loops_rejected == 1


@pytest.mark.parametrize("gate", [True, False])
def test_many_false_loops_gnc_recovers_the_clean_solution(gate):
    data, truth = two_lap_graph(seed=1)
    clean = optimize(data, GraphParams.preset("least_squares"))
    bad, injected = inject_false_loops(data, 0.5, seed=3)
    res = optimize(bad, GraphParams().replace(robust={"gate_loops": gate}))
    sc = loop_scores(res.loop_inlier, injected[bad.is_loop])
    assert sc.false_rejected == 1.0
    assert sc.recall >= 0.95
    assert ate(clean.poses, res.poses) < 0.02


def test_gtsam_gnc_backend_runs_and_labels():
    data, _ = two_lap_graph()
    bad = data.append_edges([data.node_ids[40]], [data.node_ids[3]], [[0.5, 0.0, 0.3]], [data.information[0]], True)
    res = optimize(bad, GraphParams().replace(robust={"gnc_impl": "gtsam", "gate_loops": False, "reinit_rounds": 0}))
    assert not res.loop_inlier[-1] and res.loop_inlier[:-1].all()


def test_probability_shifts_the_threshold():
    from graph.thresholds import loop_thresholds

    p = GraphParams()
    c = loop_thresholds(np.array([np.nan, 0.5, 0.99, 0.01]), 3, p)
    assert c[0] == pytest.approx(c[1]) and c[2] > c[0] > c[3] > 0
    assert np.all(loop_thresholds(np.array([0.01, 0.99]), 3, p.replace(robust={"loop_weighting": "none"})) == c[0])


def test_result_maps_ids_and_writers(tmp_path):
    g = PoseGraph()
    for k, nid in enumerate([7, 3, 1000]):
        g.add_node(nid, [k, 0, 0])
    g.add_odometry(7, 3, [1, 0, 0], COV)
    g.add_odometry(3, 1000, [1, 0, 0], COV)
    res = g.optimize()
    np.testing.assert_allclose(res.pose(1000), [2, 0, 0], atol=1e-9)
    with pytest.raises(KeyError):
        res.pose(8)
    g.write_g2o(tmp_path / "o.g2o", res)
    text = (tmp_path / "o.g2o").read_text()
    assert [ln.split()[1] for ln in text.splitlines() if ln.startswith("VERTEX")] == ["7", "3", "1000"]
    res.write_tum(tmp_path / "t.txt")
    rows = np.loadtxt(tmp_path / "t.txt")
    assert rows[:, 0].tolist() == [7, 3, 1000] and rows.shape == (3, 8)


def test_api_rejects_bad_input():
    g = PoseGraph()
    g.add_node(0, [0, 0, 0])
    g.add_node(1)
    with pytest.raises(ValueError, match="already exists"):
        g.add_node(0)
    with pytest.raises(KeyError, match="unknown node id 5"):
        g.add_odometry(0, 5, [1, 0, 0], COV)
    with pytest.raises(ValueError, match="3x3"):
        g.add_odometry(0, 1, [1, 0, 0], np.eye(2))
    with pytest.raises(ValueError, match="positive definite"):
        g.add_odometry(0, 1, [1, 0, 0], -np.eye(3))
    with pytest.raises(ValueError, match="exactly one"):
        g.add_odometry(0, 1, [1, 0, 0])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        g.add_loop(1, 0, [1, 0, 0], COV, probability=1.5)
    with pytest.raises(ValueError, match="itself"):
        g.add_loop(1, 1, [0, 0, 0], COV)
    with pytest.raises(ValueError, match="LAGO"):
        PoseGraph(dim=3).optimize(init="lago") if False else optimize(_tiny3d().to_data(), init="lago")


def _tiny3d() -> PoseGraph:
    g = PoseGraph(dim=3)
    g.add_node(0, [0, 0, 0, 0, 0, 0, 1])
    g.add_node(1)
    g.add_odometry(0, 1, [1, 0, 0, 0, 0, 0, 1], np.eye(6) * 1e-4)
    return g


def test_3d_cube_loop_is_solved_exactly():
    import gtsam

    # a closed loop in 3D: four edges of a tilted square, all consistent
    steps = [gtsam.Pose3(gtsam.Rot3.Ypr(np.pi / 2, 0.0, 0.1), np.array([1.0, 0.0, 0.2]))] * 4
    truth = [gtsam.Pose3()]
    for s in steps[:3]:
        truth.append(truth[-1].compose(s))
    def row(p):
        q = p.rotation().toQuaternion()
        return [*p.translation(), q.x(), q.y(), q.z(), q.w()]
    g = PoseGraph(dim=3)
    g.add_node(0, row(truth[0]))
    for k in range(1, 4):
        g.add_node(k)
    cov = np.eye(6) * 1e-4
    for k in range(3):
        g.add_odometry(k, k + 1, row(truth[k].between(truth[k + 1])), cov)
    g.add_loop(3, 0, row(truth[3].between(truth[0])), cov)
    for robust in ("none", "gnc"):
        res = g.optimize(robust=robust)
        np.testing.assert_allclose(res.poses[:, :3], np.array([t.translation() for t in truth]), atol=1e-7)
        assert res.final_cost < 1e-10 and res.loop_inlier.all()


def test_odometry_guess_composes_reversed_edges():
    # w10000 stores odometry newer -> older; the guess must invert those measurements
    data, truth = two_lap_graph()
    rev = data.copy()
    odo = ~rev.is_loop
    rev.edge_from[odo], rev.edge_to[odo] = data.edge_to[odo].copy(), data.edge_from[odo].copy()
    from odometry.shared.poses import inverse

    rev.measurements[odo] = inverse(data.measurements[odo])
    rev.poses[:] = np.nan
    from graph.initial import spanning_tree_guess

    anchor = np.zeros(1, np.int64)
    ga = spanning_tree_guess(data, anchor, np.zeros((1, 3)), *data.edge_index_pairs())
    gb = spanning_tree_guess(rev, anchor, np.zeros((1, 3)), *rev.edge_index_pairs())
    np.testing.assert_allclose(gb, ga, atol=1e-9)
    # the guess follows odometry, not the loops
    np.testing.assert_allclose(ga[1:4], data.poses[1:4], atol=1e-9)
    b = optimize(rev, GraphParams.preset("least_squares"), init="odometry")
    a = optimize(data, GraphParams.preset("least_squares"), init="odometry")
    assert ate(a.poses, b.poses) < 0.01      # same graph up to the frame each edge's noise is expressed in
