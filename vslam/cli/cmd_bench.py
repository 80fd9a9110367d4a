"""`vslam bench NAME`: benchmarks, registered in `vslam.bench.registry`.

Benchmarks print a table and write JSON; speed is reported against a baseline measured in the same run. Their
tables also go into docs/benchmarks.md between `<!-- bench:NAME -->` markers (see `vslam.bench.docs`).
"""
from __future__ import annotations

import argparse
import shlex

from vslam.bench.registry import BENCHMARKS, run_benchmark

NAME = "bench"
HELP = "run a benchmark (prints a table, writes JSON)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bench", metavar="BENCH")
    sub.required = True
    for bench in BENCHMARKS.values():
        p = sub.add_parser(bench.name, help=bench.help, description=bench.description)
        bench.add_arguments(p)
        g = p.add_argument_group("docs/benchmarks.md")
        g.add_argument("--docs", action=argparse.BooleanOptionalAction, default=None,
                       help="write the tables into the benchmark's section of the docs file (default: only when "
                            "its <!-- bench:NAME --> markers are there; --docs also appends a missing section)")
        g.add_argument("--docs-file", metavar="PATH", help="the docs file (default: docs/benchmarks.md of the checkout)")


def run(args: argparse.Namespace) -> int:
    command = "vslam " + shlex.join(getattr(args, "command_line", None) or ["bench", args.bench])
    code, note = run_benchmark(args.bench, args, command, args.docs, args.docs_file)
    if note:
        print(note)
    return code
