import numpy as np

from vslam.cli.main import main

GRAPH = """# square with a loop, ids not contiguous
VERTEX_SE2 10 0 0 0
VERTEX_SE2 20 1.1 0 1.5
VERTEX_SE2 30 1 1.2 3.1
VERTEX_SE2 40 0 1 -1.5
EDGE_SE2 10 20 1 0 1.5707963 100 0 0 100 0 400
EDGE_SE2 20 30 1 0 1.5707963 100 0 0 100 0 400
EDGE_SE2 30 40 1 0 1.5707963 100 0 0 100 0 400
EDGE_SE2 40 10 1 0 1.5707963 100 0 0 100 0 400
"""


def test_graph_optimize_keeps_ids_and_writes_outputs(tmp_path, capsys):
    src = tmp_path / "in.g2o"
    src.write_text(GRAPH)
    out, tum, labels = tmp_path / "out.g2o", tmp_path / "traj.txt", tmp_path / "loops.csv"
    rc = main(["graph", "optimize", str(src), "--out", str(out), "--tum", str(tum), "--labels", str(labels),
               "--robust", "gnc", "--solver", "lm"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "loops kept 1 / rejected 0" in text and "cost" in text and "iterations" in text
    lines = out.read_text().splitlines()
    assert lines[0] == "# square with a loop, ids not contiguous"
    vertices = [ln.split() for ln in lines if ln.startswith("VERTEX_SE2")]
    assert [v[1] for v in vertices] == ["10", "20", "30", "40"]
    xy = np.array([[float(v[2]), float(v[3])] for v in vertices])
    np.testing.assert_allclose(xy, [[0, 0], [1, 0], [1, 1], [0, 1]], atol=1e-6)
    assert [ln for ln in lines if ln.startswith("EDGE")] == [ln for ln in GRAPH.splitlines() if ln.startswith("EDGE")]
    assert np.loadtxt(tum).shape == (4, 8)
    assert labels.read_text().splitlines()[1].startswith("3,40,10,1,")


def test_graph_optimize_isam2_to_toro(tmp_path, capsys):
    src = tmp_path / "in.g2o"
    src.write_text(GRAPH)
    out = tmp_path / "out.graph"
    assert main(["graph", "optimize", str(src), "--out", str(out), "--solver", "isam2", "--robust", "none"]) == 0
    assert out.read_text().startswith("# square") and "EDGE2 10 20" in out.read_text()


def test_graph_malformed_input_exits_2_with_file_and_line(tmp_path, capsys):
    src = tmp_path / "bad.g2o"
    src.write_text(GRAPH.replace("EDGE_SE2 20 30 1 0", "EDGE_SE2 20 30 1 zero"))
    rc = main(["graph", "optimize", str(src), "--out", str(tmp_path / "o.g2o")])
    err = capsys.readouterr().err
    assert rc == 2
    assert f"{src}:7: EDGE_SE2: non-numeric value 'zero'" in err
    assert not (tmp_path / "o.g2o").exists()


def test_graph_info(tmp_path, capsys):
    src = tmp_path / "in.g2o"
    src.write_text(GRAPH)
    assert main(["graph", "info", str(src)]) == 0
    assert "4 vertices (SE(2)), 4 edges: 3 odometry, 1 loops" in capsys.readouterr().out


def test_graph_optimize_reads_settings_from_config_and_set(tmp_path, capsys):
    src = tmp_path / "in.g2o"
    src.write_text(GRAPH)
    cfg = tmp_path / "graph.yaml"
    cfg.write_text("graph:\n  robust:\n    support_window: 20\n")      # a pipeline config's section works too
    assert main(["graph", "optimize", str(src), "--out", str(tmp_path / "o.g2o"), "--config", str(cfg),
                 "--set", "robust.calibration_margin=5", "--set", "graph.solver.lm_max_iterations=7",
                 "--print-config"]) == 0
    text = capsys.readouterr().out
    assert "support_window: 20" in text and "calibration_margin: 5" in text and "lm_max_iterations: 7" in text
    assert not (tmp_path / "o.g2o").exists()          # --print-config only prints
    assert main(["graph", "optimize", str(src), "--out", str(tmp_path / "o.g2o"), "--set",
                 "robust.method=none"]) == 0
    assert "robust none" in capsys.readouterr().out


def test_graph_optimize_bad_or_removed_setting_is_a_clear_error(tmp_path, capsys):
    src = tmp_path / "in.g2o"
    src.write_text(GRAPH)
    rc = main(["graph", "optimize", str(src), "--out", str(tmp_path / "o.g2o"), "--set", "robust.support_window=-1"])
    err = capsys.readouterr().err
    assert rc != 0 and "--set" in err and "support_window" in err
    rc = main(["graph", "optimize", str(src), "--out", str(tmp_path / "o.g2o"), "--set",
               "robust.data_snooping=true"])
    err = capsys.readouterr().err
    assert rc != 0 and "data_snooping" in err and "removed" in err
    assert not (tmp_path / "o.g2o").exists()
