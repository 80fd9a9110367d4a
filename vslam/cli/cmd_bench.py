"""`vslam bench NAME`: benchmarks, each in `vslam/bench/<name>.py`.

A benchmark module exposes NAME, HELP, add_arguments(parser) and run(args) -> int, like a command.
Benchmarks print a table and write JSON; speed is reported against a baseline measured in the same run.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil

NAME = "bench"
HELP = "run a benchmark (prints a table, writes JSON)"


def _bench_modules():
    import vslam.bench as pkg

    names = sorted(m.name for m in pkgutil.iter_modules(pkg.__path__) if not m.name.startswith("_"))
    return [importlib.import_module(f"vslam.bench.{n}") for n in names]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bench", metavar="BENCH")
    sub.required = True
    for mod in _bench_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP))
        mod.add_arguments(p)
        p.set_defaults(func=mod.run)


def run(args: argparse.Namespace) -> int:  # pragma: no cover - argparse always dispatches to a bench
    return args.func(args)
