"""`vslam bench fuzz`: the long hostile-input fuzz of every parser and decoder (issue 15).

Structure-aware malformed inputs (`vslam.bench.fuzz_cases`): descriptor blobs (decoded, then matched against a valid
descriptor both ways and against themselves), sequence directories (opened with every image decoded, summarised,
wheel/gyro fused) and pipeline configs (loaded and validated); pose-graph files through
`vslam.bench.fuzz_graphs.fuzz_graph_files` when that module is present. Every case ends as one of:

- processed: the input was accepted and the work done;
- typed_error: a documented error (a ToolkitError: LoopsError, VslamError, ConfigError, ...); `typed_without_file`
  counts those whose message does not name the input file (descriptor blobs are bytes, not files: not counted);
- traceback: any other exception (a bug);
- hang: a case slower than --hang-seconds (cut at --kill-seconds).

The baseline in the same run is the valid input each case was made from (processed at the same rate, their median
time per case is reported beside the malformed cases'). The exit code is 1 when there is any traceback or hang.
"""
from __future__ import annotations

import argparse
import random
import shutil
import signal
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from loops.cdvs import decode
from loops.cdvs.match import match
from odometry.shared.errors import ToolkitError
from vslam.app.info import sequence_summary
from vslam.app.odometry import fuse_sequence_odometry
from vslam.bench.fuzz_cases import config_text, descriptor_blob, seed_descriptors, sequence_folder
from vslam.bench.results import BenchResult, write_json
from vslam.bench.timing import median
from vslam.evaluation.tables import format_table
from vslam.io import open_sequence
from vslam.pipeline import PipelineConfig

OUTCOMES = ("processed", "typed_error", "traceback", "hang")


class CaseTimeout(BaseException):
    """Raised in the fuzzed call when it runs past the kill limit (BaseException: no `except Exception` eats it)."""


@dataclass
class Tally:
    name: str
    cases: int = 0
    counts: dict = field(default_factory=lambda: {k: 0 for k in OUTCOMES})
    typed_without_file: int = 0
    seconds: list = field(default_factory=list)
    examples: dict = field(default_factory=lambda: {"traceback": [], "hang": [], "typed_without_file": []})

    def add(self, k: int, outcome: str, detail: str, dt: float, named: bool) -> None:
        self.cases += 1
        self.counts[outcome] += 1
        self.seconds.append(dt)
        if outcome == "typed_error" and not named:
            self.typed_without_file += 1
            if len(self.examples["typed_without_file"]) < 5:
                self.examples["typed_without_file"].append((k, detail[:300]))
        if outcome in ("traceback", "hang") and len(self.examples[outcome]) < 5:
            self.examples[outcome].append((k, detail[-1200:]))

    def row(self) -> list:
        return [self.name, self.cases, *(self.counts[k] for k in OUTCOMES), self.typed_without_file,
                round(1e3 * median(self.seconds), 2) if self.seconds else float("nan"),
                round(max(self.seconds), 3) if self.seconds else float("nan")]

    def to_dict(self) -> dict:
        return {"cases": self.cases, **self.counts, "typed_without_file": self.typed_without_file,
                "median_ms": 1e3 * median(self.seconds) if self.seconds else None,
                "max_seconds": max(self.seconds) if self.seconds else None, "examples": self.examples}


def _on_alarm(signum, frame):
    raise CaseTimeout()


def run_case(fn: Callable[[], None], hang_seconds: float, kill_seconds: float, name_hint: str | None
             ) -> tuple[str, str, float, bool]:
    """(outcome, detail, seconds, error names the input) of one call."""
    previous = signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, kill_seconds)
    t0 = time.perf_counter()
    named = True
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fn()
        outcome, detail = "processed", ""
    except CaseTimeout:
        outcome, detail = "hang", f"cut after {kill_seconds} s"
    except ToolkitError as exc:
        outcome, detail = "typed_error", str(exc)
        named = name_hint is None or name_hint in detail
    except Exception:   # noqa: BLE001 - any other exception is what the fuzz counts
        outcome, detail = "traceback", traceback.format_exc(limit=8)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    dt = time.perf_counter() - t0
    if outcome in ("processed", "typed_error") and dt > hang_seconds:
        outcome, detail = "hang", f"{dt:.2f} s ({outcome}: {detail[:200]})"
    return outcome, detail, dt, named


# ---- the three families ------------------------------------------------------------------------------------------
def fuzz_descriptors(n: int, seed: int, hang: float, kill: float) -> Tally:
    seeds = seed_descriptors()
    ref = decode(seeds[3])
    rng = random.Random(seed)
    tally = Tally("descriptor blobs")
    for k in range(n):
        blob = descriptor_blob(rng, seeds)

        def work(blob=blob):
            d = decode(blob)
            match(d, ref)
            match(ref, d)
            match(d, d)
        tally.add(k, *run_case(work, hang, kill, None))
    return tally


def check_sequence(root: Path) -> None:
    """What `vslam info --decode` does, plus the wheel/gyro fusion the pipeline runs on the streams."""
    seq = open_sequence(root, check_images="decode")
    sequence_summary(seq)
    for i in range(len(seq)):
        seq.image(i, gray=True)
    seq.groundtruth_planar()
    if seq.odometry is not None:
        fuse_sequence_odometry(seq)


