"""`vslam loops` and `vslam train-loops` end to end on small inputs."""
import csv
import json

import cv2
import pytest

from loops.cdvs.model import LoopModel
from tests.loops.test_cdvs_database import PATH
from tests.loops.test_cdvs_match import view
from vslam.cli.main import main


@pytest.fixture(scope="module")
def image_folder(tmp_path_factory):
    """A forward-facing-style plain image folder (no calibration, no odometry) that revisits its start."""
    d = tmp_path_factory.mktemp("imgs")
    for k, (x, y) in enumerate(PATH):
        cv2.imwrite(str(d / f"{k:04d}.png"), view(x, y, angle=7 * k))
    return d


def test_vslam_loops_on_an_image_folder(image_folder, tmp_path):
    out = tmp_path / "run"
    assert main(["loops", str(image_folder), "--mode", "4", "--out", str(out), "--exclude-recent", "5",
                 "--exclude-seconds", "0", "--quiet"]) == 0
    rows = list(csv.DictReader(open(out / "loops.csv")))
    assert rows and list(rows[0]) == ["query_frame", "match_frame", "global_score", "local_score", "probability",
                                      "accepted", "motion_consistent"]
    assert all(r["motion_consistent"] == "" for r in rows)    # an image folder has no odometry: nothing checked
    for r in rows:
        assert int(r["match_frame"]) <= int(r["query_frame"]) - 5
        assert r["accepted"] in ("0", "1") and 0.0 <= float(r["probability"]) <= 1.0
    revisit = [r for r in rows if int(r["query_frame"]) >= 16 and r["accepted"] == "1"]
    assert revisit, "the return to the start was not detected"
    s = json.loads((out / "summary.json").read_text())
    assert s["mode"] == 4 and s["keyframes"] == len(PATH) and s["geometry"] == "affine"


def test_vslam_loops_reports_bad_input(tmp_path, capsys):
    assert main(["loops", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "missing" in capsys.readouterr().err
    bad = tmp_path / "model.json"
    bad.write_text("{}")
    (tmp_path / "imgs").mkdir()
    cv2.imwrite(str(tmp_path / "imgs" / "0.png"), view(600, 600))
    assert main(["loops", str(tmp_path / "imgs"), "--out", str(tmp_path / "o"), "--model", str(bad)]) == 2
    assert "model.json" in capsys.readouterr().err


def test_train_loops_on_a_small_simulated_sequence(tmp_path):
    seq = tmp_path / "seq"
    assert main(["simulate", str(seq), "--floor", "tiles", "--trajectory", "loop", "--length", "3", "--fps", "8",
                 "--seed", "3", "--quiet"]) == 0
    out = tmp_path / "model.json"
    assert main(["train-loops", str(seq), "--out", str(out), "--modes", "2,5", "--every", "2", "--quiet"]) == 0
    m = LoopModel.load(out)
    assert sorted(m.curves) == [2, 5]
    assert m.provenance["relative_motion"].startswith("odometry.fusion")
    assert (tmp_path / "model.png").stat().st_size > 1000
    for mode in (2, 5):
        c = m.curves[mode]
        assert c.totals.sum() > 20 and c.positives.sum() > 0   # pairs were matched and some are loops
    assert main(["train-loops", str(seq), "--out", str(out), "--modes", "0"]) == 2
