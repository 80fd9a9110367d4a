"""`vslam localize build/query/eval` end to end on small synthetic image folders."""
import csv
import json

import cv2
import pytest

from vslam.cli.main import main

from ._vocab_helpers import perturb, texture


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("loc")
    (root / "keys").mkdir()
    (root / "queries").mkdir()
    for i in range(6):
        img = texture(200 + i)
        cv2.imwrite(str(root / "keys" / f"key{i}.png"), img)
        cv2.imwrite(str(root / "queries" / f"q{i}.png"), perturb(img, i))
    (root / "truth.csv").write_text("query,key\n" + "".join(f"q{i}.png,key{i}.png\n" for i in range(6))
                                    + "q0.png,key1.png\n")
    return root


def test_build_query_eval(folders, tmp_path, capsys):
    mem = tmp_path / "m.vmem"
    assert main(["localize", "build", str(folders / "keys"), "--descriptor", "orb", "--preset", "fast",
                 "--out", str(mem)]) == 0
    assert mem.stat().st_size > 0
    assert main(["localize", "query", str(mem), str(folders / "queries" / "q2.png"), "--top", "2",
                 "--csv", str(tmp_path / "r.csv")]) == 0
    out = capsys.readouterr().out
    assert "q2.png" in out and out.split("q2.png")[1].split(":", 1)[1].strip().startswith("key2.png")
    rows = list(csv.DictReader(open(tmp_path / "r.csv")))
    assert rows[0]["rank"] == "1" and rows[0]["key"] == "key2.png"

    out_dir = tmp_path / "ev"
    assert main(["localize", "eval", str(folders / "keys"), str(folders / "queries"), "--truth",
                 str(folders / "truth.csv"), "--descriptor", "brief", "--preset", "fast", "--out", str(out_dir)]) == 0
    ranking = list(csv.DictReader(open(out_dir / "ranking.csv")))
    assert list(ranking[0]) == ["query", "rank", "key", "score"]
    firsts = {r["query"]: r["key"] for r in ranking if r["rank"] == "1"}
    assert firsts == {f"q{i}.png": f"key{i}.png" for i in range(6)}
    metrics = json.loads((out_dir / "metrics.json").read_text())
    assert metrics["n_tests"] == 6 and metrics["correct_mu1"] == 6 and metrics["recall_at_1"] == 1.0
    assert (out_dir / "report.md").read_text().count("| BRIEF |") == 1
    assert (out_dir / "pr.png").stat().st_size > 0


def test_sequence_directory_is_accepted(folders, tmp_path):
    seq = tmp_path / "seq"
    (seq / "img").mkdir(parents=True)
    lines = ["timestamp,image"]
    for i in range(6):
        cv2.imwrite(str(seq / "img" / f"{i:03d}.png"), texture(200 + i))
        lines.append(f"{i * 0.1:.1f},img/{i:03d}.png")
    (seq / "frames.csv").write_text("\n".join(lines) + "\n")
    assert main(["localize", "build", str(seq), "--preset", "fast", "--out", str(tmp_path / "s.vmem")]) == 0


@pytest.mark.parametrize("truth, message", [
    ("q,k\nq0.png,key0.png\n", "line 1: header must be 'query,key'"),
    ("query,key\nq0.png,nokey.png\n", "line 2: field 'key': no key image named 'nokey.png'"),
    ("query,key\nq0.png\n", "line 2: expected 2 fields"),
])
def test_bad_truth_files_are_one_line_errors(folders, tmp_path, capsys, truth, message):
    t = tmp_path / "t.csv"
    t.write_text(truth)
    code = main(["localize", "eval", str(folders / "keys"), str(folders / "queries"), "--truth", str(t),
                 "--descriptor", "brief", "--preset", "fast", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and str(t) in err


def test_empty_folder_and_grayscale_colour_errors(folders, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["localize", "build", str(tmp_path / "empty"), "--out", str(tmp_path / "x.vmem")]) == 2
    assert "no images found" in capsys.readouterr().err
    gray = tmp_path / "gray"
    gray.mkdir()
    cv2.imwrite(str(gray / "g.png"), texture(1, color=False))
    assert main(["localize", "build", str(gray), "--descriptor", "color-whole", "--out", str(tmp_path / "g.vmem")]) == 2
    assert "g.png: is a grayscale image" in capsys.readouterr().err
    assert not (tmp_path / "g.vmem").exists()
