"""The benchmarks `vslam bench NAME` runs: name -> Benchmark (help, arguments, the function that runs it).

A benchmark is a module exposing NAME, HELP, optional DESCRIPTION, add_arguments(parser) and
run(args) -> BenchResult; adding one means adding its module to BENCHMARK_MODULES.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Callable

from vslam.bench import descriptors, graph, horizon, localize, odometry, pipeline
from vslam.bench.docs import publish
from vslam.bench.results import BenchResult

BENCHMARK_MODULES: tuple[ModuleType, ...] = (descriptors, graph, horizon, localize, odometry, pipeline)


@dataclass(frozen=True)
class Benchmark:
    name: str
    help: str
    description: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], BenchResult]


BENCHMARKS: dict[str, Benchmark] = {
    m.NAME: Benchmark(m.NAME, m.HELP, getattr(m, "DESCRIPTION", m.HELP), m.add_arguments, m.run)
    for m in sorted(BENCHMARK_MODULES, key=lambda m: m.NAME)
}


def run_benchmark(name: str, args: argparse.Namespace, command: str, docs: bool | None = None,
                  docs_file: str | Path | None = None) -> tuple[int, str | None]:
    """Run benchmark `name` with its parsed arguments, then publish its tables (see `vslam.bench.docs.publish`).
    Returns the exit code and the docs note (None when nothing was written or asked for)."""
    result = BENCHMARKS[name].run(args)
    return result.exit_code, publish(name, result.markdown, command, docs, docs_file)
