"""One front door: solver strategies inside RobustPoseGraph, robust methods behind one LoopRejector interface."""
import ast
from pathlib import Path

import numpy as np
import pytest

from graph import (
    BatchStrategy,
    GraphParams,
    IncrementalPoseGraph,
    IncrementalStrategy,
    PoseGraph,
    RobustPoseGraph,
    inject_false_loops,
    loop_rejector,
    optimize,
)
from graph.components import anchor_components
from graph.incremental import full_pass
from graph.rejection import ArrivalGate, Consensus, Direct, SplitChain
from tests.graph.synth import noisy_graph, square_laps

GRAPH = Path(__file__).resolve().parents[2] / "graph"


def lap_graph(seed: int = 0):
    data, truth = noisy_graph(square_laps(laps=2, side=5), np.random.default_rng(seed))
    return data, truth


def build(g: RobustPoseGraph, data) -> None:
    for k, nid in enumerate(data.node_ids.tolist()):
        g.add_node(nid, data.poses[k] if k == 0 else None)
    for e in range(data.num_edges):
        i, j = int(data.edge_from[e]), int(data.edge_to[e])
        if data.is_loop[e]:
            g.add_loop(i, j, data.measurements[e], information=data.information[e])
        else:
            g.add_odometry(i, j, data.measurements[e], information=data.information[e])


@pytest.mark.parametrize("strategy, cls", [("lm", BatchStrategy), ("isam2", IncrementalStrategy)])
def test_the_strategy_is_chosen_by_the_solver_setting(strategy, cls):
    by_arg = RobustPoseGraph(2, strategy=strategy)
    by_params = RobustPoseGraph(2, GraphParams().replace(solver=strategy))
    assert type(by_arg.strategy) is cls and type(by_params.strategy) is cls
    assert by_arg.incremental == (strategy == "isam2")


@pytest.mark.parametrize("robust", ["consensus", "gnc", "none"])
def test_built_graph_and_whole_file_solve_agree(robust):
    # the batch strategy's result() is the whole-graph solve of what was added: one code path, not two
    data, _ = lap_graph()
    params = GraphParams().replace(robust=robust)
    g = RobustPoseGraph(2, params)
    build(g, data)
    res = g.result()
    whole = RobustPoseGraph.solve(g.to_data(), params)
    np.testing.assert_array_equal(res.poses, whole.poses)
    assert res.loop_inlier.tolist() == whole.loop_inlier.tolist()
    np.testing.assert_array_equal(g.estimate()[1], res.poses)


def test_isam2_whole_file_solve_is_the_replay_with_the_online_classifier():
    # robust methods other than consensus keep the iSAM2 pass's own classification; consensus decides as batch
    # does (tests/graph/test_incremental_consensus.py)
    data, _ = lap_graph(1)
    bad, _ = inject_false_loops(data, 0.3, seed=2)
    params = GraphParams().replace(robust="gnc")
    res = optimize(bad, params, solver="isam2")
    ref = full_pass(anchor_components(bad)[0], IncrementalStrategy.online_params(params))
    np.testing.assert_array_equal(res.poses, ref.poses)
    assert res.loop_inlier.tolist() == ref.loop_inlier.tolist()
    assert optimize(bad, solver="isam2").loop_inlier.tolist() == optimize(bad).loop_inlier.tolist()


def test_the_robust_method_is_one_interface_chosen_by_params_and_graph():
    data, _ = lap_graph()
    p = GraphParams()
    assert type(loop_rejector(data, p)) is Consensus
    for m in ("gnc", "huber", "cauchy"):
        assert type(loop_rejector(data, p.replace(robust=m))) is ArrivalGate
        assert type(loop_rejector(data, p.replace(robust={"method": m, "gate_loops": False}))) is Direct
    assert type(loop_rejector(data, p.replace(robust="none"))) is Direct
    # the odometry chain in two parts that only loops link
    g = PoseGraph()
    for k in range(8):
        g.add_node(k, [k, 0, 0])
    for k in (0, 1, 2, 4, 5, 6):
        g.add_odometry(k, k + 1, [1, 0, 0], np.eye(3) * 1e-4)
    g.add_loop(2, 5, [3, 0, 0], np.eye(3) * 1e-4)
    g.add_loop(3, 6, [3, 0, 0], np.eye(3) * 1e-4)
    for m in ("consensus", "gnc", "huber"):
        assert type(loop_rejector(g.to_data(), p.replace(robust=m))) is SplitChain
    assert type(loop_rejector(g.to_data(), p.replace(robust="none"))) is Direct


def test_isam2_strategy_ignores_guesses_and_keeps_online_labels_until_the_final_solve():
    data, _ = lap_graph(2)
    g = RobustPoseGraph(2, strategy="isam2")
    build(g, data)
    ids, poses = g.update()
    g.set_guesses(np.zeros((data.num_nodes, 3)))          # iSAM2 keeps its own estimate
    np.testing.assert_array_equal(g.estimate()[1], poses)
    assert len(g.loop_inliers()) == data.num_loops
    res = g.result()
    assert res.loop_inlier.all() and g.loop_inliers().all()


def test_add_loop_rejects_a_probability_outside_0_1_in_both_strategies():
    for strategy in ("lm", "isam2"):
        g = RobustPoseGraph(2, strategy=strategy)
        g.add_node(0, [0, 0, 0])
        g.add_node(1)
        g.add_odometry(0, 1, [1, 0, 0], np.eye(3) * 1e-4)
        with pytest.raises(ValueError, match=r"\[0, 1\]"):
            g.add_loop(1, 0, [-1, 0, 0], np.eye(3) * 1e-4, probability=1.5)


def test_place_gives_an_unplaced_node_its_guess_once():
    inc = IncrementalPoseGraph()
    inc.add_node(0, [0, 0, 0])
    inc.add_node(1)
    assert inc.placed(0) and not inc.placed(1)
    with pytest.raises(ValueError, match="finite"):
        inc.place(1, [np.nan, 0, 0])
    inc.place(1, [1, 0, 0])
    assert inc.placed(1)
    np.testing.assert_array_equal(inc.pose(1), [1, 0, 0])
    with pytest.raises(ValueError, match="already placed"):
        inc.place(1, [2, 0, 0])


def _graph_modules():
    for path in sorted(GRAPH.glob("*.py")):
        yield path, ast.parse(path.read_text(), str(path))


def test_graph_writes_no_private_state_of_another_object():
    # `_replay` used to set `inc._guess[k]` on an IncrementalPoseGraph (issue 14)
    bad = []
    for path, tree in _graph_modules():
        for node in ast.walk(tree):
            targets = node.targets if isinstance(node, ast.Assign) else \
                [node.target] if isinstance(node, (ast.AugAssign, ast.AnnAssign)) else []
            for t in targets:
                while isinstance(t, ast.Subscript):
                    t = t.value
                if isinstance(t, ast.Attribute) and t.attr.startswith("_") and not t.attr.startswith("__") \
                        and not (isinstance(t.value, ast.Name) and t.value.id in ("self", "cls")):
                    bad.append(f"{path.name}:{node.lineno}")
    assert bad == []


def test_graph_has_no_function_local_imports():
    # a function-local import hid how the batch and incremental paths depended on each other (issue 14)
    bad = []
    for path, tree in _graph_modules():
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                bad += [f"{path.name}:{n.lineno}" for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))]
    assert bad == []
