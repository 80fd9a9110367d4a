"""`vslam batch` on the local process pool, and its parts: what INPUTS name, the hashes that decide what is redone,
the manifest, the summary, a killed worker process."""
from __future__ import annotations

import json
import os
import shutil
import signal
import threading
import time
from dataclasses import replace
from pathlib import Path

import pytest

from vslam.batch import BatchError, run_many
from vslam.batch.hashing import input_hash, stat_fingerprint
from vslam.batch.inputs import resolve_inputs
from vslam.batch.manifest import Manifest
from vslam.cli.main import main
from vslam.pipeline import PipelineConfig

QUICK = replace(PipelineConfig(), recording=replace(PipelineConfig().recording, enabled=False))


def _simulate(path: Path, frames: int = 30, seed: int = 0) -> Path:
    assert main(["simulate", str(path), "--frames", str(frames), "--size", "320x240", "--seed", str(seed),
                 "--quiet"]) == 0
    return path


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("fleet")
    for i in range(3):
        _simulate(root / f"s{i}", seed=i)
    _simulate(root / "long", frames=120, seed=7)
    return root


def _copy(fleet: Path, tmp: Path, names) -> Path:
    d = tmp / "fleet"
    for n in names:
        shutil.copytree(fleet / n, d / n)
    return d


# ------------------------------------------------------------------------------------------------------ inputs
def test_inputs_folder_glob_and_manifest_csv(fleet, tmp_path):
    assert [i.name for i in resolve_inputs([str(fleet)])] == ["long", "s0", "s1", "s2"]
    assert [i.name for i in resolve_inputs([str(fleet / "s*")])] == ["s0", "s1", "s2"]
    one = resolve_inputs([str(fleet / "s1")])
    assert [(i.name, i.sequence) for i in one] == [("s1", str(fleet / "s1"))]
    csv = tmp_path / "runs.csv"
    csv.write_text(f"sequence,name,overrides\n{fleet / 's0'},a,loops.mode=5; vo.max_features=300\n"
                   f"{os.path.relpath(fleet / 's1', tmp_path)},,\n")
    items = resolve_inputs([str(csv)])
    assert [(i.name, i.sequence, i.overrides) for i in items] == [
        ("a", str(fleet / "s0"), ("loops.mode=5", "vo.max_features=300")), ("s1", str(fleet / "s1"), ())]
    assert items[0].source == f"{csv}:2"
    # the same sequence named twice runs once; equal folder names are told apart by their parents
    assert len(resolve_inputs([str(fleet / "s0"), str(fleet)])) == 4
    (tmp_path / "r1").mkdir()
    (tmp_path / "r2").mkdir()
    shutil.copytree(fleet / "s0", tmp_path / "r1" / "night")
    shutil.copytree(fleet / "s1", tmp_path / "r2" / "night")
    names = [i.name for i in resolve_inputs([str(tmp_path / "r1" / "night"), str(tmp_path / "r2" / "night"),
                                             str(fleet / "s2")])]
    assert names == ["r1__night", "r2__night", "s2"]


@pytest.mark.parametrize("text, line, field", [
    ("sequence,robot\nx,1\n", 1, "robot"),
    ("name\nx\n", 1, None),
    ("sequence,name\n,x\n", 2, "sequence"),
    ("sequence,name\nx,../up\n", 2, "name"),
    ("sequence\nx,y\n", 2, None),
])
def test_bad_manifest_csv_names_file_line_and_field(tmp_path, text, line, field):
    csv = tmp_path / "bad.csv"
    csv.write_text(text)
    with pytest.raises(BatchError) as e:
        resolve_inputs([str(csv)])
    assert (e.value.path, e.value.line, e.value.field) == (csv, line, field)
    assert str(e.value).startswith(f"{csv}:{line}: ")


def test_inputs_that_name_nothing(tmp_path):
    with pytest.raises(BatchError, match="matched nothing"):
        resolve_inputs([str(tmp_path / "none-*")])
    (tmp_path / "empty").mkdir()
    with pytest.raises(BatchError, match="neither a sequence nor a folder"):
        resolve_inputs([str(tmp_path / "empty")])


def test_a_missing_scheduler_file_is_a_typed_error(fleet, tmp_path):
    pytest.importorskip("distributed", reason="dask[distributed] is the optional extra vslam[cluster]")
    with pytest.raises(BatchError, match="no such scheduler file"):
        run_many([fleet / "s0"], QUICK, str(tmp_path / "sched.json"), out=tmp_path / "out")


# ------------------------------------------------------------------------------------------------------ hashing
def test_input_hash_follows_content_not_timestamps(fleet, tmp_path):
    a = tmp_path / "a"
    shutil.copytree(fleet / "s0", a)
    h = input_hash(a)
    assert h == input_hash(fleet / "s0")                      # a copy is the same input
    st = stat_fingerprint(a)
    os.utime(a / "frames.csv", ns=(1, 1))
    assert stat_fingerprint(a) != st and input_hash(a) == h   # touched: re-read, same hash
    with open(a / "frames.csv", "a") as f:
        f.write("\n")
    assert input_hash(a) != h
    assert input_hash(tmp_path / "missing") == "missing"


def test_unreadable_manifest_is_a_typed_error(tmp_path):
    (tmp_path / "batch.json").write_text("{not json")
    with pytest.raises(BatchError, match="batch.json"):
        Manifest.load(tmp_path)
    (tmp_path / "batch.json").write_text(json.dumps({"version": 1, "sequences": {"a": {"status": "odd"}}}))
    with pytest.raises(BatchError) as e:
        Manifest.load(tmp_path)
    assert e.value.field == "status"


