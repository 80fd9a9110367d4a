"""`vslam horizon` commands: memorise, recognise, pairs, evaluate; bad input gives one clear line and exit 2."""
from __future__ import annotations

import csv
import json

import cv2
import pytest

from vslam.cli.main import main

from .test_horizon import horizon_image, texture


@pytest.fixture(scope="module")
def images(tmp_path_factory):
    d = tmp_path_factory.mktemp("horizon_images")
    paths = {}
    views = {
        "north": lambda x: texture(x, 31),
        "north_turned": lambda x: texture((x - 60) / 1.08, 31),
        "south": lambda x: texture(x, 32),
        "elsewhere": lambda x: texture(x, 33),
    }
    for name, f in views.items():
        paths[name] = d / f"{name}.png"
        cv2.imwrite(str(paths[name]), horizon_image(f))
    return paths


def _read_csv(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_pairs_scores_every_pair_and_keeps_extra_columns(images, tmp_path):
    # Relative image paths are relative to the CSV's folder; absolute ones are used as they are.
    rel = images["north"].parent / "pairs.csv"
    rel.write_text(
        "a,b,row_a,row_b,label\n"
        f"north.png,north_turned.png,60,60,1\n"
        f"north.png,{images['south']},60,60,0\n"
        f"south.png,elsewhere.png,60,58:62,0\n")                  # LEFT:RIGHT: a tilted horizon line
    out = tmp_path / "scores.csv"
    assert main(["horizon", "pairs", str(rel), "--out", str(out), "--preset", "paper"]) == 0   # the paper's line
    rows = _read_csv(out)
    assert list(rows[0].keys()) == ["a", "b", "row_a", "row_b", "label", "score", "score_ransac", "b_s", "b_d"]
    assert len(rows) == 3
    same, diff = rows[0], rows[1]
    assert float(same["score_ransac"]) > 2 * float(diff["score_ransac"])
    assert float(same["b_s"]) == pytest.approx(1.08, abs=0.03)
    assert float(same["b_d"]) == pytest.approx(60, abs=8)
    # evaluate reads the label column and reports AUCs; --plot writes a PNG.
    png = tmp_path / "roc.png"
    assert main(["horizon", "evaluate", str(out), "--plot", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("content,message", [
    ("a,b,row_a\nx.png,y.png,3\n", "line 1: missing column(s) row_b"),
    ("a,b,row_a,row_b\nx.png,y.png,abc,4\n", "line 2, field row_a: 'abc' is not a horizon row"),
    ("a,b,row_a,row_b\nx.png,,4,4\n", "line 2, field b: empty image path"),
    ("a,b,row_a,row_b\nmissing.png,other.png,4,4\n", "missing.png: image not found"),
    ("a,b,row_a,row_b,score\nx.png,y.png,4,4,1\n", "would be overwritten"),
])
def test_pairs_bad_input_is_one_clear_line(tmp_path, capsys, content, message):
    pairs = tmp_path / "pairs.csv"
    pairs.write_text(content)
    out = tmp_path / "scores.csv"
    assert main(["horizon", "pairs", str(pairs), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()


def test_pairs_horizon_outside_image_names_the_image(images, tmp_path, capsys):
    pairs = tmp_path / "pairs.csv"
    pairs.write_text(f"a,b,row_a,row_b\n{images['north']},{images['south']},60,115\n")
    assert main(["horizon", "pairs", str(pairs), "--out", str(tmp_path / "s.csv"), "--preset", "paper"]) == 2
    err = capsys.readouterr().err
    assert "south.png" in err and "horizon row 115" in err
    # the default (fast) moves its bands inside the image, but a horizon outside it is still an error
    pairs.write_text(f"a,b,row_a,row_b\n{images['north']},{images['south']},60,500\n")
    assert main(["horizon", "pairs", str(pairs), "--out", str(tmp_path / "s.csv")]) == 2
    err = capsys.readouterr().err
    assert "south.png" in err and "horizon row 500 is outside the image" in err and err.count("\n") == 1
    pairs.write_text(f"a,b,row_a,row_b\n{images['north']},{images['south']},60,58:62\n")
    assert main(["horizon", "pairs", str(pairs), "--out", str(tmp_path / "s.csv")]) == 2
    assert "needs a level horizon" in capsys.readouterr().err


def test_memorise_then_recognise(images, tmp_path, capsys):
    mem = tmp_path / "landmarks.npz"
    assert main(["horizon", "memorise", str(images["north"]), str(images["south"]), "--row", "60",
                 "--out", str(mem), "--preset", "paper"]) == 0
    assert mem.exists()
    capsys.readouterr()
    js = tmp_path / "rec.json"
    assert main(["horizon", "recognise", str(mem), str(images["north_turned"]), str(images["elsewhere"]),
                 "--row", "60", "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "landmark north" in out and "no landmark" in out
    res = json.loads(js.read_text())
    assert res[0]["landmark"] == "north" and res[1]["landmark"] is None
    assert res[0]["b_s"] == pytest.approx(1.08, abs=0.03)
    # --append adds to the memory with its stored parameters.
    assert main(["horizon", "memorise", str(images["elsewhere"]), "--row", "60", "--out", str(mem), "--append",
                 "--names", "far"]) == 0
    capsys.readouterr()
    assert main(["horizon", "recognise", str(mem), str(images["elsewhere"]), "--row", "60"]) == 0
    assert "landmark far" in capsys.readouterr().out


def test_recognise_with_a_malformed_memory_names_the_file(images, tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    bad.write_text("not a memory")
    assert main(["horizon", "recognise", str(bad), str(images["north"]), "--row", "60"]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "not a valid horizon landmark memory" in err


def test_set_overrides_and_presets(images, tmp_path, capsys):
    pairs = tmp_path / "p.csv"
    pairs.write_text(f"a,b,row_a,row_b\n{images['north']},{images['north_turned']},60,60\n")
    assert main(["horizon", "pairs", str(pairs), "--out", str(tmp_path / "s.csv"), "--preset", "robust",
                 "--set", "ransac_tolerance=6"]) == 0
    assert main(["horizon", "pairs", str(pairs), "--out", str(tmp_path / "s.csv"), "--set", "nope=1"]) == 2
    assert "unknown HorizonParams field(s): nope" in capsys.readouterr().err
    assert main(["horizon", "pairs", str(pairs), "--out", str(tmp_path / "s.csv"), "--set", "ratio=3"]) == 2
    assert "ratio must be in (0, 1]" in capsys.readouterr().err


def test_the_default_preset_is_fast_and_memorises_every_band(images, tmp_path, capsys):
    """`vslam horizon` defaults to preset fast (the packed path: seven bands, one call per query)."""
    from loops.horizon import HorizonParams, load_memory

    mem = tmp_path / "fast.npz"
    assert main(["horizon", "memorise", str(images["north"]), str(images["south"]), "--row", "60",
                 "--out", str(mem)]) == 0
    memory = load_memory(mem)
    assert memory.params == HorizonParams.preset("fast") and memory.packed
    capsys.readouterr()
    js = tmp_path / "rec.json"
    assert main(["horizon", "recognise", str(mem), str(images["north_turned"]), str(images["elsewhere"]),
                 "--row", "60", "--json", str(js)]) == 0
    res = json.loads(js.read_text())
    assert res[0]["landmark"] == "north" and res[1]["landmark"] is None
    assert res[0]["b_s"] == 1.0 and res[0]["b_d"] == pytest.approx(60, abs=20)    # the turn; no scale on this path
    assert res[0]["threshold"] == HorizonParams.preset("fast").recognition_threshold
    # --append keeps the memory's parameters; a preset given with it is refused
    assert main(["horizon", "memorise", str(images["elsewhere"]), "--row", "60", "--out", str(mem), "--append",
                 "--preset", "fast"]) == 2
    assert "--append uses the parameters stored in the memory" in capsys.readouterr().err
