"""`vslam bench odometry`: downward VO drift and speed against two baselines measured in the same run.

Sequences come from the simulator (seeded; blur, lighting, vignetting, noise and camera wobble on; wheel
odometry and gyro with scale errors, noise, bias and slip). For each sequence:

- VO: `odometry.vo` (LK on keyframe corners -> floor -> Kabsch in RANSAC), with the fused wheel/gyro motion
  as prediction and fallback;
- baseline (a): wheel + gyro EKF fusion alone (`odometry.fusion`);
- baseline (b): OpenCV `estimateAffinePartial2D` (RANSAC) on exactly the same floor-point matches, chained
  through the same keyframes (rotation angle and translation of the similarity it returns).

Drift: translational error of relative motions over path segments of 1, 2, 5 and 10 m as % of the segment
length (KITTI-style, averaged over all segment starts), the same for heading in deg/m, and the end-point error
as % of the path length. Speed: the VO step alone (image decode excluded and reported separately), median per
frame; baseline (b) replaces our fit time by OpenCV's on the same matches.
"""
from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from odometry.fusion import fuse_wheel_gyro
from odometry.rigid import ransac_rigid_2d
from odometry.shared.poses import between, compose
from odometry.tracking import detect_corners, highpass, normalize, track_lk
from odometry.vo import Reference, VOConfig, VOStatus, run_visual_odometry
from vslam.app.odometry import fuse_sequence_odometry, parse_overrides
from vslam.bench import odometry_regimes, odometry_regimes_slam
from vslam.bench.docs import publish
from vslam.bench.results import BenchResult, write_json
from vslam.evaluation.drift import drift_metrics
from vslam.evaluation.tables import format_table
from vslam.io import open_sequence
from vslam.sim import Effects, SimConfig, simulate
from vslam.sim.simulate import length_for_frames

NATURAL = ("carpet", "concrete", "asphalt", "tiles")
TRAJECTORIES = ("loop", "figure8", "lawnmower", "random")
METHODS = (("vo", "VO (LK + Kabsch/RANSAC)"), ("fusion", "(a) wheel + gyro EKF"),
           ("affine", "(b) estimateAffinePartial2D"))
FRONT_ENDS = ("ORB 1000 + BF ratio test", "Shi-Tomasi + LK 3 levels (no prediction)",
              "ours: keyframe corners + LK 1 level from the prediction")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quick", action="store_true", help="two floors, 300 frames each (a smoke run, not the targets)")
    p.add_argument("--floors", default="carpet,concrete,asphalt,tiles,wood,gravel",
                   help="comma-separated floor types (targets are judged on carpet, concrete, asphalt, tiles)")
    p.add_argument("--frames", type=int, default=1000, help="frames per sequence (default 1000)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--preset", default="default", help="VOConfig preset: default, fast")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a VOConfig field for an ablation, e.g. --set refine_tilt=false (repeatable)")
    p.add_argument("--threads", type=int, default=1,
                   help="OpenCV threads (default 1: the machine is shared; the VO itself is single-threaded)")
    p.add_argument("--faults", type=float, default=0.03, metavar="P",
                   help="also run a carpet sequence with this probability of dropped and of corrupt frames "
                        "(reported separately; 0 to skip)")
    p.add_argument("--data", default=None, help="keep the simulated sequences here and reuse them on later runs")
    p.add_argument("--out", default=None, help="write the results as JSON here")
    p.add_argument("--regimes", action="store_true",
                   help="instead: low frame rates, large shifts, turns in place, camera heights 5 cm-100 m, dropped "
                        "runs, distortion/JPEG/exposure jumps on both renderers, against the naive ORB chain "
                        "(docs section odometry-regimes)")
    p.add_argument("--only", default=None, help="with --regimes: only regimes whose name contains this text")


# ---------------------------------------------------------------------------------------------------- one run

