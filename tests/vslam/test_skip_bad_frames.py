"""--skip-bad-frames on every command that reads a sequence: a missing or corrupt image is warned about, the run goes
on, the frame is flagged; without it a missing image is still an error (strict default)."""
import csv
import json
import shutil

import pytest

from vslam.cli.main import main


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    s = tmp_path_factory.mktemp("bad") / "seq"
    assert main(["simulate", str(s), "--frames", "14", "--quiet"]) == 0
    rows = list(csv.DictReader(open(s / "frames.csv")))
    (s / rows[5]["image"]).unlink()                                  # missing
    data = (s / rows[9]["image"]).read_bytes()
    (s / rows[9]["image"]).write_bytes(data[: len(data) // 3])       # truncated
    return s, rows[5]["image"], rows[9]["image"]


COMMANDS = {"odometry": ["odometry"], "run": ["run", "--no-recording"], "loops": ["loops"]}


@pytest.mark.parametrize("name", list(COMMANDS))
def test_strict_by_default_then_skips_and_flags(seq, tmp_path, capsys, name):
    root, missing, truncated = seq
    cmd = COMMANDS[name][:1] + [str(root), "--out", str(tmp_path / "o"), "--quiet"] + COMMANDS[name][1:]
    assert main(cmd) == 2
    err = capsys.readouterr().err
    assert missing.split("/")[-1] in err and "missing" in err
    assert main(cmd + ["--skip-bad-frames"]) == 0
    err = capsys.readouterr().err
    assert missing.split("/")[-1] in err and truncated.split("/")[-1] in err and "warning" in err
    out = tmp_path / "o"
    if name == "odometry":
        rows = list(csv.DictReader(open(out / "odometry.csv")))
        assert len(rows) == 14
        assert "could not be read" in rows[5]["reason"] and "truncated" in rows[9]["reason"]
        assert rows[4]["reason"] == ""
    elif name == "run":
        bad = json.loads((out / "run.json").read_text())["bad_frames"]
        assert [b["index"] for b in bad] == [5, 9] and "truncated" in bad[1]["problem"]
        assert json.loads((out / "metrics.json").read_text())["summary"]["bad_frames"] == 2
    else:
        summary = json.loads((out / "summary.json").read_text())
        assert summary["skipped_frames"] == 2 and len(summary["warnings"]) == 2


def test_localize_build_on_the_same_sequence(seq, tmp_path, capsys):
    root, missing, _ = seq
    assert main(["localize", "build", str(root), "--preset", "fast", "--out", str(tmp_path / "m.vmem")]) == 2
    assert main(["localize", "build", str(root), "--preset", "fast", "--out", str(tmp_path / "m.vmem"),
                 "--skip-bad-frames"]) == 0
    assert "2 of 14 key images" in capsys.readouterr().out


def test_a_sequence_without_bad_frames_has_none_flagged(tmp_path):
    clean = tmp_path / "clean"
    assert main(["simulate", str(clean), "--frames", "6", "--quiet"]) == 0
    out = tmp_path / "o"
    assert main(["run", str(clean), "--out", str(out), "--no-recording", "--quiet", "--skip-bad-frames"]) == 0
    assert json.loads((out / "run.json").read_text())["bad_frames"] == []
    shutil.rmtree(out)
