"""Where the tests find the independent floor renderer (../shared/tools/render_floor.py), and what they render with it."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def render_floor_tool() -> Path | None:
    """render_floor.py beside $VSLAM_SHARED_DATA, or None (the tests that render with it skip with a reason)."""
    data = os.environ.get("VSLAM_SHARED_DATA")
    if not data:
        return None
    p = Path(data).parent / "tools" / "render_floor.py"
    return p if p.exists() else None


def render_printed_floor(out: Path, seed: int) -> Path:
    """A 2-lap, 10 fps sequence of render_floor.py's printed floor (the shared wood-plank photograph repeated every
    0.256 m, so places far apart look alike) in `out`; call only where render_floor_tool() is not None."""
    tex = Path(os.environ["VSLAM_SHARED_DATA"]) / "textures" / "aws_robomaker_mit0" / "house_FloorB_01_wood_planks.png"
    subprocess.run([sys.executable, str(render_floor_tool()), str(out), "--textures", str(tex), "--printed",
                    "--laps", "2", "--fps", "10", "--seed", str(seed)], check=True, stdout=subprocess.DEVNULL)
    return out