# ------------------------------------------------------------------------------------------------------ runs
def test_local_pool_runs_resumes_and_redoes_what_changed(fleet, tmp_path):
    src = _copy(fleet, tmp_path, ["s0", "s1", "s2"])
    out = tmp_path / "out"
    seen = []
    summary = run_many([src], QUICK, out=out, workers=2, progress=lambda s: seen.append(s.finished))
    assert summary.exit_code == 0 and summary.counts()["ran"] == 3
    assert seen[-1] == 3
    rows = {r["name"]: r for r in summary.rows}
    for n in ("s0", "s1", "s2"):
        traj = (out / n / "trajectory_slam.txt").read_text().split("\n")
        assert rows[n]["status"] == "done" and rows[n]["ate_slam_m"] > 0
        assert rows[n]["frames"] == sum(1 for line in traj if line and not line.startswith("#"))
        assert not (out / n / "recording.rrd").exists()
    assert summary.files["png"].stat().st_size > 0
    assert json.loads(summary.files["json"].read_text())["counts"]["done"] == 3
    assert not list((out / ".batch").glob("*/*"))            # staging, attempts, markers: cleaned up

    # resumed: nothing to do
    again = run_many([src], QUICK, out=out, workers=2)
    assert again.counts() == {"sequences": 3, "done": 3, "failed": 0, "reused": 3, "ran": 0}
    # a changed input, a changed configuration (a manifest row's override): only those run
    with open(src / "s1" / "frames.csv", "a") as f:
        f.write("\n")
    csv = tmp_path / "runs.csv"
    csv.write_text(f"sequence,overrides\n{src / 's0'},\n{src / 's1'},\n{src / 's2'},vo.max_features=300\n")
    third = run_many([csv], QUICK, out=out, workers=2)
    assert {r["name"]: r["reused"] for r in third.rows} == {"s0": True, "s1": False, "s2": False}
    assert third.exit_code == 0


def test_failures_are_reported_the_others_done_and_earlier_outputs_kept(fleet, tmp_path, capsys):
    src = _copy(fleet, tmp_path, ["s0", "s1"])
    out = tmp_path / "out"
    assert run_many([src], QUICK, out=out, workers=2).exit_code == 0
    before = (out / "s1" / "trajectory_slam.txt").read_bytes()
    # s1 now broken; a bad override on s0's manifest row; a path that does not exist
    (src / "s1" / "frames.csv").write_text("timestamp,image\nx,y.jpg\n")
    csv = tmp_path / "runs.csv"
    csv.write_text(f"sequence,overrides\n{src / 's0'},vo.max_featurez=3\n{src / 's1'}\n{tmp_path / 'gone'}\n")
    rc = main(["batch", str(csv), str(fleet / "s2"), "--out", str(out), "--no-recording", "--workers", "2"])
    assert rc == 1
    text = capsys.readouterr().out
    assert "1 of 4 sequences done" in text and "3 failed" in text
    rows = {r["name"]: r for r in json.loads((out / "summary.json").read_text())["sequences"]}
    assert rows["s2"]["status"] == "done"
    assert rows["s0"]["status"] == "failed" and f"{csv}:2" in rows["s0"]["error"] and "max_featurez" in \
        rows["s0"]["error"]
    assert rows["s1"]["status"] == "failed" and "frames.csv:2" in rows["s1"]["error"]
    assert rows["gone"]["status"] == "failed" and "no such file" in rows["gone"]["error"]
    assert (out / "s1" / "trajectory_slam.txt").read_bytes() == before   # the earlier run's outputs stay
    # failed ones stay failed until asked: --retry-failed runs them again
    stamp = json.loads((out / "batch.json").read_text())["sequences"]["s1"]["finished"]
    time.sleep(1.1)
    assert main(["batch", str(src / "s1"), "--out", str(out), "--no-recording", "--quiet"]) == 1
    assert json.loads((out / "batch.json").read_text())["sequences"]["s1"]["finished"] == stamp
    assert main(["batch", str(src / "s1"), "--out", str(out), "--no-recording", "--quiet", "--retry-failed"]) == 1
    assert json.loads((out / "batch.json").read_text())["sequences"]["s1"]["finished"] != stamp


def _killer(out: Path, name: str, times: int, killed: list, deadline: float) -> None:
    """SIGKILL the process running `name` each time a new attempt of it starts, `times` times."""
    marker = out / ".batch" / "running" / f"{name}.json"
    while len(killed) < times and time.monotonic() < deadline:
        try:
            info = json.loads(marker.read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            time.sleep(0.02)
            continue
        if info["pid"] not in killed:
            os.kill(info["pid"], signal.SIGKILL)
            killed.append(info["pid"])


@pytest.mark.parametrize("kills, status, attempts", [(1, "done", 2), (2, "failed", 2)])
def test_a_killed_worker_process_costs_only_its_sequence(fleet, tmp_path, kills, status, attempts):
    src = _copy(fleet, tmp_path, ["s0", "s1", "long"])
    out = tmp_path / "out"
    killed: list = []
    t = threading.Thread(target=_killer, args=(out, "long", kills, killed, time.monotonic() + 120))
    t.start()
    summary = run_many([src], QUICK, out=out, workers=2)
    t.join()
    assert len(killed) == kills
    rows = {r["name"]: r for r in summary.rows}
    assert rows["s0"]["status"] == rows["s1"]["status"] == "done"
    assert (rows["long"]["status"], rows["long"]["attempts"]) == (status, attempts)
    assert summary.exit_code == (0 if status == "done" else 1)
    if status == "failed":
        assert "worker lost" in rows["long"]["error"] and not (out / "long").exists()
    assert not list((out / ".batch").glob("*/*"))            # no staging folder or marker of the killed process
