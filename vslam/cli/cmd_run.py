"""`vslam run SEQ --out OUT`: the whole SLAM pipeline on a sequence."""
from __future__ import annotations

import argparse
import json
import math
from dataclasses import replace

from vslam.cli.options import add_frame_and_out_options
from vslam.cli.progress import Progress

NAME = "run"
HELP = "run SLAM (VO + compact-descriptor loops + robust pose graph) on a sequence; writes trajectories, loops, " \
       "graph, metrics, plots and a Rerun recording"


def add_pipeline_options(p) -> None:
    """The options that build the pipeline config (`build_config`); `vslam batch` applies the same ones to every
    sequence. `p` is a parser or an argument group."""
    p.add_argument("--mode", type=int, choices=range(1, 7), metavar="1..6",
                   help="descriptor size mode (512 B .. 16 kB per keyframe; default 4)")
    p.add_argument("--loop-model", help="P(loop|score) model from `vslam train-loops` (default: the shipped model)")
    p.add_argument("--incremental", action="store_true", help="iSAM2 as keyframes arrive instead of batch LM")
    p.add_argument("--config", help="YAML or TOML file with pipeline settings (see --print-config)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting by its dotted key, e.g. --set loops.recognizer=vocab "
                        "--set vo.max_features=300 (repeatable; applied after --config, before the flags below)")
    p.add_argument("--no-loops", action="store_true", help="visual odometry only")
    p.add_argument("--no-recording", action="store_true", help="do not write recording.rrd")
    p.add_argument("--camera", help="camera.yaml for image folders and videos")
    p.add_argument("--max-frames", type=int, help="process only the first N frames")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequence", help="sequence directory (or TUM RGB-D / KITTI folder, image folder, video)")
    p.add_argument("--out", required=True, help="output directory")
    add_pipeline_options(p)
    p.add_argument("--print-config", action="store_true", help="print the effective configuration as YAML and exit")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("--json", action="store_true",
                   help="print the run summary as one JSON object on stdout (metrics.json's content plus the output "
                        "directory); progress still goes to stderr")
    add_frame_and_out_options(p, writes="the files a run writes")


def build_config(a: argparse.Namespace):
    from vslam.pipeline.config import PipelineConfig  # on use: it loads the pose graph (scipy.stats)

    cfg = PipelineConfig.load(a.config) if a.config else PipelineConfig()
    if a.overrides:
        cfg = cfg.with_overrides(a.overrides, source="--set")
    loops = cfg.loops
    if a.mode is not None:
        loops = replace(loops, mode=a.mode)
    if a.loop_model:
        loops = replace(loops, model=a.loop_model)
    if a.no_loops:
        loops = replace(loops, enabled=False)
    cfg = replace(cfg, loops=loops)
    if a.incremental:
        cfg = replace(cfg, incremental=True)
    if a.no_recording:
        cfg = replace(cfg, recording=replace(cfg.recording, enabled=False))
    return cfg


def run(a: argparse.Namespace) -> int:
    from vslam.app.run import run_sequence  # on use: keeps `vslam --help` fast (see vslam.cli.main)

    cfg = build_config(a)
    if a.print_config:
        print(cfg.dumps(), end="")
        return 0
    bar = Progress(0, label="vslam run", enabled=None if not a.quiet else False)
    summary = run_sequence(a.sequence, a.out, cfg, camera=a.camera, max_frames=a.max_frames, progress=bar.update,
                           overwrite=a.overwrite, skip_bad_frames=a.skip_bad_frames)
    bar.close()
    if a.json:   # one object, nothing else on stdout: `vslam run ... --json | jq .summary`
        doc = {"out": str(summary.out), **json.loads((summary.out / "metrics.json").read_text())}
        print(json.dumps(_strict(doc), allow_nan=False))
    elif not a.quiet:
        print(summary.format())
    return 0


def _strict(v):
    """Strict JSON (what jq and other parsers accept): NaN and infinities, e.g. an undefined recall, become null."""
    if isinstance(v, dict):
        return {k: _strict(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_strict(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v
