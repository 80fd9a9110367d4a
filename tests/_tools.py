"""Where the tests find the independent floor renderer (../shared/tools/render_floor.py)."""
from __future__ import annotations

import os
from pathlib import Path


def render_floor_tool() -> Path | None:
    """render_floor.py beside $VSLAM_SHARED_DATA, or None (the tests that render with it skip with a reason)."""
    data = os.environ.get("VSLAM_SHARED_DATA")
    if not data:
        return None
    p = Path(data).parent / "tools" / "render_floor.py"
    return p if p.exists() else None
