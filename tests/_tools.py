"""Where the tests find the independent floor renderer (../shared/tools/render_floor.py), and what they render with it."""
from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

import cv2
import numpy as np


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


@dataclass
class FloorScene:
    """render_floor.py's floor mosaic and trajectory, built with its own functions (so views rendered here are the
    sequence's own, in a fraction of the time): `rng` has drawn what build_floor draws, the image model's
    draws follow from it; `warp(i)` is frame i's view of the floor before blur, exposure, noise and JPEG."""

    rf: ModuleType
    rng: np.random.Generator
    t: np.ndarray
    xs: np.ndarray
    ys: np.ndarray
    th: np.ndarray
    floor: np.ndarray
    x0: float
    y0: float
    fh: float
    size: tuple[int, int]
    focal: float
    vignette: np.ndarray

    def height(self, i: int) -> float:
        return 0.5 * (1 + 0.01 * math.sin(0.7 * self.t[i]))

    def warp(self, i: int) -> np.ndarray:
        (w, h), f = self.size, self.focal
        cx, cy = (w - 1) / 2, (h - 1) / 2
        hh, c, s = self.height(i), math.cos(self.th[i]), math.sin(self.th[i])
        a = np.array([[hh / f, 0.0, -cx * hh / f], [0.0, -hh / f, cy * hh / f]])
        aw = np.array([[c, -s], [s, c]]) @ a
        aw[:, 2] += [self.xs[i], self.ys[i]]
        res = self.rf.RES
        m_floor = np.array([[1 / res, 0, -self.x0 / res], [0, -1 / res, (self.y0 + self.fh) / res]])
        m = m_floor[:, :2] @ aw
        m[:, 2] += m_floor[:, 2]
        return cv2.warpAffine(self.floor, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_REFLECT).astype(np.float32)


def render_floor_scene(textures: list[str], laps: int, seed: int, size: tuple[int, int] = (640, 480),
                       focal: float = 500.0) -> FloorScene:
    """The scene of `render_floor.py --textures T... --laps N --seed S` at 30 fps (textures relative to
    $VSLAM_SHARED_DATA/textures); call only where render_floor_tool() is not None."""
    spec = importlib.util.spec_from_file_location("render_floor_tool", render_floor_tool())
    rf = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(rf)
    tex = Path(os.environ["VSLAM_SHARED_DATA"]) / "textures"
    rng = np.random.default_rng(seed)
    t, xs, ys, th, _ = rf.trajectory("loop", [2.0, 1.5], laps, 0.3, 30.0)
    x0, y0 = xs.min() - 1.0, ys.min() - 1.0
    fw, fh = xs.max() - xs.min() + 2.0, ys.max() - ys.min() + 2.0
    floor = rf.build_floor([str(tex / p) for p in textures], fw, fh, rng)
    w, h = size
    cx, cy = (w - 1) / 2, (h - 1) / 2
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    vignette = 1 - 0.25 * (((xx - cx) / cx) ** 2 + ((yy - cy) / cy) ** 2) / 2
    return FloorScene(rf, rng, t, xs, ys, th, floor, x0, y0, fh, size, focal, vignette)
