"""--out: a non-empty folder is refused unless --overwrite (which clears what the command wrote), an unwritable one
fails before any work, and SIGTERM leaves no partial recording."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from vslam.app.outdir import RUN_OUTPUTS, prepare_out_dir
from vslam.cli.main import main
from vslam.errors import VslamError
from vslam.pipeline import Pipeline

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    s = tmp_path_factory.mktemp("outdir") / "seq"
    assert main(["simulate", str(s), "--frames", "12", "--quiet"]) == 0
    return s


def test_a_used_out_folder_is_refused_then_cleared_with_overwrite(seq, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "recording.rrd").write_bytes(b"another sequence's recording")
    (out / "plots").mkdir()
    (out / "plots" / "old.png").write_bytes(b"stale")
    (out / "notes.txt").write_text("mine")
    assert main(["run", str(seq), "--out", str(out), "--no-recording", "--quiet"]) == 2
    assert "not empty" in capsys.readouterr().err and (out / "recording.rrd").exists()
    assert main(["run", str(seq), "--out", str(out), "--no-recording", "--quiet", "--overwrite"]) == 0
    assert not (out / "recording.rrd").exists() and not (out / "plots" / "old.png").exists()   # stale: gone
    assert (out / "plots" / "trajectories.png").is_file() and (out / "metrics.json").is_file()
    assert (out / "notes.txt").read_text() == "mine"    # not ours: kept


@pytest.mark.parametrize("command", [["odometry"], ["loops"]])
def test_odometry_and_loops_refuse_a_used_folder_too(seq, tmp_path, capsys, command):
    out = tmp_path / "out"
    out.mkdir()
    (out / "loops.csv").write_text("stale\n")
    (out / "trajectory_vo.txt").write_text("stale\n")
    assert main(command + [str(seq), "--out", str(out), "--quiet"]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(command + [str(seq), "--out", str(out), "--quiet", "--overwrite"]) == 0
    written = out / ("trajectory_vo.txt" if command == ["odometry"] else "loops.csv")
    assert written.read_text() != "stale\n"


def test_an_unwritable_out_fails_before_any_work(seq, tmp_path, monkeypatch, capsys):
    def no_work(*a, **k):
        raise AssertionError("the pipeline ran before the output folder was checked")
    monkeypatch.setattr(Pipeline, "run", no_work)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["run", str(seq), "--out", str(blocker / "out"), "--quiet"]) == 2
    assert "cannot write" in capsys.readouterr().err


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders; the case above covers it")
def test_a_read_only_folder_is_refused(tmp_path):
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        with pytest.raises(VslamError, match="cannot write"):
            prepare_out_dir(out, RUN_OUTPUTS)
    finally:
        out.chmod(0o755)


def test_sigterm_leaves_no_partial_recording(tmp_path):
    seq = tmp_path / "long"
    assert main(["simulate", str(seq), "--frames", "150", "--quiet"]) == 0
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "vslam", "run", str(seq), "--out", str(out), "--quiet"],
                            cwd=ROOT, env=env, stderr=subprocess.PIPE, text=True)
    partial = out / ".recording.rrd.partial"
    deadline = time.monotonic() + 120
    while not partial.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert partial.exists(), "the run ended before it could be interrupted"
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=60)[1]
    assert proc.returncode == 143, err
    assert not partial.exists() and not (out / "recording.rrd").exists()
