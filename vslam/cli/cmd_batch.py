"""`vslam batch INPUTS... --out DIR`: many sequences through `vslam run`'s pipeline, on a local process pool or a
Dask cluster; resumable; a summary across the fleet."""
from __future__ import annotations

import argparse

from vslam.cli.cmd_run import add_pipeline_options, build_config
from vslam.cli.progress import Progress

NAME = "batch"
HELP = "run SLAM on many sequences (folders, a folder of them, globs, a manifest CSV) on a local process pool " \
       "or a Dask cluster; resumable; fleet summary"
DESCRIPTION = HELP + (". Each sequence goes to OUT/<name>/ with the outputs of `vslam run`; OUT/batch.json records "
                      "status, input and config hashes, timings and errors; OUT/summary.{csv,json,png} sums up. "
                      "Exit code 1 when any sequence failed. See docs/batch.md.")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="a sequence folder (or video), a folder of sequences, a glob (quoted), or a manifest CSV "
                        "with columns sequence[,name][,overrides] (overrides: 'loops.mode=5; vo.max_features=300')")
    p.add_argument("--out", required=True, help="output folder: OUT/<name>/ per sequence, batch.json, summary.*")
    where = p.add_argument_group("where it runs")
    where.add_argument("--workers", type=int, help="local worker processes (default: one per CPU)")
    where.add_argument("--scheduler", metavar="ADDRESS|FILE",
                       help="run on a Dask cluster: tcp://HOST:PORT or a scheduler file (needs vslam[cluster]; "
                            "workers must reach the sequences and OUT by the same paths)")
    p.add_argument("--retry-failed", action="store_true",
                   help="run again the sequences that failed in an earlier batch into OUT (changed ones always run)")
    run = p.add_argument_group("options of `vslam run`, applied to every sequence (a manifest row's overrides go "
                              "on top of --set)")
    add_pipeline_options(run)
    run.add_argument("--print-config", action="store_true", help="print the effective configuration as YAML and exit")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary table")


def _bar_update(bar: Progress):
    def update(state) -> None:
        running = state.running
        frames = "".join(f" {n} {d}/{t}" for n, (d, t) in list(running.items())[:3] if t)
        bar.label = f"vslam batch ({len(running)} running{':' if frames else ''}{frames})"
        bar.update(state.finished, state.total)

    return update


def run(a: argparse.Namespace) -> int:
    from vslam.batch import run_many  # on use: keeps `vslam --help` fast (see vslam.cli.main)

    cfg = build_config(a)
    if a.print_config:
        print(cfg.dumps(), end="")
        return 0
    bar = Progress(0, label="vslam batch", unit="sequences", enabled=None if not a.quiet else False)
    summary = run_many(a.inputs, cfg, a.scheduler, out=a.out, workers=a.workers, retry_failed=a.retry_failed,
                       camera=a.camera, max_frames=a.max_frames, progress=_bar_update(bar))
    bar.close()
    if not a.quiet:
        print(summary.format())
        print(f"  summary  {summary.files['csv']}, {summary.files['json'].name}, {summary.files['png'].name}; "
              f"manifest {summary.out / 'batch.json'}")
    return summary.exit_code
