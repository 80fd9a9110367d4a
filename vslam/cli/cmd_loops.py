"""`vslam loops SEQ --mode M --out DIR`: loop detection alone (compact descriptors), writes DIR/loops.csv.

Works on any image sequence (sequence directory, TUM/KITTI folder, image folder, video): no odometry, ground
truth or camera height is needed. A downward camera (camera_height in camera.yaml) uses the floor geometry
check (rotation + translation); anything else the general one.
"""
from __future__ import annotations

import argparse

from vslam.errors import VslamError

NAME = "loops"
HELP = "detect loops in an image sequence with compact descriptors (writes loops.csv)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sequence", help="sequence directory, TUM RGB-D / KITTI folder, image folder or video")
    p.add_argument("--mode", type=int, default=4, choices=range(1, 7), metavar="{1..6}",
                   help="descriptor mode: 512 B, 1, 2, 4, 8, 16 kB (default 4)")
    p.add_argument("--out", required=True, help="output directory (loops.csv, summary.json)")
    p.add_argument("--model", help="loop model JSON from `vslam train-loops` (default: the shipped model)")
    p.add_argument("--threshold", type=float, help="accept local scores >= this instead of the model threshold")
    p.add_argument("--every", type=int, default=1, help="use every N-th frame as a keyframe (default 1)")
    p.add_argument("--shortlist", type=int, default=5, help="candidates verified per query (default 5)")
    p.add_argument("--exclude-recent", type=int, default=20,
                   help="never match the most recent N keyframes (default 20)")
    p.add_argument("--confirmations", type=int, default=1,
                   help="consecutive keyframes that must agree before a loop is accepted (default 1)")
    p.add_argument("--geometry", choices=["auto", "floor", "general"], default="auto",
                   help="geometric model: floor = rotation+translation (downward camera), general = affine")
    p.add_argument("--camera", help="camera.yaml to use (image folders and videos)")
    p.add_argument("--fps", type=float, default=10.0, help="frame rate for image folders without timestamps")
    p.add_argument("--quiet", action="store_true")


def run(a: argparse.Namespace) -> int:
    import json
    import sys
    from dataclasses import replace
    from pathlib import Path

    from loops.cdvs import CdvsParams, GeometryModel
    from loops.cdvs.database import DatabaseParams
    from loops.cdvs.detector import LOOPS_CSV_HEADER, detect_loops
    from loops.cdvs.model import LoopModel
    from odometry.shared.atomic_io import atomic_write_text
    from vslam.cli.progress import Progress
    from vslam.io import open_sequence

    if a.every < 1 or a.shortlist < 1 or a.exclude_recent < 0 or a.confirmations < 1:
        raise VslamError("--every, --shortlist and --confirmations must be >= 1 and --exclude-recent >= 0")
    seq = open_sequence(a.sequence, camera=a.camera, fps=a.fps)
    model = LoopModel.load(a.model) if a.model else LoopModel.default()
    downward = seq.camera is not None and seq.camera.camera_height is not None
    geometry = {"floor": GeometryModel.SIMILARITY, "general": GeometryModel.AFFINE,
                "auto": GeometryModel.SIMILARITY if downward else GeometryModel.AFFINE}[a.geometry]
    params = CdvsParams.floor(a.mode) if downward else CdvsParams.for_mode(a.mode)
    params = replace(params, matching=replace(params.matching, geometry=geometry))
    dbp = DatabaseParams(shortlist=a.shortlist, exclude_recent=a.exclude_recent, confirmations=a.confirmations)
    indices = list(range(0, len(seq), a.every))
    warnings: list[str] = []

    def frames():
        for i in indices:
            try:
                yield i, seq.image(i, gray=True)
            except ValueError as exc:  # an unreadable frame is skipped, not fatal
                warnings.append(str(exc))
                yield i, None

    prog = Progress(len(indices), "loops", enabled=None if not a.quiet else False)
    rows, st = detect_loops(frames(), a.mode, params, dbp, model=model, threshold=a.threshold,
                            on_frame=lambda k: prog.update(k + 1))
    elapsed = prog.close()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "loops.csv", ",".join(LOOPS_CSV_HEADER) + "\n" + "".join(r.csv() + "\n" for r in rows))
    thr = a.threshold if a.threshold is not None else model.threshold(a.mode)
    summary = {"sequence": str(a.sequence), "mode": a.mode, "keyframes": st.frames, "skipped_frames": st.skipped,
               "candidates": st.candidates, "accepted": st.accepted,
               "threshold": thr if thr != float("inf") else None, "geometry": geometry.value,
               "model": str(a.model) if a.model else "default",
               "mean_bytes": st.bytes_total / max(st.frames, 1),
               "encode_ms_per_frame": 1e3 * st.encode_seconds / max(st.frames, 1),
               "query_ms_per_frame": 1e3 * st.query_seconds / max(st.frames, 1), "seconds": elapsed,
               "warnings": warnings[:20]}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    for w in warnings[:5]:
        print(f"vslam loops: warning: skipped unreadable frame: {w}", file=sys.stderr)
    if not a.quiet:
        print(f"{st.frames} keyframes, {st.candidates} verified candidates, {st.accepted} accepted loops "
              f"(mode {a.mode}, threshold {thr:.3g}) -> {out / 'loops.csv'}")
    return 0
