"""`vslam bench odometry --regimes`: the VO outside the 30 fps ground-robot regime (issue 13), on both renderers,
against the naive ORB chain in the same run.

Regimes (our simulator, `vslam.sim`): survey lanes flown in alternating directions at 0.2 / 0.1 Hz with 35 % and
60 % of the footprint between frames and turns in place at the lane ends, camera heights 0.05-100 m (the ground
photographs magnified with the height, `SimConfig.scene_scale`), runs of dropped frames, lens distortion with
heavy JPEG and auto-exposure jumps. Independent renderer (`../shared/tools/render_floor.py`, shared textures): it
ties motion blur to the frame interval (a third of it), so a low-rate sequence is every k-th frame of a 30 fps
one (k = 22: 35 % of the footprint per frame, k = 38: 60 %); it has no lanes, turns in place or camera heights
beyond a few metres, so those regimes are ours only.

Per sequence: our VO (no wheel odometry, as on a drone) and the naive chain ORB(2000) + ratio test 0.8 +
cv2.estimateAffinePartial2D between consecutive frames (its similarity, back-projected through the camera to a
planar motion; a failed pair counts as untracked and adds no motion). ATE: RMS position error after a planar
rigid alignment, in metres and in % of the path length; drift: `vslam.evaluation.drift` over 1 m segments.
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from odometry.shared.poses import between
from odometry.vo import VOConfig, VOStatus, run_visual_odometry
from vslam.app.odometry import fuse_sequence_odometry
from vslam.bench.baseline_orb_chain import naive_orb_chain, planar_ate
from vslam.evaluation.drift import drift_metrics
from vslam.evaluation.tables import format_table
from vslam.io import open_sequence
from vslam.sim import Effects, SimConfig, simulate


def shared_dir() -> Path:
    """../shared beside the repository, or the parent of $VSLAM_SHARED_DATA (the shared data folder)."""
    data = os.environ.get("VSLAM_SHARED_DATA")
    return Path(data).resolve().parent if data else Path(__file__).resolve().parents[3] / "shared"

TEXTURES = ("skimage_cc0/gravel.png", "gazebo_models_ccby3/cloverleaf_interchange__concrete.png",
            "gazebo_models_ccby3/cloverleaf_interchange__grass.png", "aws_robomaker_mit0/racetrack_Ground_01_grass_dirt.png",
            "skimage_cc0/grass.png", "gazebo_models_ccby3/vrc_driving_terrain__grass_dry.png",
            "gazebo_models_ccby3/cloverleaf_interchange__road.png", "gazebo_models_ccby3/robocup09_spl_field__carpet.jpg",
            "aws_robomaker_mit0/house_FloorB_01_wood_planks.png", "skimage_cc0/brick.png",
            "gazebo_models_ccby3/drc_practice_wood_slats__wood_slats.png")
# tuning half (looked at while developing the descriptor path; e.g. a wrong ORB-only re-acquisition on seed 2 led
# to LK confirmation, a lost lane change on seed 13 to descriptors on the previous frame with its own corners):
# render_floor seeds 1-3, our lanes seeds 11 and 13, and the default demo sequence (carpet, seed 0) used to choose
# the height tracking. The camera height tracking (odometry.height) was developed on render_floor at 30 fps with
# grass+dry-grass s21 and road+carpet s22, and on our simulator's carpet/concrete/tiles/asphalt seeds 40-45
# (never on the `vslam bench odometry` sequences, seeds 0-3). The rest is the reporting half.
TUNING = {"render_floor gravel+concrete s1 1/22", "ours lanes grass h40 s11", "render_floor lawn+grass-dirt s2 1/22",
          "render_floor grass+dry-grass s3 1/38", "ours lanes gravel h100 0.1Hz 60% s13",
          "render_floor grass+dry-grass s21 30fps", "render_floor road+carpet s22 30fps",
          # the graded height estimate (odometry.height) was developed on edge-like floors other than the reporting
          # wood planks + brick pair: they showed the same failure (> 0.3 % per metre with the 3-sigma switch)
          "render_floor wood-slats s35 30fps", "render_floor brick s36 30fps", "render_floor wood-slats+brick s38 30fps"}


@dataclass(frozen=True)
class Regime:
    name: str
    renderer: str     # "ours" or "render_floor"
    make: object      # callable(where: Path) -> Path
    fallback: bool = False   # use the sequence's wheel odometry as the VO's prediction and fallback
    low_rate: bool = False   # judged by the low-rate targets (every frame by vision, ATE <= 1 % of the path)


def _lanes(floor: str, h: float, fps: float, shift: float, seed: int, frames_per_lane: int = 6, lanes: int = 3,
           **effects) -> SimConfig:
    along = 640 * h / 500.0     # footprint along the lanes (image width)
    across = 480 * h / 500.0
    length = lanes * (frames_per_lane - 1) * shift * along + (lanes - 1) * 2 / 3 * across
    return SimConfig(floor=floor, trajectory="lanes", fps=fps, camera_height=h, scene_scale=h / 0.5,
                     speed=shift * along * fps, length=length, lanes=lanes, seed=seed,
                     effects=Effects(**effects) if effects else Effects())


def _ours(cfg: SimConfig, name: str):
    def make(where: Path) -> Path:
        out = where / name.replace(" ", "_").replace("/", "-")
        if not (out / "frames.csv").is_file():
            simulate(cfg, out, overwrite=True)
        return out
    return make


def render_floor_sequence(textures: tuple[int, ...], seed: int, step: int, name: str, laps: int = 1, shape: str = "loop"):
    def make(where: Path) -> Path:
        data = shared_dir() / "data"
        full = where / f"rf_{'-'.join(map(str, textures))}_s{seed}_{shape}{laps}"
        if not (full / "frames.csv").is_file():
            tex = [str(data / "textures" / TEXTURES[t]) for t in textures]
            subprocess.run([sys.executable, str(shared_dir() / "tools" / "render_floor.py"), str(full), "--textures", *tex, "--seed", str(seed),
                            "--laps", str(laps), "--shape", shape], check=True, capture_output=True)
        return subsample(full, where / name.replace(" ", "_").replace("/", "-"), step) if step > 1 else full
    return make


def subsample(src: Path, dst: Path, step: int) -> Path:
    """A sequence directory holding every `step`-th frame of `src` (images linked, ground truth kept; the wheel
    odometry is left out: it would be a prediction the low-rate regimes do not have)."""
    if (dst / "frames.csv").is_file():
        return dst
    dst.mkdir(parents=True, exist_ok=True)
    for f in ("camera.yaml", "groundtruth.txt"):
        shutil.copy(src / f, dst / f)
    if not (dst / "images").exists():
        os.symlink((src / "images").resolve(), dst / "images")
    lines = (src / "frames.csv").read_text().splitlines()
    (dst / "frames.csv").write_text("\n".join([lines[0]] + lines[1::step]) + "\n")
    return dst


def regimes() -> list[Regime]:
    """The sequences of the regimes table (tuning ones are marked in TUNING)."""
    r = []
    for name, (tex, seed, step) in {"render_floor gravel+concrete s1 1/22": ((0, 1), 1, 22),
                                    "render_floor lawn+grass-dirt s2 1/22": ((2, 3), 2, 22),
                                    "render_floor grass+dry-grass s3 1/38": ((4, 5), 3, 38),
                                    "render_floor lawn+grass-dirt s6 1/22": ((2, 3), 6, 22),
                                    "render_floor gravel+concrete s7 1/22": ((0, 1), 7, 22),
                                    "render_floor grass+dry-grass s8 1/38": ((4, 5), 8, 38)}.items():
        r.append(Regime(name, "render_floor", render_floor_sequence(tex, seed, step, name), low_rate=True))
    for name, cfg in {"ours lanes grass h40 s11": _lanes("grass", 40.0, 0.2, 0.35, 11),
                      "ours lanes asphalt h40 s12": _lanes("asphalt", 40.0, 0.2, 0.35, 12),
                      "ours lanes gravel h100 0.1Hz 60% s13": _lanes("gravel", 100.0, 0.1, 0.6, 13),
                      "ours lanes concrete h0.5 0.2Hz 35% s14": _lanes("concrete", 0.5, 0.2, 0.35, 14),
                      "ours lanes carpet h100 0.1Hz 60% s18": _lanes("carpet", 100.0, 0.1, 0.6, 18)}.items():
        r.append(Regime(name, "ours", _ours(cfg, name), low_rate=True))
    hi = {"ours carpet h0.05 30Hz s15": SimConfig(floor="carpet", camera_height=0.05, scene_scale=0.1, fps=30.0,
                                                  speed=0.06, length=1.5, seed=15),
          "ours carpet 10 dropped-frame runs of 8 s16": SimConfig(
              floor="carpet", fps=20.0, length=8.0, seed=16,
              effects=Effects(dropped_frames=0.01, dropped_run=8)),
          "ours tiles distortion JPEG 40 exposure jumps s17": SimConfig(
              floor="tiles", fps=10.0, length=8.0, seed=17, jpeg_quality=40, distortion=(-0.15, 0.03, 0, 0, 0),
              effects=Effects(exposure_jumps=0.1))}
    for name, cfg in hi.items():
        r.append(Regime(name, "ours", _ours(cfg, name)))
    for name, (tex, seed) in {"render_floor gravel+concrete s4 30fps": ((0, 1), 4),
                              "render_floor lawn+grass-dirt s5 30fps": ((2, 3), 5),
                              "render_floor wood-planks+brick s23 30fps": ((8, 9), 23),
                              "render_floor grass+dry-grass s21 30fps": ((4, 5), 21),
                              "render_floor road+carpet s22 30fps": ((6, 7), 22),
                              "render_floor wood-slats s35 30fps": ((10,), 35),
                              "render_floor brick s36 30fps": ((9,), 36),
                              "render_floor wood-slats+brick s38 30fps": ((10, 9), 38)}.items():
        r.append(Regime(name, "render_floor", render_floor_sequence(tex, seed, 1, name), fallback=True))
    return r


# ---------------------------------------------------------------------------------------------------- naive chain

# ---------------------------------------------------------------------------------------------------- measures

def measure(path: Path, fallback: bool = False, config: VOConfig | None = None) -> dict:
    seq = open_sequence(path)
    cam = seq.require_camera()
    gt = seq.groundtruth_planar()
    gt = between(gt[0], gt)
    fb = None
    if fallback and seq.odometry is not None:
        fused = fuse_sequence_odometry(seq)
        fb = lambda i: fused.relative(i - 1, i)  # noqa: E731
    vo = run_visual_odometry(cam, seq.timestamps, lambda i: seq.image(i, gray=True), config or VOConfig(),
                             fallback=fb)
    naive, naive_ok, naive_s = naive_orb_chain(seq, cam)
    length = float(np.sum(np.hypot(*np.diff(gt[:, :2], axis=0).T)))
    step_m = length / max(len(seq) - 1, 1)
    seg = (1.0,) if length >= 2.0 else (length / 2,)
    out = {"frames": len(seq), "path_m": length, "step_m": step_m,
           "footprint_shift": step_m / (cam.width * cam.camera_height / cam.fx),
           "vo": {"by_vision": int(sum(1 for s in vo.status[1:] if s == VOStatus.OK)),
                  "ate_m": planar_ate(vo.poses, gt), "drift_1m_pct": drift_metrics(vo.poses, gt, seg)["segment_drift_pct"],
                  "ms": float(np.median(vo.vo_seconds[1:]) * 1e3),
                  "methods": dict(Counter(m.value for m in vo.method[1:]))},
           "naive": {"by_vision": naive_ok, "ate_m": planar_ate(naive, gt),
                     "drift_1m_pct": drift_metrics(naive, gt, seg)["segment_drift_pct"], "ms": naive_s * 1e3}}
    for k in ("vo", "naive"):
        out[k]["ate_pct"] = out[k]["ate_m"] / length * 100.0
    return out


def run_regimes(where: Path, only: str | None = None, config: VOConfig | None = None) -> list[dict]:
    rows = []
    for reg in regimes():
        if only and only not in reg.name:
            continue
        t0 = time.perf_counter()
        path = reg.make(where)
        r = measure(path, reg.fallback, config)
        r.update(regime=reg.name, renderer=reg.renderer, half="tuning" if reg.name in TUNING else "reporting",
                 low_rate=reg.low_rate, seconds=time.perf_counter() - t0)
        rows.append(r)
        print(f"{reg.name}: VO {r['vo']['by_vision']}/{r['frames'] - 1} by vision, ATE {r['vo']['ate_pct']:.3f} % "
              f"({r['vo']['methods']}); naive {r['naive']['by_vision']}/{r['frames'] - 1}, "
              f"ATE {r['naive']['ate_pct']:.3f} %", flush=True)
    return rows


def table(rows: list[dict]) -> str:
    out = []
    for r in rows:
        n = r["frames"] - 1
        for key, label in (("vo", "VO"), ("naive", "naive ORB chain")):
            m = r[key]
            out.append([r["regime"], r["half"], r["frames"], round(r["path_m"], 1),
                        f"{r['footprint_shift'] * 100:.0f} %", label, f"{m['by_vision']}/{n}", m["ate_m"],
                        m["ate_pct"], m["drift_1m_pct"], m["ms"],
                        ", ".join(f"{k} {v}" for k, v in sorted(m.get("methods", {}).items()))])
    return format_table(["regime", "half", "frames", "path m", "shift / footprint", "method", "by vision", "ATE m",
                         "ATE % path", "drift % (1 m seg.)", "ms/frame", "VO methods"], out)


def targets(rows: list[dict]) -> dict:
    low = [r for r in rows if r["low_rate"] and r["half"] == "reporting"]
    hi = [r for r in rows if r["renderer"] == "render_floor" and not r["low_rate"] and r["half"] == "reporting"]
    return {"low_rate_every_frame_by_vision": all(r["vo"]["by_vision"] == r["frames"] - 1 for r in low),
            "low_rate_ate_le_1pct": all(r["vo"]["ate_pct"] <= 1.0 for r in low),
            "render_floor_30fps_drift_le_0.3pct": all(r["vo"]["drift_1m_pct"] <= 0.3 for r in hi)}


def ratio(a: float, b: float) -> float:
    return a / b if b else math.inf
