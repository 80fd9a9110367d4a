"""The console: progress as a bar on a terminal and as a few whole lines in a log; `vslam run --json` prints one
JSON object on stdout and nothing else."""
import io
import json

import pytest

from vslam.cli.main import main
from vslam.cli.progress import Progress
from vslam.sim import SimConfig, simulate


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_in_a_log_is_a_few_whole_lines():
    log = io.StringIO()
    bar = Progress(0, label="vslam run", stream=log)
    for i in range(1, 441):
        bar.update(i, 440)
    bar.close()
    text = log.getvalue()
    assert "\r" not in text                                  # not "frame 1/18frame 2/18..." run together
    lines = text.splitlines()
    assert len(lines) == 4 and text.endswith("\n")
    assert lines[0].startswith("vslam run: 110/440 frames (25 %)") and lines[-1].startswith("vslam run: 440/440")


def test_progress_on_a_terminal_is_a_bar_and_quiet_is_silent():
    tty = _Terminal()
    bar = Progress(0, label="simulate", stream=tty)
    for i in range(1, 51):
        bar.update(i, 50)
    bar.close()
    assert "\r" in tty.getvalue() and "100%" in tty.getvalue() and "50/50" in tty.getvalue()
    quiet = _Terminal()
    bar = Progress(0, stream=quiet, enabled=False)
    bar.update(5, 10)
    bar.close()
    assert quiet.getvalue() == ""


@pytest.fixture(scope="module")
def small_seq(tmp_path_factory):
    root = tmp_path_factory.mktemp("console")
    simulate(SimConfig(width=160, height=120, focal=125.0, length=1.5, fps=8.0, seed=2), root / "seq")
    return root


def test_run_json_is_one_object_on_stdout(small_seq, capsys):
    assert main(["run", str(small_seq / "seq"), "--out", str(small_seq / "out"), "--no-recording", "--json"]) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)                            # the whole of stdout is one JSON object
    assert doc["out"] == str(small_seq / "out")
    assert doc["summary"]["frames"] == json.loads((small_seq / "out" / "metrics.json").read_text())["summary"][
        "frames"]
    assert "NaN" not in captured.out                          # strict JSON: undefined figures are null
    assert "vslam run:" in captured.err and "\r" not in captured.err   # progress went to stderr, as lines


def test_run_quiet_prints_nothing(small_seq, capsys):
    assert main(["run", str(small_seq / "seq"), "--out", str(small_seq / "out2"), "--no-recording", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
