"""`vslam batch --scheduler` on a real Dask cluster: a `dask scheduler` and two `dask worker` processes on
127.0.0.1, started here as subprocesses (bounded in time, torn down at the end).

One batch of four simulated sequences and one invalid one, with the worker running the longest sequence killed
mid-run: every valid sequence's outputs equal those of `vslam run`; the killed worker's sequence is started again
and finishes; the invalid one is reported and the others are done. Then the same batch resumed runs nothing again.
"""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from vslam.cli.main import main

distributed = pytest.importorskip("distributed", reason="dask[distributed] is the optional extra vslam[cluster]")

ROOT = Path(__file__).resolve().parents[2]
START_TIMEOUT = 60.0      # seconds for the scheduler and both workers to come up on a loaded machine
TIMING_KEYS = {"median_ms", "wall_seconds", "frames_per_second", "seconds"}   # metrics.json: timings of this run


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stop(procs: list[subprocess.Popen], grace: float = 5.0) -> None:
    """SIGTERM every process, then SIGKILL the process groups still there after `grace` seconds in all."""
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + grace
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            pass
    for p in procs:
        try:
            os.killpg(p.pid, signal.SIGKILL)   # the nannies' worker processes too
        except ProcessLookupError:
            pass
        p.wait(timeout=10)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """The address of a scheduler with two single-threaded workers (each with a nanny that restarts it)."""
    tmp = tmp_path_factory.mktemp("dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    dask = [str(Path(sys.executable).parent / "dask")]
    logs = [open(tmp / f"{n}.log", "w") for n in ("scheduler", "worker1", "worker2")]
    procs = [subprocess.Popen([*dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              cwd=ROOT, env=env, stdout=logs[0], stderr=subprocess.STDOUT, start_new_session=True)]
    try:
        for i in (1, 2):
            procs.append(subprocess.Popen(
                [*dask, "worker", address, "--nthreads", "1", "--name", f"w{i}", "--host", "127.0.0.1",
                 "--no-dashboard", "--memory-limit", "0", "--local-directory", str(tmp / f"w{i}"),
                 "--death-timeout", "60"],
                cwd=ROOT, env=env, stdout=logs[i], stderr=subprocess.STDOUT, start_new_session=True))
        with distributed.Client(address, timeout=START_TIMEOUT) as client:
            client.wait_for_workers(2, timeout=START_TIMEOUT)
        yield address
    finally:
        _stop(procs)
        for f in logs:
            f.close()


def _simulate(path: Path, frames: int, seed: int) -> Path:
    assert main(["simulate", str(path), "--frames", str(frames), "--size", "320x240", "--seed", str(seed),
                 "--quiet"]) == 0
    return path


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Four sequences (one long enough to be killed mid-run) and an invalid one, in one folder."""
    root = tmp_path_factory.mktemp("fleet")
    for i, frames in enumerate((40, 40, 40, 120)):
        _simulate(root / f"seq{i}", frames, seed=i)
    bad = root / "seq9-bad"
    bad.mkdir()
    (bad / "camera.yaml").write_text((root / "seq0" / "camera.yaml").read_text())
    (bad / "frames.csv").write_text("timestamp,image\n0.0,img/0.jpg\nnot-a-number,img/1.jpg\n")
    return root


def _strip_timings(d):
    if isinstance(d, dict):
        return {k: _strip_timings(v) for k, v in d.items() if k not in TIMING_KEYS}
    return d


def _assert_same_outputs(ref: Path, got: Path) -> None:
    files = sorted(p.relative_to(ref).as_posix() for p in ref.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(got).as_posix() for p in got.rglob("*") if p.is_file())
    assert "trajectory_slam.txt" in files and "recording.rrd" in files
    for f in files:
        if f == "recording.rrd":
            continue   # Rerun stamps the wall clock into it: two `vslam run`s differ too
        if f == "metrics.json":
            assert _strip_timings(json.loads((ref / f).read_text())) == _strip_timings(json.loads((got / f).read_text()))
            continue
        assert (ref / f).read_bytes() == (got / f).read_bytes(), f


def _kill_when_running(out: Path, name: str, killed: dict, deadline: float) -> None:
    """Kill the worker process running `name` as soon as its running-marker appears."""
    marker = out / ".batch" / "running" / f"{name}.json"
    while time.monotonic() < deadline:
        try:
            info = json.loads(marker.read_text())
        except (FileNotFoundError, json.JSONDecodeError):
            time.sleep(0.02)
            continue
        os.kill(info["pid"], signal.SIGKILL)
        killed.update(info)
        return


def test_batch_on_a_dask_cluster_survives_a_killed_worker_and_resumes(cluster, fleet, tmp_path, capsys):
    out = tmp_path / "out"
    killed: dict = {}
    killer = threading.Thread(target=_kill_when_running, args=(out, "seq3", killed, time.monotonic() + 120))
    killer.start()
    rc = main(["batch", str(fleet), "--out", str(out), "--scheduler", cluster, "--quiet"])
    killer.join()
    assert rc == 1                                   # one sequence failed
    assert killed, "the long sequence never ran"
    manifest = json.loads((out / "batch.json").read_text())["sequences"]
    assert sorted(manifest) == ["seq0", "seq1", "seq2", "seq3", "seq9-bad"]
    bad = manifest["seq9-bad"]
    assert bad["status"] == "failed"
    assert "frames.csv" in bad["error"] and ":3" in bad["error"]    # names the file and the line
    for name in ("seq0", "seq1", "seq2", "seq3"):
        assert manifest[name]["status"] == "done", manifest[name]
    assert manifest["seq3"]["attempts"] == 2         # the killed worker's sequence was started once more
    assert manifest["seq3"]["pid"] != killed["pid"]
    # the others ran once, unless a loaded machine made the scheduler give up on a live worker too (it then
    # reschedules that worker's task by itself); never more than the limit
    assert all(1 <= manifest[n]["attempts"] <= 2 for n in ("seq0", "seq1", "seq2"))
    summary = (out / "summary.csv").read_text().splitlines()
    assert summary[0].startswith("name,status,")
    assert len(summary) == 6
    assert (out / "summary.png").stat().st_size > 0

    # the same outputs as `vslam run` on each sequence
    for name in ("seq0", "seq3"):
        ref = tmp_path / "ref" / name
        assert main(["run", str(fleet / name), "--out", str(ref), "--quiet"]) == 0
        _assert_same_outputs(ref, out / name)

    # resumed: nothing runs again (the failed one too, without --retry-failed)
    stamps = {n: (out / n / "trajectory_slam.txt").stat().st_mtime_ns for n in ("seq0", "seq1", "seq2", "seq3")}
    capsys.readouterr()
    rc = main(["batch", str(fleet), "--out", str(out), "--scheduler", cluster])
    assert rc == 1
    assert "4 of 5 sequences done (0 run now, 4 from an earlier run), 1 failed" in capsys.readouterr().out
    assert stamps == {n: (out / n / "trajectory_slam.txt").stat().st_mtime_ns for n in stamps}
    again = json.loads((out / "batch.json").read_text())["sequences"]
    assert {n: again[n]["finished"] for n in again} == {n: manifest[n]["finished"] for n in manifest}
