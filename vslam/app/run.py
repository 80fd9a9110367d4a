"""The whole SLAM pipeline on a sequence, with its files (`vslam run`): trajectories, loops, graph, metrics, plots
and a Rerun recording in one output directory."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from vslam.app.outdir import RUN_OUTPUTS, prepare_out_dir
from vslam.io import open_sequence
from vslam.io.bad_frames import check_mode, note_bad_frames
from vslam.pipeline import Pipeline, PipelineConfig, PipelineResult
from vslam.recording import RunRecorder


@dataclass(frozen=True)
class RunSummary:
    """A finished run: the pipeline's result, where its files are, and metrics.json's "evaluation" (None without
    ground truth)."""
    result: PipelineResult
    out: Path
    evaluation: dict | None

    def format(self) -> str:
        """The summary `vslam run` prints."""
        s = self.result.summary()
        st = s["vo_status"]
        ms = s["median_ms"]
        lines = [f"vslam run: {s['frames']} frames in {s['wall_seconds']:.1f} s ({s['frames_per_second']:.1f} "
                 f"frames/s), {s['keyframes']} keyframes",
                 f"  VO       ok {st.get('ok', 0)}, fallback {st.get('fallback', 0)}, lost {st.get('lost', 0)}; "
                 f"median {ms.get('vo', 0):.1f} ms/frame",
                 f"  loops    {s['loops_verified']} verified candidates, {s['loops_accepted']} accepted, "
                 f"{s['loops_kept']} kept by the back end, {s['loops_rejected_by_backend']} rejected as outliers; "
                 f"descriptor {s['descriptor_bytes_mean']:.0f} B mean / {s['descriptor_bytes_max']} B max"]
        if self.evaluation:
            lines += _evaluation_lines(self.evaluation)
        lines.append(f"  outputs  {self.out}/ (trajectory_vo.txt, trajectory_slam.txt, loops.csv, graph.g2o, "
                     f"metrics.json, plots/{', recording.rrd' if self.result.config.recording.enabled else ''})")
        return "\n".join(lines)


def _evaluation_lines(ev: dict) -> list[str]:
    lines = [f"  not evaluated: {p}" for p in ev.get("problems", [])]
    for name in ("vo", "slam"):
        if name not in ev:
            continue
        d = ev[name]
        se = d["start_to_end"]
        lines.append(f"  {name.upper():<8} ATE {d['ape_m']['rmse']:.4f} m RMSE ({d['ape_rmse_percent_of_path']:.3f} % "
                     f"of {d['path_length_m']:.1f} m), start-to-end error {se.get('error_distance', float('nan')):.4f} m")
    if "loops" in ev:
        la = ev["loops"]["kept_by_back_end"]
        lines.append(f"  loops vs footprint ground truth: precision {la['precision']:.3f}, "
                     f"recall {la.get('recall', float('nan')):.3f}")
    return lines


def run_sequence(sequence: str | Path, out: str | Path, config: PipelineConfig | None = None,
                 camera: str | None = None, max_frames: int | None = None,
                 progress: Callable[[int, int], None] | None = None, overwrite: bool = False,
                 skip_bad_frames: bool = False) -> RunSummary:
    """Run SLAM on a sequence (any layout `vslam.io.open_sequence` reads) and write every output into `out`; the
    Rerun recording (out/recording.rrd) when the config's recording is enabled. progress(done, total) per frame.
    A non-empty `out` is refused unless `overwrite` (see `vslam.app.outdir`). A frames.csv listing a missing
    image is refused unless `skip_bad_frames`; unreadable frames are warned about and listed in run.json."""
    config = config or PipelineConfig()
    seq = open_sequence(sequence, camera=camera, check_images=check_mode(skip_bad_frames))
    noted = note_bad_frames(seq)
    out = prepare_out_dir(out, RUN_OUTPUTS, overwrite)
    recorder = None
    try:
        if config.recording.enabled:   # inside the try: an interrupt right after it opened must not leave a .partial
            recorder = RunRecorder(out / "recording.rrd", seq.camera, recording_id=f"vslam-{seq.name}",
                                   jpeg_quality=config.recording.jpeg_quality,
                                   image_every=config.recording.image_every,
                                   image_scale=config.recording.image_scale)
        result = Pipeline(config, recorder=recorder).run(seq, progress=progress, max_frames=max_frames)
    except BaseException:
        if recorder is not None:
            recorder.abort()   # no half-written recording.rrd
        raise
    if recorder is not None:
        recorder.close()
    result.write(out, sequence=seq, bad_frames=noted.rows())
    metrics = json.loads((out / "metrics.json").read_text())
    return RunSummary(result, out, metrics.get("evaluation"))
