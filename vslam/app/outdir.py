"""The output folder of a command (`--out`): checked before any work is done.

A folder that already holds files is refused unless `overwrite`, so that a new run never sits beside another run's
stale recording and plots; `overwrite` removes what the command writes (and only that). A folder the command cannot
write into fails here, not after the run.
"""
from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Iterable

from vslam.errors import VslamError

# what each command writes into its --out folder (overwrite clears these names, files or folders)
RUN_OUTPUTS = ("trajectory_vo.txt", "trajectory_slam.txt", "loops.csv", "graph.g2o", "run.json", "metrics.json",
               "eval.json", "plots", "recording.rrd", ".recording.rrd.partial")
ODOMETRY_OUTPUTS = ("trajectory_vo.txt", "trajectory_fused.txt", "odometry.csv")
LOOPS_OUTPUTS = ("loops.csv", "summary.json")
LOCALIZE_EVAL_OUTPUTS = ("ranking.csv", "per_query.csv", "report.md", "metrics.json", "pr.png")


def prepare_out_dir(out: str | Path, writes: Iterable[str], overwrite: bool = False) -> Path:
    """Create `out` if needed and make sure the command may write there: refuse a non-empty folder unless
    `overwrite` (which removes the entries named in `writes`), and a folder that cannot be written."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise VslamError(f"--out {out}: exists and is not a folder")
    if out.is_dir():
        present = sorted(p.name for p in out.iterdir())
        if present and not overwrite:
            shown = ", ".join(present[:5]) + (", ..." if len(present) > 5 else "")
            raise VslamError(f"--out {out}: the folder is not empty ({shown}); give --overwrite to replace what "
                             "this command writes there, or another folder")
        if present:
            for name in writes:
                p = out / name
                try:
                    if p.is_dir() and not p.is_symlink():
                        shutil.rmtree(p)
                    elif p.exists() or p.is_symlink():
                        p.unlink()
                except OSError as exc:
                    raise VslamError(f"--out {out}: cannot remove the old {name} ({exc.strerror or exc})") from None
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise VslamError(f"--out {out}: cannot write into the folder ({exc.strerror or exc})") from None
    return out
