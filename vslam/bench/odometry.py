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
from pathlib import Path

import numpy as np

NAME = "odometry"
HELP = "VO drift and frames/s on simulated floors vs wheel+gyro fusion and cv2.estimateAffinePartial2D"

NATURAL = ("carpet", "concrete", "asphalt", "tiles")
TRAJECTORIES = ("loop", "figure8", "lawnmower", "random")
SEGMENTS = (1.0, 2.0, 5.0, 10.0)


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


# ---------------------------------------------------------------------------------------------------- metrics

def drift_metrics(est: np.ndarray, gt: np.ndarray, segments=SEGMENTS, step: int = 5) -> dict:
    """Drift of planar poses `est` against `gt` (both (N, 3), same frames; NaN gt rows are skipped)."""
    from odometry.shared.poses import between, wrap_angle

    ok = np.all(np.isfinite(gt), axis=1)
    est, gt = est[ok], gt[ok]
    dist = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(gt[:, :2], axis=0).T))])
    out: dict = {"path_m": float(dist[-1])}
    trans, rot = [], []
    for length in segments:
        if dist[-1] < length:
            continue
        starts = np.arange(0, len(gt), step)
        ends = np.searchsorted(dist, dist[starts] + length)
        keep = ends < len(gt)
        s, e = starts[keep], ends[keep]
        de, dg = between(est[s], est[e]), between(gt[s], gt[e])
        seg_len = dist[e] - dist[s]
        trans.append(np.hypot(*(de[:, :2] - dg[:, :2]).T) / seg_len * 100.0)
        rot.append(np.degrees(np.abs(wrap_angle(de[:, 2] - dg[:, 2]))) / seg_len)
    out["segment_drift_pct"] = float(np.mean(np.concatenate(trans))) if trans else float("nan")
    out["segment_heading_deg_per_m"] = float(np.mean(np.concatenate(rot))) if rot else float("nan")
    g0 = between(gt[0], gt)  # ground truth expressed from its first pose, like the estimate
    e0 = between(est[0], est)
    out["end_drift_pct"] = float(np.hypot(*(e0[-1, :2] - g0[-1, :2])) / max(dist[-1], 1e-9) * 100.0)
    out["end_heading_deg_per_m"] = float(np.degrees(abs(wrap_angle(e0[-1, 2] - g0[-1, 2]))) / max(dist[-1], 1e-9))
    return out


# ---------------------------------------------------------------------------------------------------- one run

class _AffineBaseline:
    """cv2.estimateAffinePartial2D on the VO's own floor matches, chained through the VO's keyframes."""

    def __init__(self, camera, threshold_m: float):
        self.camera = camera
        self.threshold = threshold_m
        self.poses: list[np.ndarray] = []
        self.seconds: list[float] = []
        self.failures = 0

    def __call__(self, est) -> None:
        import cv2

        from odometry.shared.poses import compose
        from odometry.vo import Reference, VOStatus

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
    from dataclasses import replace

    from vslam.sim import Effects, SimConfig, simulate
    from vslam.sim.simulate import length_for_frames

    effects = replace(Effects(), dropped_frames=faults, corrupt_frames=faults)  # blur, lighting etc. stay on
    cfg = SimConfig(floor=floor, trajectory=trajectory, seed=seed, max_frames=frames, effects=effects,
                    length=length_for_frames(frames, SimConfig.fps, SimConfig.speed))
    out = where / (f"{floor}_{trajectory}_{frames}_s{seed}" + (f"_faults{faults:g}" if faults > 0 else ""))
    if not (out / "frames.csv").is_file():
        simulate(cfg, out, overwrite=True)
    return out


