"""`vslam bench NAME`: benchmarks, registered in `vslam.bench.registry`.

Benchmarks print a table and write JSON; speed is reported against a baseline measured in the same run. Their
tables also go into docs/benchmarks.md between `<!-- bench:NAME -->` markers (see `vslam.bench.docs`).
"""
from __future__ import annotations

import argparse
import shlex
from typing import Callable

from vslam.bench.registry import BENCHMARKS, Benchmark, run_benchmark

NAME = "bench"
HELP = "run a benchmark (prints a table, writes JSON)"


class _DeferredParser(argparse.ArgumentParser):
    """A parser that adds its arguments when it first parses: a benchmark's module is imported only when that
    benchmark is asked for (or its --help), not to build `vslam --help`."""

    def __init__(self, *args, add_arguments: Callable[[argparse.ArgumentParser], None] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._add_arguments = add_arguments

    def parse_known_args(self, args=None, namespace=None):
        if self._add_arguments is not None:
            add, self._add_arguments = self._add_arguments, None
            add(self)
        return super().parse_known_args(args, namespace)


def _bench_arguments(bench: Benchmark) -> Callable[[argparse.ArgumentParser], None]:
    def add(p: argparse.ArgumentParser) -> None:
        bench.load().add_arguments(p)
        g = p.add_argument_group("docs/benchmarks.md")
        g.add_argument("--docs", action=argparse.BooleanOptionalAction, default=None,
                       help="write the tables into the benchmark's section of the docs file (default: only when "
                            "its <!-- bench:NAME --> markers are there; --docs also appends a missing section)")
        g.add_argument("--docs-file", metavar="PATH", help="the docs file (default: docs/benchmarks.md of the checkout)")

    return add


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bench", metavar="BENCH", parser_class=_DeferredParser)
    sub.required = True
    for bench in BENCHMARKS.values():
        sub.add_parser(bench.name, help=bench.help, description=bench.help, add_arguments=_bench_arguments(bench))


def run(args: argparse.Namespace) -> int:
    command = "vslam " + shlex.join(getattr(args, "command_line", None) or ["bench", args.bench])
    code, note = run_benchmark(args.bench, args, command, args.docs, args.docs_file)
    if note:
        print(note)
    return code
