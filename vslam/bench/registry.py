"""The benchmarks `vslam bench NAME` runs: name -> Benchmark (its module and one line of help).

A benchmark module exposes add_arguments(parser) and run(args) -> BenchResult; its docstring says what it measures.
Modules are imported when their benchmark is asked for (`Benchmark.load`), not when the registry is: they pull in
the whole toolkit (scipy.stats through the pose graph, OpenCV, matplotlib), and `vslam --help` reads this registry.
"""
from __future__ import annotations

import argparse
import importlib
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from vslam.bench.docs import publish


@dataclass(frozen=True)
class Benchmark:
    name: str
    module: str     # exposes add_arguments(parser) and run(args) -> BenchResult
    help: str

    def load(self) -> ModuleType:
        return importlib.import_module(self.module)


BENCHMARKS: dict[str, Benchmark] = {b.name: b for b in (
    Benchmark("batch", "vslam.bench.batch",
              "`vslam batch` throughput: sequential vs local process pool vs local Dask cluster on simulated sequences"),
    Benchmark("descriptors", "vslam.bench.descriptors",
              "compact descriptors (modes 1-6) vs OpenCV SIFT: size, speed, query scaling, loop P/R, 48 real pairs"),
    Benchmark("fuzz", "vslam.bench.fuzz",
              "hostile inputs: malformed descriptor blobs, sequence folders, configs and graph files; counts of "
              "processed / typed error / traceback / hang"),
    Benchmark("graph", "vslam.bench.graph",
              "pose-graph back end: solve times, iSAM2 pass, robustness to injected false loops (tables + JSON)"),
    Benchmark("horizon", "vslam.bench.horizon",
              "1D SURF horizon landmarks vs SIFT: ROC/AUC on a KITTI crop bank, extraction and matching time"),
    Benchmark("loops", "vslam.bench.loop_regimes",
              "standalone loop detection across regimes (printed/natural floors, low-rate lanes), both renderers"),
    Benchmark("localize", "vslam.bench.localize",
              "visual-memory localisation: paper tables on real sets, pydbow comparison, repeatability, query time"),
    Benchmark("odometry", "vslam.bench.odometry",
              "VO drift and frames/s on simulated floors vs wheel+gyro fusion and cv2.estimateAffinePartial2D"),
    Benchmark("paper", "vslam.bench.paper",
              "seed 001's experiment: 110 m of printed wood, 7154 frames, modes 1-6; Tables IV and V beside the paper"),
    Benchmark("pipeline", "vslam.bench.pipeline",
              "end-to-end SLAM frames/s, accuracy (ATE, start-to-end) and peak memory on simulated sequences"),
)}


def run_benchmark(name: str, args: argparse.Namespace, command: str, docs: bool | None = None,
                  docs_file: str | Path | None = None) -> tuple[int, str | None]:
    """Run benchmark `name` with its parsed arguments, then publish its tables (see `vslam.bench.docs.publish`).
    Returns the exit code and the docs note (None when nothing was written or asked for)."""
    result = BENCHMARKS[name].load().run(args)
    return result.exit_code, publish(name, result.markdown, command, docs, docs_file)