class _AffineBaseline:
    """Baseline (b): cv2.estimateAffinePartial2D (RANSAC) on the VO's own floor matches, chained through the VO's
    keyframes."""

    def __init__(self, camera, threshold_m: float):
        self.camera = camera
        self.threshold = threshold_m
        self.poses: list[np.ndarray] = []
        self.seconds: list[float] = []
        self.failures = 0

    def __call__(self, est) -> None:
        i = est.index
        if i == 0:
            self.poses.append(np.zeros(3))
            self.seconds.append(0.0)
            return
        motion, base = est.delta, self.poses[i - 1]
        dt = 0.0
        if est.status == VOStatus.OK and len(est.matches) >= 2:
            ref = self.camera.pixel_to_floor(est.matches[:, :2])
            cur = self.camera.pixel_to_floor(est.matches[:, 2:])
            t0 = time.perf_counter()
            m, _ = cv2.estimateAffinePartial2D(cur, ref, method=cv2.RANSAC, ransacReprojThreshold=self.threshold,
                                               maxIters=2000, confidence=0.999, refineIters=10)
            dt = time.perf_counter() - t0
            if m is not None:
                motion = np.array([m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0])])
                if est.reference == Reference.KEYFRAME:
                    base = self.poses[est.keyframe_index]
            else:
                self.failures += 1
        self.poses.append(compose(base, motion))
        self.seconds.append(dt)


def _simulate(floor: str, trajectory: str, frames: int, seed: int, where: Path, faults: float = 0.0) -> Path:
    effects = replace(Effects(), dropped_frames=faults, corrupt_frames=faults)  # blur, lighting etc. stay on
    cfg = SimConfig(floor=floor, trajectory=trajectory, seed=seed, max_frames=frames, effects=effects,
                    length=length_for_frames(frames, SimConfig.fps, SimConfig.speed))
    out = where / (f"{floor}_{trajectory}_{frames}_s{seed}" + (f"_faults{faults:g}" if faults > 0 else ""))
    if not (out / "frames.csv").is_file():
        simulate(cfg, out, overwrite=True)
    return out