def run_sequence(path: Path, preset: str = "default", overrides: dict | None = None) -> dict:
    """VO + both baselines on one sequence directory; returns metrics and timings."""
    from odometry.fusion import fuse_wheel_gyro
    from odometry.shared.poses import between
    from odometry.vo import VOConfig, VOStatus, run_visual_odometry
    from vslam.io import open_sequence

    seq = open_sequence(path)
    cam = seq.require_camera()
    gt = seq.groundtruth_planar()
    gt = between(gt[0], gt)
    t0 = time.perf_counter()
    fused = fuse_wheel_gyro(seq.odometry.timestamps, seq.odometry.v, seq.odometry.omega, seq.imu.timestamps,
                            seq.imu.gyro_z, seq.timestamps)
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
    # covariance honesty: NEES of the per-frame motions measured by vision (3 on average when consistent)
    ok = np.array([s == VOStatus.OK for s in vo.status])
    ok[0] = False
    ok &= np.all(np.isfinite(gt), axis=1) & np.roll(np.all(np.isfinite(gt), axis=1), 1)
    idx = np.flatnonzero(ok)
    err = vo.deltas[idx] - between(gt[idx - 1], gt[idx])
    err[:, 2] = (err[:, 2] + np.pi) % (2 * np.pi) - np.pi
    nees = np.einsum("ni,ni->n", err, np.linalg.solve(vo.covariances[idx], err[:, :, None])[:, :, 0])
    aff = np.asarray(base.seconds[1:])
    counts = {s.value: int(sum(1 for x in vo.status if x == s)) for s in VOStatus}
    return {
        "sequence": path.name,
        "frames": len(seq),
        "status": counts,
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

def frontend_comparison(path: Path, pairs: int = 60, seed: int = 0) -> list[dict]:
    """Time and precision of candidate front ends on consecutive frame pairs of one sequence.

    For each pair: correspondences from the front end, back-projected to the floor, rigid RANSAC fit; reported
    are the median time per frame (detection on the new frame + matching / tracking), the number of inliers
    and their RMS residual in pixels (keypoint precision: what drift is made of).
    """
    import cv2

    from odometry.fusion import fuse_wheel_gyro
    from odometry.rigid import ransac_rigid_2d
    from odometry.tracking import detect_corners, highpass, normalize, track_lk
    from vslam.io import open_sequence

    seq = open_sequence(path)
    cam = seq.require_camera()
    m_px = cam.ground_resolution()
    rng = np.random.default_rng(seed)
    frames = [seq.image(i, gray=True) for i in range(min(len(seq), pairs + 1))]
    orb = cv2.ORB_create(nfeatures=1000)
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)

    def orb_pairs(a, b, kd_a):
        kb, db = orb.detectAndCompute(b, None)
        if kd_a[1] is None or db is None or len(kb) < 2:
            return np.zeros((0, 2)), np.zeros((0, 2)), (kb, db)
        good = [p[0] for p in bf.knnMatch(kd_a[1], db, k=2) if len(p) == 2 and p[0].distance < 0.8 * p[1].distance]
        pa = np.array([kd_a[0][g.queryIdx].pt for g in good]).reshape(-1, 2)
        pb = np.array([kb[g.trainIdx].pt for g in good]).reshape(-1, 2)
        return pa, pb, (kb, db)

    fused = fuse_wheel_gyro(seq.odometry.timestamps, seq.odometry.v, seq.odometry.omega, seq.imu.timestamps,
                            seq.imu.gyro_z, seq.timestamps[:len(frames)])

    def predicted(a_idx, b_idx, pts):  # the VO's own prediction: the fused wheel/gyro motion
        d = fused.relative(a_idx, b_idx)[0]
        fl = cam.pixel_to_floor(pts)
        c, s_ = np.cos(d[2]), np.sin(d[2])
        return cam.floor_to_pixel((fl - d[:2]) @ np.array([[c, -s_], [s_, c]]))

    rows = []
    variants = ["ORB 1000 + BF ratio test", "Shi-Tomasi + LK 3 levels (no prediction)",
                "ours: keyframe corners + LK 1 level from the prediction"]
    for name in variants:
        times, inl, rms = [], [], []
        state = None
        for k in range(1, len(frames)):
            a, b = frames[k - 1], frames[k]
            if name.startswith("ORB"):
                if state is None:
                    state = orb.detectAndCompute(a, None)
                t0 = time.perf_counter()
                pa, pb, state = orb_pairs(a, b, state)
                times.append(time.perf_counter() - t0)
            else:
                ours = name.startswith("ours")
                # ours: high-passed frames, single level; the classic pyramid needs the low frequencies
                ha, hb = (highpass(a), highpass(b)) if ours else (normalize(a), normalize(b))
                pa = detect_corners(ha, 200, (8, 6), 0.01, 14.0, 16, True)
                guess = predicted(k - 1, k, pa) if name.startswith("ours") else None
                levels = 0 if name.startswith("ours") else 3
                t0 = time.perf_counter()
                if not name.startswith("ours"):
                    pa = detect_corners(ha, 200, (8, 6), 0.01, 14.0, 16, True)  # detection on every frame
                pb, ok = track_lk(ha, hb, pa, guess, 15, levels, 20, 0.02, 1e-3)
                times.append(time.perf_counter() - t0)
                pa, pb = pa[ok], pb[ok]
            if len(pa) < 3:
                continue
            fit = ransac_rigid_2d(cam.pixel_to_floor(pb), cam.pixel_to_floor(pa), 1.5 * m_px, rng=rng)
            if fit is not None:
                inl.append(fit.n_inliers)
                rms.append(fit.rms / m_px)
        rows.append({"front_end": name, "ms_per_frame": float(np.median(times) * 1e3),
                     "inliers": float(np.median(inl)) if inl else 0.0,
                     "rms_px": float(np.median(rms)) if rms else float("nan")})
    return rows


