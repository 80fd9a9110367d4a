"""`vslam localize build/eval` with a blank wall, a corrupt and a missing key image: skipped with a warning, kept as
keys that never match, reported by count and name."""
import json
import shutil

import cv2
import numpy as np
import pytest

from loops.vocab import EmptyMemoryError, VisualMemory, preset
from vslam.cli.main import main

from ._vocab_helpers import perturb, texture


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    root = tmp_path_factory.mktemp("badkeys")
    (root / "keys").mkdir()
    (root / "queries").mkdir()
    for i in range(5):
        img = texture(300 + i)
        cv2.imwrite(str(root / "keys" / f"key{i}.png"), img)
        cv2.imwrite(str(root / "queries" / f"q{i}.png"), perturb(img, i))
    cv2.imwrite(str(root / "keys" / "wall.png"), np.full((240, 320, 3), 200, np.uint8))    # blank wall
    (root / "keys" / "broken.jpg").write_bytes(b"\xff\xd8\xff\xe0 not really a jpeg")
    (root / "truth.csv").write_text("query,key\n" + "".join(f"q{i}.png,key{i}.png\n" for i in range(5)))
    return root


@pytest.mark.parametrize("descriptor", ["orb", "brief"])
def test_build_skips_blank_and_corrupt_keys(folders, tmp_path, capsys, descriptor):
    mem = tmp_path / "m.vmem"
    assert main(["localize", "build", str(folders / "keys"), "--descriptor", descriptor, "--preset", "fast",
                 "--out", str(mem)]) == 0
    cap = capsys.readouterr()
    assert "2 of 7 key images have no features or could not be read" in cap.out
    assert "broken.jpg" in cap.out and "wall.png" in cap.out
    assert "warning: key image broken.jpg skipped" in cap.err and "warning: key image wall.png has no" in cap.err
    memory = VisualMemory.load(mem)
    assert sorted(memory.key_names[i] for i in memory.featureless) == ["broken.jpg", "wall.png"]
    for i in range(5):     # the good keys still match, the empty ones never come first
        r = memory.query(perturb(texture(300 + i), i))
        assert memory.key_names[r.keys[0]] == f"key{i}.png"


def test_eval_reports_the_skipped_keys(folders, tmp_path, capsys):
    out = tmp_path / "ev"
    assert main(["localize", "eval", str(folders / "keys"), str(folders / "queries"), "--truth",
                 str(folders / "truth.csv"), "--descriptor", "orb", "--preset", "fast", "--out", str(out)]) == 0
    assert "2 of 7 key images" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["n_tests"] == 5 and metrics["recall_at_1"] == 1.0


def test_missing_key_in_frames_csv_needs_skip_bad_frames(folders, tmp_path, capsys):
    seq = tmp_path / "seq"
    shutil.copytree(folders / "keys", seq / "img")
    names = sorted(p.name for p in (seq / "img").glob("key*.png")) + ["gone.png"]
    (seq / "frames.csv").write_text("timestamp,image\n" + "".join(f"{i * 0.1:.1f},img/{n}\n"
                                                                 for i, n in enumerate(names)))
    assert main(["localize", "build", str(seq), "--preset", "fast", "--out", str(tmp_path / "a.vmem")]) == 2
    assert "gone.png is missing" in capsys.readouterr().err
    assert main(["localize", "build", str(seq), "--preset", "fast", "--out", str(tmp_path / "a.vmem"),
                 "--skip-bad-frames"]) == 0
    cap = capsys.readouterr()
    assert "1 of 6 key images" in cap.out and "img/gone.png" in cap.out and "img/gone.png skipped" in cap.err


def test_a_memory_of_blank_images_only_is_refused():
    blank = [np.full((120, 160), 90, np.uint8)] * 3
    with pytest.raises(EmptyMemoryError, match="none of the 3 key images"):
        VisualMemory.build(blank, ["a", "b", "c"], preset("fast", descriptor="orb"))
