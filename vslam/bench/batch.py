"""`vslam bench batch`: throughput of `vslam batch` over simulated sequences, in one run:

- sequential (baseline): `run_sequence` on each sequence in turn, in this process (what running `vslam run` by
  hand does, minus its start-up: a baseline that favours sequential),
- the local process pool (`run_many(workers=N)`),
- a local Dask cluster (`distributed.LocalCluster`, N single-threaded worker processes; its start-up is reported
  apart, as a real cluster is long-lived).

Each engine runs the batch `--repeats` times into a fresh folder (nothing skipped); medians are reported. The
per-sequence overhead of an engine is the worker time a sequence holds beyond its task: wall x workers / sequences
minus the mean time of the task itself (`seconds` in batch.json). The load average is read before and after each
engine: the machine may be shared, and load beyond the workers lowers the speedup.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib
import json
import logging
import os
import shutil
import statistics
import time
from pathlib import Path

import vslam.batch.warm  # noqa: F401  (the sequential baseline starts as warm as the pool's processes)
from vslam.app.run import run_sequence
from vslam.batch import run_many
from vslam.batch.pool import default_workers, start_server
from vslam.bench.results import BenchResult, write_json
from vslam.bench.timing import median
from vslam.evaluation.tables import format_table
from vslam.pipeline import PipelineConfig
from vslam.sim import SimConfig, simulate
from vslam.sim.simulate import length_for_frames


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="out/bench_batch", help="output folder (JSON, cached sequences, batch outputs)")
    p.add_argument("--sequences", type=int, default=8, help="simulated sequences in the batch (default 8)")
    p.add_argument("--frames", type=int, default=200, help="frames per sequence (default 200)")
    p.add_argument("--size", default="640x480", help="image size WxH (default 640x480)")
    p.add_argument("--workers", type=int, default=None, help="pool and cluster workers (default: one per CPU)")
    p.add_argument("--repeats", type=int, default=3, help="runs of each engine (median reported; default 3)")
    p.add_argument("--no-dask", action="store_true", help="skip the Dask cluster")
    p.add_argument("--quick", action="store_true", help="4 sequences of 60 frames at 320x240, 1 repeat")


def _sequences(cache: Path, n: int, frames: int, size: tuple[int, int]) -> list[Path]:
    paths = []
    for seed in range(n):
        w, h = size
        cfg = SimConfig(width=w, height=h, focal=500.0 * w / 640.0, seed=seed, max_frames=frames,
                        length=length_for_frames(frames, 20.0, 0.5))
        key = hashlib.sha1(json.dumps(cfg.to_dict(), sort_keys=True).encode()).hexdigest()[:10]
        path = cache / f"seq{seed:02d}-{key}"
        if not (path / "frames.csv").is_file():
            simulate(cfg, path, overwrite=True)
        paths.append(path)
    return paths


def _load() -> float:
    return os.getloadavg()[0]


def _sequential(paths: list[Path], out: Path, cfg: PipelineConfig) -> dict:
    shutil.rmtree(out, ignore_errors=True)
    load0, t0 = _load(), time.perf_counter()
    task_s, cpu_s = [], []
    for p in paths:
        t1, c1 = time.perf_counter(), time.process_time()
        run_sequence(str(p.resolve()), out / p.name, cfg)
        task_s.append(time.perf_counter() - t1)
        cpu_s.append(time.process_time() - c1)
    return {"wall": time.perf_counter() - t0, "task_seconds": task_s, "cpu_seconds": cpu_s, "load": [load0, _load()]}


def _batch(paths: list[Path], out: Path, cfg: PipelineConfig, workers: int, client=None) -> dict:
    shutil.rmtree(out, ignore_errors=True)
    load0, t0 = _load(), time.perf_counter()
    summary = run_many(paths, cfg, client, out=out, workers=workers)
    wall = time.perf_counter() - t0
    if not summary.ok:
        raise RuntimeError(f"batch into {out} failed: {[r['error'] for r in summary.failed]}")
    return {"wall": wall, "task_seconds": [r["seconds"] for r in summary.rows],
            "cpu_seconds": [r["cpu_seconds"] for r in summary.rows], "load": [load0, _load()]}


def _same_outputs(a: Path, b: Path, names: list[str]) -> bool:
    files = ("trajectory_vo.txt", "trajectory_slam.txt", "loops.csv", "graph.g2o", "run.json")
    return all((a / n / f).read_bytes() == (b / n / f).read_bytes() for n in names for f in files)


def _overhead(run: dict, n: int, workers: int) -> float:
    """Seconds of worker time per sequence beyond the task itself."""
    return run["wall"] * workers / n - statistics.fmean(run["task_seconds"])


def _start_cluster(workers: int):
    # on use: dask[distributed] is the optional extra vslam[cluster]
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    client.run(importlib.import_module, "vslam.batch.warm")   # what a long-lived worker has already imported
    return cluster, client, time.perf_counter() - t0


def _row(label: str, runs: list[dict], base: float, n: int, workers: int) -> list:
    wall = median([r["wall"] for r in runs])
    over = median([_overhead(r, n, workers) for r in runs])
    task = median([statistics.fmean(r["task_seconds"]) for r in runs])
    cpu = median([statistics.fmean(r["cpu_seconds"]) for r in runs])
    load = f"{min(r['load'][0] for r in runs):.1f}-{max(max(r['load']) for r in runs):.1f}"
    # CPU share: CPU-seconds the engine got per wall second, out of `workers` (what other jobs left to us)
    share = median([sum(r["cpu_seconds"]) / r["wall"] for r in runs])
    return [label, workers, f"{wall:.1f}", f"{n / wall * 3600:.0f}", f"{base / wall:.2f}", f"{task:.2f}",
            f"{cpu:.2f}", f"{over:+.2f}", f"{share:.2f}", load]


def run(args: argparse.Namespace) -> BenchResult:
    if args.quick:
        args.sequences, args.frames, args.size, args.repeats = 4, 60, "320x240", 1
    size = tuple(int(v) for v in args.size.lower().split("x"))
    workers = args.workers or default_workers()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"simulating {args.sequences} sequences of {args.frames} frames at {args.size} ...", flush=True)
    paths = _sequences(out / "sequences", args.sequences, args.frames, size)
    cfg = PipelineConfig()          # what `vslam run` does by default, Rerun recording included
    n = len(paths)
    res: dict[str, list[dict]] = {"sequential": [], "pool": [], "dask": []}
    cluster = client = None
    cluster_start = None
    pool_start = start_server()
    if not args.no_dask:
        cluster, client, cluster_start = _start_cluster(workers)
    try:
        for k in range(args.repeats):    # engines interleaved: a change of machine load hits all of them
            print(f"repeat {k + 1}/{args.repeats}: sequential ...", flush=True)
            res["sequential"].append(_sequential(paths, out / "sequential", cfg))
            print(f"repeat {k + 1}/{args.repeats}: local pool of {workers} ...", flush=True)
            res["pool"].append(_batch(paths, out / "pool", cfg, workers))
            if client is not None:
                print(f"repeat {k + 1}/{args.repeats}: Dask cluster of {workers} ...", flush=True)
                res["dask"].append(_batch(paths, out / "dask", cfg, workers, client))
    finally:
        if client is not None:
            # workers shutting down log their closed heartbeats as errors: not news at the end of a benchmark
            logging.getLogger("distributed").setLevel(logging.CRITICAL)
            client.close()
            cluster.close()
    names = [p.name for p in paths]
    same = _same_outputs(out / "sequential", out / "pool", names) and (
        not res["dask"] or _same_outputs(out / "sequential", out / "dask", names))
    base = median([r["wall"] for r in res["sequential"]])
    rows = [_row("sequential, one process (baseline)", res["sequential"], base, n, 1),
            _row("local process pool", res["pool"], base, n, workers)]
    if res["dask"]:
        rows.append(_row("local Dask cluster", res["dask"], base, n, workers))
    table = format_table(["engine", "workers", "wall (s)", "sequences/hour", "speedup", "task (s/seq)",
                          "CPU (s/seq)", "overhead (s/seq)", "CPUs used", "load avg"], rows)
    title = (f"{n} simulated sequences of {args.frames} frames at {args.size}, full pipeline with recording, on "
             f"{os.cpu_count()} CPUs; median of {args.repeats} runs per engine")
    notes = [f"outputs identical across engines (trajectories, loops, graph, run.json): {'yes' if same else 'NO'}"]
    if cluster_start is not None:
        dask_over = median([_overhead(r, n, workers) for r in res["dask"]])
        pool_over = median([_overhead(r, n, workers) for r in res["pool"]])
        notes.append(f"Dask path: {dask_over - pool_over:+.2f} s per sequence beyond the local pool")
    notes.append(f"start-up, once per batch command, not in the walls above: local pool's fork server "
                 f"{pool_start:.1f} s" + ("" if cluster_start is None else
                                         f"; Dask cluster of {workers} workers with the toolkit imported "
                                         f"{cluster_start:.1f} s (a real cluster is already up)"))
    notes.append("overhead = wall x workers / sequences - mean task time: worker time a sequence holds beyond its "
                 "own run (process start, scheduling, waiting for the last sequence); CPU = CPU seconds of the "
                 "process per sequence, all threads; CPUs used = CPU seconds of the tasks per wall second: a speedup "
                 "needs the CPUs that other jobs on the machine leave free")
    print(f"\n{title}\n{table}\n\n" + "\n".join(notes))
    write_json(out / "bench_batch.json", {"sequences": n, "frames": args.frames, "size": args.size,
                                          "workers": workers, "runs": res, "cluster_start_seconds": cluster_start,
                                          "pool_start_seconds": pool_start,
                                          "same_outputs": same})
    print(f"wrote {out / 'bench_batch.json'}")
    return BenchResult(f"{title}\n\n{table}\n\n" + "\n\n".join(notes), exit_code=0 if same else 1)