# ---------------------------------------------------------------------------------------------------- command

METHODS = (("vo", "VO (LK + Kabsch/RANSAC)"), ("fusion", "(a) wheel + gyro EKF"),
           ("affine", "(b) estimateAffinePartial2D"))


def run(args: argparse.Namespace) -> int:
    import cv2

    from vslam.bench._common import format_table, write_json
    from vslam.cli.cmd_odometry import _overrides

    if args.frames < 50:
        raise ValueError("--frames must be at least 50")
    overrides = _overrides(args.set)
    from odometry.vo import VOConfig

    VOConfig.from_dict(overrides)  # fail early on a bad override
    floors = [f.strip() for f in args.floors.split(",") if f.strip()]
    frames = args.frames
    if args.quick:
        floors, frames = floors[:2], min(frames, 300)
    cv2.setNumThreads(max(1, args.threads))
    tmp = None
    if args.data:
        where = Path(args.data)
        where.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="vslam-bench-odometry-")
        where = Path(tmp.name)
    runs = [(floor, TRAJECTORIES[k % len(TRAJECTORIES)], args.seed + k, 0.0) for k, floor in enumerate(floors)]
    if args.faults > 0 and not args.quick:
        runs.append(("carpet", "random", args.seed + len(floors), args.faults))
    results, paths = [], []
    front: list[dict] = []
    try:
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
        front = frontend_comparison(paths[0], pairs=30 if args.quick else 100)
    finally:
        if tmp is not None:
            tmp.cleanup()

    headers = ["floor", "trajectory", "frames", "path m", "method", "drift % (1-10 m segments)", "end drift %",
               "heading deg/m", "frames/s"]
    rows = []
    for r in results:
        for key, label in METHODS:
            m = r[key]
            rows.append([r["floor"], r["trajectory"], r["frames"], round(m["path_m"], 1), label,
                         m["segment_drift_pct"], m["end_drift_pct"], m["segment_heading_deg_per_m"], m["fps"]])
    natural = [r for r in results if r["floor"] in NATURAL]
    summary = {}
    srows = []
    for key, label in METHODS:
        sel = natural or results
        med = {k: float(np.median([r[key][k] for r in sel])) for k in
               ("segment_drift_pct", "end_drift_pct", "segment_heading_deg_per_m", "fps")}
        summary[key] = med
        srows.append([label, med["segment_drift_pct"], med["end_drift_pct"], med["segment_heading_deg_per_m"],
                      med["fps"]])
    decode_ms = float(np.median([r["decode_ms"] for r in results]))
    print("\nVO covariance honesty (per-frame motions measured by vision; consistent: mean NEES 3, 95 % within "
          "the chi2(3) 95 % bound):")
    print(format_table(["floor", "mean NEES", "within 95 % bound"],
                       [[r["floor"], r["nees_mean"], r["nees_within_95pct"]] for r in results]))
    print()
    print(format_table(headers, rows))
    print()
    print(f"Median over {'natural floors (' + ', '.join(r['floor'] for r in natural) + ')' if natural else 'all'}:")
    print(format_table(["method", "drift %", "end drift %", "heading deg/m", "frames/s"], srows))
    vo, fa, af = summary["vo"], summary["fusion"], summary["affine"]
    checks = {
        "drift_le_0.5pct": vo["segment_drift_pct"] <= 0.5,
        "better_than_fusion": vo["segment_drift_pct"] < fa["segment_drift_pct"],
        "better_than_affine": vo["segment_drift_pct"] < af["segment_drift_pct"],
        "vo_fps_ge_100": vo["fps"] >= 100.0,
    }
    if front:
        print("\nFront ends on consecutive frames of the first sequence (time: detection/description on the new frame "
              "+ matching or tracking):")
        print(format_table(["front end", "ms/frame", "inliers", "inlier RMS px"],
                           [[f["front_end"], f["ms_per_frame"], f["inliers"], f["rms_px"]] for f in front]))
    print(f"\nimage decode (excluded above): {decode_ms:.2f} ms/frame ({1e3 / decode_ms:.0f} frames/s)")
    print("targets: " + ", ".join(f"{k} {'met' if v else 'NOT met'}" for k, v in checks.items()))
    if args.out:
        write_json(args.out, {"benchmark": "odometry", "quick": bool(args.quick), "frames": frames,
                              "preset": args.preset, "overrides": overrides, "opencv_threads": max(1, args.threads),
                              "seed": args.seed, "sequences": results, "front_ends": front,
                              "summary_natural_median": summary, "decode_ms": decode_ms, "targets": checks})
        print(f"wrote {args.out}")
    return 0