def fuzz_sequences(n: int, seed: int, hang: float, kill: float, work: Path) -> Tally:
    tally = Tally("sequence folders")
    for k in range(n):
        root = work / f"seq{k:05d}"
        sequence_folder(random.Random(seed * 1_000_003 + k), root)
        tally.add(k, *run_case(lambda: check_sequence(root), hang, kill, str(root)))
        shutil.rmtree(root, ignore_errors=True)
    return tally


def fuzz_configs(n: int, seed: int, hang: float, kill: float, work: Path) -> Tally:
    valid = PipelineConfig().dumps()
    tally = Tally("pipeline configs")
    for k in range(n):
        path = work / f"config{k:05d}.yaml"
        path.write_text(config_text(random.Random(seed * 1_000_003 + k), valid), encoding="utf-8",
                        errors="surrogatepass")

        def work_fn(path=path):
            cfg = PipelineConfig.load(path)
            cfg.to_dict()
            cfg.database_params()
        tally.add(k, *run_case(work_fn, hang, kill, str(path)))
        path.unlink()
    return tally


def baseline(n: int, hang: float, kill: float, work: Path) -> Tally:
    """The valid inputs the cases are made from, through the same calls."""
    tally = Tally("baseline: valid inputs")
    seeds = seed_descriptors()
    ref = decode(seeds[3])
    for k in range(n):
        blob = seeds[k % len(seeds)]
        tally.add(k, *run_case(lambda: (match(decode(blob), ref), None)[1], hang, kill, None))
        root = work / "valid"
        sequence_folder(random.Random(k), root, corrupt=False)
        tally.add(k, *run_case(lambda: check_sequence(root), hang, kill, str(root)))
        shutil.rmtree(root, ignore_errors=True)
        path = work / "valid.yaml"
        path.write_text(PipelineConfig().dumps())
        tally.add(k, *run_case(lambda: PipelineConfig.load(path), hang, kill, str(path)))
    return tally


def graph_counts(n: int, seed: int, hang: float) -> dict | None:
    """Counts of the pose-graph file fuzz (vslam.bench.fuzz_graphs), or None when that module is absent."""
    try:
        from vslam.bench.fuzz_graphs import fuzz_graph_files  # noqa: PLC0415 - optional: provided separately
    except ImportError:
        return None
    return fuzz_graph_files(n, seed, hang_seconds=hang)


# ---- the benchmark -----------------------------------------------------------------------------------------------
def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--blobs", type=int, default=10_000, help="descriptor blobs (default 10,000)")
    p.add_argument("--sequences", type=int, default=1000, help="malformed sequence folders (default 1,000)")
    p.add_argument("--configs", type=int, default=1000, help="malformed pipeline configs (default 1,000)")
    p.add_argument("--graphs", type=int, default=1000, help="malformed pose-graph files (default 1,000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--hang-seconds", type=float, default=2.0, help="a case slower than this is a hang (s)")
    p.add_argument("--kill-seconds", type=float, default=20.0, help="a case is cut after this (s)")
    p.add_argument("--quick", action="store_true", help="a tenth of every count (a smoke run)")
    p.add_argument("--json", default="fuzz.json", help="where to write the counts and examples")


def run(args: argparse.Namespace) -> BenchResult:
    scale = 0.1 if args.quick else 1.0
    n = {k: int(round(getattr(args, k) * scale)) for k in ("blobs", "sequences", "configs", "graphs")}
    hang, kill = args.hang_seconds, args.kill_seconds
    work = Path(tempfile.mkdtemp(prefix="vslam-fuzz-"))
    try:
        tallies = [fuzz_descriptors(n["blobs"], args.seed, hang, kill),
                   fuzz_sequences(n["sequences"], args.seed, hang, kill, work),
                   fuzz_configs(n["configs"], args.seed, hang, kill, work),
                   baseline(20, hang, kill, work)]
    finally:
        shutil.rmtree(work, ignore_errors=True)
    rows = [t.row() for t in tallies]
    graphs = graph_counts(n["graphs"], args.seed, hang) if n["graphs"] > 0 else None
    if graphs is not None:
        rows.insert(3, ["pose-graph files", graphs.get("cases", n["graphs"]),
                        *(graphs.get(k, 0) for k in OUTCOMES), graphs.get("typed_without_file", 0),
                        "n/a", graphs.get("max_seconds", "n/a")])   # fuzz_graphs reports no median
    table = format_table(["input", "cases", *OUTCOMES, "typed error not naming the file", "median ms", "max s"], rows)
    note = "" if graphs is not None or n["graphs"] == 0 else \
        "\n\n(pose-graph files: vslam.bench.fuzz_graphs is not installed here)\n"
    print(table + note)
    payload = {"seed": args.seed, "hang_seconds": hang, "kill_seconds": kill,
               **{t.name: t.to_dict() for t in tallies}, "pose-graph files": graphs}
    write_json(args.json, payload)
    bad = sum(t.counts["traceback"] + t.counts["hang"] for t in tallies)
    if graphs is not None:
        bad += graphs.get("traceback", 0) + graphs.get("hang", 0)
    for t in tallies:
        for kind in ("traceback", "hang"):
            for k, detail in t.examples[kind][:2]:
                print(f"--- {t.name} case {k}: {kind}\n{detail}")
    md = (f"Seed {args.seed}; a case slower than {hang:g} s counts as a hang. Structure-aware cases from "
          "`vslam.bench.fuzz_cases` (descriptor blobs made CRC- and length-consistent so that they reach the "
          "checks behind the checksum).\n\n" + table + note)
    return BenchResult(md, exit_code=1 if bad else 0)
