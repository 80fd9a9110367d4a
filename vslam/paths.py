"""Where the toolkit finds bundled and shared data files."""
from __future__ import annotations

import os
from pathlib import Path

PACKAGE_DATA = Path(__file__).resolve().parent / "data"
REPO_ROOT = Path(__file__).resolve().parents[1]


def shared_data_dir(required: bool = False) -> Path | None:
    """The public data sets used by benchmarks: $VSLAM_SHARED_DATA, else `../shared/data` beside the checkout
    (or beside the working directory). Returns None when absent, or raises FileNotFoundError if `required`."""
    candidates = []
    if os.environ.get("VSLAM_SHARED_DATA"):
        candidates.append(Path(os.environ["VSLAM_SHARED_DATA"]))
    candidates += [REPO_ROOT.parent / "shared" / "data", Path.cwd().parent / "shared" / "data"]
    for c in candidates:
        if c.is_dir():
            return c.resolve()
    if required:
        raise FileNotFoundError("shared data folder not found: set VSLAM_SHARED_DATA or place it at ../shared/data "
                                f"(looked in {', '.join(str(c) for c in candidates)})")
    return None