def _nees(vo, gt: np.ndarray) -> np.ndarray:
    """Covariance honesty: NEES of the per-frame motions measured by vision (3 on average when consistent)."""
    ok = np.array([s == VOStatus.OK for s in vo.status])
    ok[0] = False
    ok &= np.all(np.isfinite(gt), axis=1) & np.roll(np.all(np.isfinite(gt), axis=1), 1)
    idx = np.flatnonzero(ok)
    err = vo.deltas[idx] - between(gt[idx - 1], gt[idx])
    err[:, 2] = (err[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return np.einsum("ni,ni->n", err, np.linalg.solve(vo.covariances[idx], err[:, :, None])[:, :, 0])


def run_sequence(path: Path, preset: str = "default", overrides: dict | None = None) -> dict:
    """VO + both baselines on one sequence directory; returns metrics and timings."""
    seq = open_sequence(path)
    cam = seq.require_camera()
    gt = seq.groundtruth_planar()
    gt = between(gt[0], gt)
    t0 = time.perf_counter()
    fused = fuse_sequence_odometry(seq)
    fusion_s = time.perf_counter() - t0
    cfg = VOConfig.from_dict(overrides or {}, base=VOConfig.preset(preset))
    base = _AffineBaseline(cam, cfg.ransac_threshold_px * cam.ground_resolution())
    fit_s: list[float] = []

    def on_frame(est) -> None:
        fit_s.append(est.fit_seconds)
        base(est)

    vo = run_visual_odometry(cam, seq.timestamps, lambda i: seq.image(i, gray=True), cfg,
                             fallback=lambda i: fused.relative(i - 1, i), on_frame=on_frame)
    vo_s = vo.vo_seconds[1:]
    fit = np.asarray(fit_s[1:])
    nees = _nees(vo, gt)
    aff = np.asarray(base.seconds[1:])
    return {
        "sequence": path.name,
        "frames": len(seq),
        "status": {s.value: int(sum(1 for x in vo.status if x == s)) for s in VOStatus},
        "keyframes": int(vo.is_keyframe.sum()),
        "median_inliers": float(np.median(vo.n_inliers[1:])),
        "median_rms_px": float(np.nanmedian(vo.rms_px[1:])) if np.any(np.isfinite(vo.rms_px[1:])) else float("nan"),
        "decode_ms": float(np.median(vo.image_seconds) * 1e3),
        "nees_mean": float(np.mean(nees)) if len(nees) else float("nan"),
        "nees_within_95pct": float(np.mean(nees < 7.815)) if len(nees) else float("nan"),
        "vo": {**drift_metrics(vo.poses, gt), "step_ms": float(np.median(vo_s) * 1e3),
               "fit_ms": float(np.median(fit) * 1e3), "fps": float(1.0 / np.median(vo_s))},
        "fusion": {**drift_metrics(fused.poses, gt), "step_ms": fusion_s / len(seq) * 1e3,
                   "fps": len(seq) / fusion_s},
        "affine": {**drift_metrics(np.asarray(base.poses), gt),
                   "step_ms": float(np.median(vo_s - fit + aff) * 1e3),
                   "fit_ms": float(np.median(aff) * 1e3),
                   "fps": float(1.0 / np.median(vo_s - fit + aff)), "failures": base.failures},
    }


# ---------------------------------------------------------------------------------------------------- front ends

class _OrbPairs:
    """ORB 1000 + brute-force Hamming kNN with the ratio test; the previous frame's features are kept."""

    def __init__(self):
        self.orb = cv2.ORB_create(nfeatures=1000)
        self.bf = cv2.BFMatcher(cv2.NORM_HAMMING)
        self.state = None

    def __call__(self, k: int, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        if self.state is None:
            self.state = self.orb.detectAndCompute(a, None)
        t0 = time.perf_counter()
        ka, da = self.state
        kb, db = self.orb.detectAndCompute(b, None)
        if da is None or db is None or len(kb) < 2:
            pa, pb = np.zeros((0, 2)), np.zeros((0, 2))
        else:
            good = [p[0] for p in self.bf.knnMatch(da, db, k=2)
                    if len(p) == 2 and p[0].distance < 0.8 * p[1].distance]
            pa = np.array([ka[g.queryIdx].pt for g in good]).reshape(-1, 2)
            pb = np.array([kb[g.trainIdx].pt for g in good]).reshape(-1, 2)
        self.state = (kb, db)
        return pa, pb, time.perf_counter() - t0


class _LkPairs:
    """Corners tracked by LK: ours = high-passed frames, keyframe corners, one level from the predicted motion;
    else the classic pyramid (3 levels, no prediction, detection on every frame), which needs the low frequencies."""

    def __init__(self, predicted=None):
        self.predicted = predicted

    def __call__(self, k: int, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        ours = self.predicted is not None
        ha, hb = (highpass(a), highpass(b)) if ours else (normalize(a), normalize(b))
        pa = detect_corners(ha, 200, (8, 6), 0.01, 14.0, 16, True)
        guess = self.predicted(k - 1, k, pa) if ours else None
        t0 = time.perf_counter()
        if not ours:
            pa = detect_corners(ha, 200, (8, 6), 0.01, 14.0, 16, True)  # detection on every frame, timed
        pb, ok = track_lk(ha, hb, pa, guess, 15, 0 if ours else 3, 20, 0.02, 1e-3)
        dt = time.perf_counter() - t0
        return pa[ok], pb[ok], dt


def _front_end_row(name: str, pairs, frames, cam, rng) -> dict:
    """Median time per frame, inliers and inlier RMS (px) of a rigid RANSAC fit on a front end's floor points."""
    m_px = cam.ground_resolution()
    times, inl, rms = [], [], []
    for k in range(1, len(frames)):
        pa, pb, dt = pairs(k, frames[k - 1], frames[k])
        times.append(dt)
        if len(pa) < 3:
            continue
        fit = ransac_rigid_2d(cam.pixel_to_floor(pb), cam.pixel_to_floor(pa), 1.5 * m_px, rng=rng)
        if fit is not None:
            inl.append(fit.n_inliers)
            rms.append(fit.rms / m_px)
    return {"front_end": name, "ms_per_frame": float(np.median(times) * 1e3),
            "inliers": float(np.median(inl)) if inl else 0.0, "rms_px": float(np.median(rms)) if rms else float("nan")}


def frontend_comparison(path: Path, pairs: int = 60, seed: int = 0) -> list[dict]:
    """Time and precision of candidate front ends on consecutive frame pairs of one sequence.

    For each pair: correspondences from the front end, back-projected to the floor, rigid RANSAC fit; reported
    are the median time per frame (detection on the new frame + matching / tracking), the number of inliers
    and their RMS residual in pixels (keypoint precision: what drift is made of).
    """
    seq = open_sequence(path)
    cam = seq.require_camera()
    rng = np.random.default_rng(seed)
    frames = [seq.image(i, gray=True) for i in range(min(len(seq), pairs + 1))]
    fused = fuse_wheel_gyro(seq.odometry.timestamps, seq.odometry.v, seq.odometry.omega, seq.imu.timestamps,
                            seq.imu.gyro_z, seq.timestamps[:len(frames)])

    def predicted(a_idx, b_idx, pts):  # the VO's own prediction: the fused wheel/gyro motion
        d = fused.relative(a_idx, b_idx)[0]
        fl = cam.pixel_to_floor(pts)
        c, s_ = np.cos(d[2]), np.sin(d[2])
        return cam.floor_to_pixel((fl - d[:2]) @ np.array([[c, -s_], [s_, c]]))

    front_ends = (_OrbPairs(), _LkPairs(), _LkPairs(predicted))
    return [_front_end_row(name, fe, frames, cam, rng) for name, fe in zip(FRONT_ENDS, front_ends)]


# ---------------------------------------------------------------------------------------------------- command

def _runs(args: argparse.Namespace, floors: list[str]) -> list[tuple[str, str, int, float]]:
    """(floor, trajectory, seed, fault probability) of every sequence."""
    runs = [(floor, TRAJECTORIES[k % len(TRAJECTORIES)], args.seed + k, 0.0) for k, floor in enumerate(floors)]
    if args.faults > 0 and not args.quick:
        runs.append(("carpet", "random", args.seed + len(floors), args.faults))
    return runs


def _measure(args, runs, frames: int, overrides: dict, where: Path) -> tuple[list[dict], list[dict]]:
    """Every sequence simulated (or reused) and measured, one line each; then the front ends on the first."""
    results, paths = [], []
    for floor, traj, seed, faults in runs:
        t0 = time.perf_counter()
        path = _simulate(floor, traj, frames, seed, where, faults)
        t1 = time.perf_counter()
        r = run_sequence(path, args.preset, overrides)
        label = floor if faults == 0 else f"{floor} + {faults:.0%} dropped + {faults:.0%} corrupt frames"
        r.update(floor=label, trajectory=traj, simulate_s=t1 - t0, run_s=time.perf_counter() - t1)
        results.append(r)
        paths.append(path)
        print(f"{label:>12} {traj:>9}: VO {r['vo']['segment_drift_pct']:.3f} % "
              f"(end {r['vo']['end_drift_pct']:.3f} %), fusion {r['fusion']['segment_drift_pct']:.3f} %, "
              f"affine {r['affine']['segment_drift_pct']:.3f} %, VO {r['vo']['fps']:.0f} frames/s, "
              f"status {r['status']}", flush=True)
    return results, frontend_comparison(paths[0], pairs=30 if args.quick else 100)


def _summary(results: list[dict]) -> tuple[list[dict], dict]:
    """The natural-floor sequences (all when there are none) and the median of each method's figures over them."""
    natural = [r for r in results if r["floor"] in NATURAL]
    sel = natural or results
    summary = {key: {k: float(np.median([r[key][k] for r in sel])) for k in
                     ("segment_drift_pct", "end_drift_pct", "segment_heading_deg_per_m", "fps")}
               for key, _ in METHODS}
    return natural, summary


def _targets(summary: dict) -> dict:
    vo, fa, af = summary["vo"], summary["fusion"], summary["affine"]
    return {"drift_le_0.5pct": vo["segment_drift_pct"] <= 0.5,
            "better_than_fusion": vo["segment_drift_pct"] < fa["segment_drift_pct"],
            "better_than_affine": vo["segment_drift_pct"] < af["segment_drift_pct"],
            "vo_fps_ge_100": vo["fps"] >= 100.0}


def _tables(results, natural, summary, front) -> list[tuple[str, str]]:
    """(caption, table) in print order."""
    rows = [[r["floor"], r["trajectory"], r["frames"], round(r[key]["path_m"], 1), label,
             r[key]["segment_drift_pct"], r[key]["end_drift_pct"], r[key]["segment_heading_deg_per_m"], r[key]["fps"]]
            for r in results for key, label in METHODS]
    over = "natural floors (" + ", ".join(r["floor"] for r in natural) + ")" if natural else "all"
    out = [("VO covariance honesty (per-frame motions measured by vision; consistent: mean NEES 3, 95 % within "
            "the chi2(3) 95 % bound):",
            format_table(["floor", "mean NEES", "within 95 % bound"],
                         [[r["floor"], r["nees_mean"], r["nees_within_95pct"]] for r in results])),
           ("", format_table(["floor", "trajectory", "frames", "path m", "method", "drift % (1-10 m segments)",
                              "end drift %", "heading deg/m", "frames/s"], rows)),
           (f"Median over {over}:",
            format_table(["method", "drift %", "end drift %", "heading deg/m", "frames/s"],
                         [[label, *(summary[key][k] for k in ("segment_drift_pct", "end_drift_pct",
                                                              "segment_heading_deg_per_m", "fps"))]
                          for key, label in METHODS]))]
    if front:
        out.append(("Front ends on consecutive frames of the first sequence (time: detection/description on the new "
                    "frame + matching or tracking):",
                    format_table(["front end", "ms/frame", "inliers", "inlier RMS px"],
                                 [[f["front_end"], f["ms_per_frame"], f["inliers"], f["rms_px"]] for f in front])))
    return out


def run_regimes_command(args: argparse.Namespace) -> BenchResult:
    """`--regimes`: the table of odometry_regimes, published into its own docs section."""
    cv2.setNumThreads(max(1, args.threads))
    with tempfile.TemporaryDirectory(prefix="vslam-bench-regimes-") as tmp:
        where = Path(args.data) if args.data else Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        config = VOConfig.from_dict(parse_overrides(args.set), base=VOConfig.preset(args.preset))
        rows = odometry_regimes.run_regimes(where, args.only, config)
        slam = odometry_regimes_slam.run_slam(where, args.only)     # the full pipeline in the low-rate regime
    checks = {**odometry_regimes.targets(rows), **odometry_regimes_slam.targets(slam)}
    md = odometry_regimes.table(rows) + "\n\n" + odometry_regimes_slam.table(slam) + "\n\ntargets: " + ", ".join(
        f"{k} {'met' if v else 'NOT met'}" for k, v in checks.items())
    print("\n" + md)
    if args.out:
        write_json(args.out, {"benchmark": "odometry-regimes", "rows": rows, "slam_rows": slam, "targets": checks})
    if not args.only:
        note = publish("odometry-regimes", md, "vslam bench odometry --regimes", getattr(args, "docs", None),
                       getattr(args, "docs_file", None))
        if note:
            print(note)
    return BenchResult(None)


def run(args: argparse.Namespace) -> BenchResult:
    if getattr(args, "regimes", False):
        return run_regimes_command(args)
    if args.frames < 50:
        raise ValueError("--frames must be at least 50")
    overrides = parse_overrides(args.set)
    VOConfig.from_dict(overrides)  # fail early on a bad override
    floors = [f.strip() for f in args.floors.split(",") if f.strip()]
    frames = args.frames
    if args.quick:
        floors, frames = floors[:2], min(frames, 300)
    cv2.setNumThreads(max(1, args.threads))
    with tempfile.TemporaryDirectory(prefix="vslam-bench-odometry-") as tmp:
        where = Path(args.data) if args.data else Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        results, front = _measure(args, _runs(args, floors), frames, overrides, where)
    natural, summary = _summary(results)
    checks = _targets(summary)
    decode_ms = float(np.median([r["decode_ms"] for r in results]))
    tables = _tables(results, natural, summary, front)
    closing = (f"image decode (excluded above): {decode_ms:.2f} ms/frame ({1e3 / decode_ms:.0f} frames/s)\n"
               "targets: " + ", ".join(f"{k} {'met' if v else 'NOT met'}" for k, v in checks.items()))
    print("\n" + "\n\n".join([f"{c}\n{t}" if c else t for c, t in tables] + [closing]))
    if args.out:
        write_json(args.out, {"benchmark": "odometry", "quick": bool(args.quick), "frames": frames,
                              "preset": args.preset, "overrides": overrides, "opencv_threads": max(1, args.threads),
                              "seed": args.seed, "sequences": results, "front_ends": front,
                              "summary_natural_median": summary, "decode_ms": decode_ms, "targets": checks})
        print(f"wrote {args.out}")
    return BenchResult("\n\n".join([f"{c}\n\n{t}" if c else t for c, t in tables] + [closing.replace("\n", "\n\n")]))
