"""`vslam bench graph`: rows resume and skip, stale rows are flagged or redone, --jobs gives the same rows, a crashed
peer loses its row only, the converged reference is cached, and the g2o peer solves the same problem as GTSAM."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from graph import GraphParams, optimize, write_graph
from graph.batch import build, initial_guess
from graph.params import InitMethod
from tests.graph.synth import noisy_graph, square_laps
from vslam.bench import graph_methods, graph_rows, graph_tables
from vslam.bench.graph_g2o import PeerCrashed, solve_in_child
from vslam.bench.graph_reference import converged_reference
from vslam.cli.main import main


@pytest.fixture
def tiny_shared(tmp_path, monkeypatch):
    """A shared-data folder whose "ring" is a 72-pose graph (three laps of a square) with its ground truth."""
    data, truth = noisy_graph(square_laps(laps=3, side=6), np.random.default_rng(5))
    root = tmp_path / "shared"
    ring = root / "posegraphs" / "vertigo_from_pyslam" / "ring"
    (ring / "originalDataset").mkdir(parents=True)
    (ring / "groundTruth").mkdir()
    write_graph(ring / "originalDataset" / "ring.g2o", data)
    np.savetxt(ring / "groundTruth" / "poses.txt", truth)
    monkeypatch.setenv("VSLAM_SHARED_DATA", str(root))
    graph_rows._graph.cache_clear()
    yield root
    graph_rows._graph.cache_clear()


def _bench(out, *extra, code: int = 0) -> None:
    assert main(["bench", "graph", "--no-docs", "--datasets", "ring", "--fractions", "0,0.3", "--policies",
                 "random,local-grouped", "--seeds", "1", "--methods", "ours,dcs", "--out", str(out), *extra]) == code


def _rows(out) -> dict:
    return {graph_rows.row_key(r): r for r in json.loads(out.read_text())["rows"]}


def _forbid(monkeypatch, *methods) -> None:
    def boom(_data):
        raise AssertionError("solved a row that was already in the file")
    for m in methods:
        monkeypatch.setitem(graph_methods.METHODS, m, boom)


def test_rerun_skips_rows_already_in_the_file(tiny_shared, tmp_path, monkeypatch):
    out = tmp_path / "g.json"
    _bench(out)
    first = _rows(out)
    assert len(first) == 2 + 2 * 2                 # clean graph once, then 2 policies x 2 methods at 30 %
    assert all(r["status"] == "ok" for r in first.values())
    clean = first[("ring", "-", 0.0, 1, "ours")]
    assert clean["true_kept"] == 1.0 and clean["version"] == graph_rows.code_version()
    _forbid(monkeypatch, "ours", "dcs")
    _bench(out)                                    # would fail rows (status "failed") if it solved any
    assert _rows(out) == first
    assert (tmp_path / "graph-reference" / "ring.npz").exists()


def test_a_killed_run_keeps_its_finished_rows_and_the_rerun_does_the_rest(tiny_shared, tmp_path, monkeypatch):
    out = tmp_path / "g.json"
    real, calls = graph_methods.METHODS["dcs"], []

    def dies_on_second(data):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt            # the run is killed while solving a row
        return real(data)
    monkeypatch.setitem(graph_methods.METHODS, "dcs", dies_on_second)
    _bench(out, code=130)                          # the CLI's exit code on an interrupt
    kept = _rows(out)
    assert 1 <= len(kept) < 6 and all(r["status"] == "ok" for r in kept.values())
    monkeypatch.setitem(graph_methods.METHODS, "dcs", real)
    solved = []
    real_run = graph_rows.run_task
    monkeypatch.setattr(graph_rows, "run_task", lambda t, *a: solved.append(t.key) or real_run(t, *a))
    _bench(out)
    assert len(_rows(out)) == 6
    assert not set(solved) & set(kept)             # finished rows were not solved again


def test_stale_rows_are_flagged_and_redone_on_request(tiny_shared, tmp_path, monkeypatch, capsys):
    out = tmp_path / "g.json"
    _bench(out)
    d = json.loads(out.read_text())
    d["rows"][0]["version"] = "old"
    stale_key = graph_rows.row_key(d["rows"][0])
    out.write_text(json.dumps(d))
    capsys.readouterr()
    _bench(out)                                    # default: keep, flag
    assert _rows(out)[stale_key]["version"] == "old"
    assert "(stale)" in capsys.readouterr().out
    _bench(out, "--redo-stale")
    assert _rows(out)[stale_key]["version"] == graph_rows.code_version()


def test_two_jobs_give_the_rows_of_one(tiny_shared, tmp_path):
    one, two = tmp_path / "a" / "g.json", tmp_path / "b" / "g.json"
    _bench(one)
    _bench(two, "--jobs", "2")
    a, b = _rows(one), _rows(two)
    assert a.keys() == b.keys()
    for k in a:
        assert b[k]["status"] == "ok"
        for f in ("ate", "true_kept", "false_rejected"):
            assert b[k][f] == pytest.approx(a[k][f], abs=1e-9)


def test_a_crashed_peer_loses_its_row_only(tiny_shared, tmp_path, monkeypatch):
    def crash(_data):
        raise PeerCrashed("g2o child died (signal SIGSEGV)")
    monkeypatch.setitem(graph_methods.METHODS, "dcs", crash)
    out = tmp_path / "g.json"
    _bench(out)
    rows = _rows(out)
    assert {r["status"] for k, r in rows.items() if k[4] == "dcs"} == {"crashed"}
    assert {r["status"] for k, r in rows.items() if k[4] == "ours"} == {"ok"}


def test_a_peer_past_its_timeout_loses_its_row_only_and_one_within_it_gives_the_same_row(tiny_shared, tmp_path):
    def bench(out, timeout):
        assert main(["bench", "graph", "--no-docs", "--datasets", "ring", "--fractions", "0.3", "--policies",
                     "random", "--seeds", "1", "--methods", "ours,plain-lm", "--out", str(out),
                     "--peer-timeout", timeout]) == 0
        return _rows(out)
    cut = bench(tmp_path / "cut" / "g.json", "0.01")       # a spawned child cannot even import numpy in 10 ms
    lm = cut[("ring", "random", 0.3, 1, "plain-lm")]
    assert lm["status"] == "timeout" and lm["timeout_s"] == 0.01
    assert cut[("ring", "random", 0.3, 1, "ours")]["status"] == "ok"
    assert "not finished in 0 s" in graph_tables.cell(graph_tables.aggregate([lm])[("ring", "random", 0.3,
                                                                                      "plain-lm")], 0.3)
    full = bench(tmp_path / "full" / "g.json", "600")
    plain = bench(tmp_path / "plain" / "g.json", "0")
    a, b = full[("ring", "random", 0.3, 1, "plain-lm")], plain[("ring", "random", 0.3, 1, "plain-lm")]
    assert a["status"] == b["status"] == "ok"
    assert a["ate"] == pytest.approx(b["ate"], abs=1e-9) and a["true_kept"] == b["true_kept"]


def test_a_segfault_in_the_child_becomes_peer_crashed(tmp_path, monkeypatch):
    (tmp_path / "segv_child.py").write_text("import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)\n")
    monkeypatch.setenv("PYTHONPATH", str(tmp_path) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    z = np.zeros((1, 3))
    with pytest.raises(PeerCrashed, match="SIGSEGV"):
        solve_in_child(2, np.zeros((2, 3)), np.array([0]), np.array([1]), z, np.eye(3)[None], np.array([False]),
                       np.array([0]), 1.0, module="segv_child")


def test_converged_reference_is_cached_and_keyed_on_the_file(tmp_path, monkeypatch):
    data, _ = noisy_graph(square_laps(laps=2, side=5), np.random.default_rng(2))
    path = tmp_path / "g.g2o"
    write_graph(path, data)
    ref = converged_reference("g", path, data, tmp_path / "cache")
    plain = optimize(data, GraphParams.preset("least_squares"))
    assert np.abs(ref.poses - plain.poses).max() < 1e-4 and ref.iterations >= 1
    monkeypatch.setattr("vslam.bench.graph_reference.optimize", lambda *a: (_ for _ in ()).throw(AssertionError))
    again = converged_reference("g", path, data, tmp_path / "cache")     # from the cache: no solve
    assert np.array_equal(again.poses, ref.poses)
    os.utime(path, ns=(0, 0))                       # the file changed: solve again
    with pytest.raises(AssertionError):
        converged_reference("g", path, data, tmp_path / "cache")


def test_g2o_peer_without_kernel_reaches_gtsams_least_squares_optimum():
    pytest.importorskip("g2opy", reason="g2o peer needs the bench extra (g2opy)")
    data, _ = noisy_graph(square_laps(laps=2, side=5), np.random.default_rng(3))
    built = build(data, GraphParams.preset("least_squares"))
    init = initial_guess(data, built, InitMethod.ODOMETRY)
    poses, chi2, _ = solve_in_child(2, init, built.a, built.b, data.measurements, data.information, data.is_loop,
                                    built.anchors, 1e12)            # phi huge: the DCS scale is 1, least squares
    plain = optimize(data, GraphParams.preset("least_squares"))
    assert np.abs(poses[:, :2] - plain.poses[:, :2]).max() < 1e-4
    assert len(chi2) == data.num_loops and np.all(chi2 < 30)


def _row(method, fraction, ate, kept=1.0, rejected=1.0, seed=2, policy="random", **kw):
    return {"graph": "g", "policy": policy if fraction else "-", "fraction": fraction, "seed": seed,
            "method": method, "status": "ok", "ate": ate, "true_kept": kept, "false_rejected": rejected, "s": 1.0,
            "version": "v", **kw}


def test_target_line_names_each_missed_row_and_by_how_much():
    head = {"graph": "g", "nodes": 10, "loops": 5, "dim": 2, "reference": "ground truth", "ref_ate": 1.0,
            "ref_iterations": 4, "ref_s": 0.1, "clean_ate": 1.0, "clean_ate_opt": 0.0, "clean_s": 0.1}
    rows = [_row("ours", 0.0, 1.0), _row("ours", 0.3, 1.05), _row("ours", 0.3, 1.2, seed=5),   # worst seed: 1.2
            _row("ours", 0.5, 1.0, rejected=0.98), _row("dcs", 0.5, 0.9), _row("ours", 0.8, 9.0)]
    text = graph_tables.tables({"g": head}, rows, "v")
    line = text.splitlines()[-1]
    assert "2 row(s) miss" in line
    assert "random 30 %: ATE 1.2 > 1.06 m (+14.0 cm)" in line
    assert "wrong loops rejected 98.0 % < 99 %" in line and "ATE 1 > DCS (GTSAM) 0.9 m" in line
    assert "stretch" in text                          # 80 %: shown, not judged
    met = graph_tables.tables({"g": head}, [r for r in rows if r["fraction"] in (0.0, 0.8)], "v")
    assert met.splitlines()[-1] == "**g**: every row met the targets."
    assert "(stale)" in graph_tables.tables({"g": head}, [_row("ours", 0.0, 1.0, version="old")], "v")
    # the kept injected loops all state the truth (graph.labels): judged on the wrong ones, the row is met
    agree = [_row("ours", 0.0, 1.0), _row("ours", 0.5, 1.0, rejected=0.98, wrong_rejected=1.0)]
    text = graph_tables.tables({"g": head}, agree, "v")
    assert text.splitlines()[-1] == "**g**: every row met the targets." and "(100.0 of wrong)" in text


def test_priority_order_puts_each_method_clean_then_fifty_percent_first():
    tasks = graph_rows.plan(["a", "b"], {"a": 10, "b": 10}, ["random", "local"], [0, 0.1, 0.3, 0.5, 0.7], [2],
                            ["ours", "dcs"], 100)
    order = graph_rows.priority_order(tasks, ["ours", "dcs"])
    assert sorted(order, key=repr) == sorted(tasks, key=repr)
    assert [(t.method, t.fraction) for t in order[:6]] == [("ours", 0.0)] * 2 + [("ours", 0.5)] * 4
    assert order[len(order) // 2].method == "dcs" and order[-1].fraction == 0.7
