"""The SLAM pipeline: visual odometry -> keyframes -> loops (the configured recogniser) -> robust pose graph.

    from vslam.pipeline import Pipeline, PipelineConfig
    result = Pipeline(PipelineConfig()).run(open_sequence("demo/seq"))
    result.write("demo/out")

Online use: `p = Pipeline(config, camera)`, then `p.step(image, timestamp, prior)` per frame and `p.finish()`.
Pipelines that differ only after VO (e.g. in the loop descriptor's mode) can share one VO pass:
`vo = Pipeline(config).odometry(seq)`, then `Pipeline(other).run(seq, odometry=vo)`.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from odometry.fusion import fuse_wheel_gyro
from odometry.shared.camera import CameraModel
from odometry.shared.pose_covariance import compose_with_covariance
from odometry.shared.poses import between, compose
from odometry.vo import VisualOdometry, VOEstimate, VOStatus
from vslam.errors import VslamError
from vslam.pipeline.anchored_motion import Anchor, AnchoredMotion, agree
from vslam.pipeline.backend import backend_graph, floored
from vslam.pipeline.cluster_gate import ClusterGate
from vslam.pipeline.config import PipelineConfig
from vslam.pipeline.loop_pose import LoopPose, loop_pose
from vslam.pipeline.motion_gate import ChainMotion, DriftModel, MotionGate, step_drift_covariance
from vslam.pipeline.outputs import write_outputs
from vslam.pipeline.prefetch import lazy_frames, prefetch
from vslam.pipeline.recognizers import build_loop_detector


@dataclass
class LoopRecord:
    """One verified loop candidate (a row of loops.csv)."""

    query_frame: int
    match_frame: int
    global_score: float
    local_score: float
    probability: float
    accepted: bool                    # passed the mode threshold (and confirmation)
    n_inliers: int = 0                # descriptor matches that passed the geometric check
    delta: np.ndarray | None = None   # pose of the query keyframe in the matched keyframe's frame
    covariance: np.ndarray | None = None
    pose_inliers: int = 0
    pose_rms: float = 0.0             # metres: RMS residual of the floor fit's inliers
    loop_index: int | None = None     # index among the loops given to the back end
    inlier: bool | None = None        # the back end's verdict (None: not given to it)
    motion_consistent: bool | None = None   # the motion gate's verdict (None: gate off, or not verified)


@dataclass
class FrameOutput:
    index: int
    timestamp: float
    vo: VOEstimate
    pose_vo: np.ndarray
    pose_slam: np.ndarray
    keyframe: bool
    loops: list[LoopRecord]
    timings: dict[str, float]


@dataclass
class PipelineResult:
    config: PipelineConfig
    camera: CameraModel
    timestamps: np.ndarray
    poses_vo: np.ndarray
    poses_slam: np.ndarray
    keyframes: np.ndarray             # frame indices of the keyframes (graph nodes)
    loops: list[LoopRecord]
    graph: object                     # graph.model.PoseGraphData
    graph_result: object | None       # graph.result.GraphResult of the final optimisation
    timings: dict[str, np.ndarray]    # per-frame seconds: decode, vo, loops, graph, record, frame
    vo_status: np.ndarray             # per-frame VOStatus values
    vo_inliers: np.ndarray
    descriptor_bytes: np.ndarray      # per keyframe
    wall_seconds: float = 0.0
    sequence: str = ""
    similarity: list = field(default_factory=list)   # per keyframe: (frame, stored frames, retrieval scores)
    vo_orb_images: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # per frame (VOEstimate.orb_images)

    @property
    def accepted_loops(self) -> list[LoopRecord]:
        return [l for l in self.loops if l.accepted]

    def summary(self) -> dict:
        st = {s.value: int(np.sum(self.vo_status == s.value)) for s in VOStatus}
        n = len(self.timestamps)
        tm = {k: float(np.median(v)) * 1000 for k, v in self.timings.items() if len(v)}
        acc = self.accepted_loops
        kept = [l for l in acc if l.inlier]
        return {"frames": n, "keyframes": int(len(self.keyframes)), "vo_status": st,
                "loops_verified": len(self.loops), "loops_accepted": len(acc), "loops_kept": len(kept),
                "loops_rejected_by_backend": sum(1 for l in acc if l.inlier is False),
                "loops_without_pose": sum(1 for l in acc if l.delta is None),
                "loops_rejected_by_motion": sum(1 for l in self.loops if l.motion_consistent is False),
                "median_ms": tm, "wall_seconds": self.wall_seconds,
                "frames_per_second": n / self.wall_seconds if self.wall_seconds > 0 else float("nan"),
                "descriptor_bytes_mean": float(np.mean(self.descriptor_bytes)) if len(self.descriptor_bytes) else 0.0,
                "descriptor_bytes_max": int(np.max(self.descriptor_bytes)) if len(self.descriptor_bytes) else 0,
                "vo_orb_extractions": int(np.sum(self.vo_orb_images)),
                "vo_frames_with_orb": int(np.count_nonzero(self.vo_orb_images))}

    def write(self, out_dir: str | Path, **kw) -> Path:
        return write_outputs(self, out_dir, **kw)


class Pipeline:
    """Frame-by-frame SLAM. Create one per sequence (or call `reset`)."""

    def __init__(self, config: PipelineConfig | None = None, camera: CameraModel | None = None, recorder=None):
        self.config = config or PipelineConfig()
        self.recorder = recorder
        self.camera: CameraModel | None = None
        if camera is not None:
            self.reset(camera)

    # ------------------------------------------------------------------ setup
    def reset(self, camera: CameraModel) -> None:
        if camera.camera_height is None:
            raise VslamError("the SLAM pipeline needs a downward-facing camera: camera.yaml must give camera_height "
                             "(for loop detection alone on any camera use `vslam loops`)")
        cfg = self.config
        self.camera = camera
        self.vo = VisualOdometry(camera, cfg.vo)
        self.rng = np.random.default_rng(cfg.seed)
        gp = cfg.loops.gate
        self.relative_motion = AnchoredMotion(self._keyframe_motion, self._anchors, lambda: self.keyframes,
                                              gp.anchor_search, self._keyframe_motion_unscaled,
                                              gp.drift.trans_fraction) if gp.anchor_loops else self._keyframe_motion
        if not gp.enabled:
            self.gate = None
        elif gp.anchor_loops:
            self.gate = ClusterGate(self._loop_fit, self.relative_motion, gp, cfg.loops.image_sigma_rms)
        else:
            self.gate = MotionGate(self._loop_fit, self.relative_motion, gp, cfg.loops.image_sigma_rms)
        self.loop_detector = build_loop_detector(cfg, camera, self.gate)
        self.graph = backend_graph(cfg.graph, cfg.incremental)
        self.timestamps: list[float] = []
        self.poses_vo: list[np.ndarray] = []
        self.vo_status: list[str] = []
        self.vo_inliers: list[int] = []
        self.vo_orb_images: list[int] = []
        self.keyframes: list[int] = []
        self.kf_slam: list[np.ndarray] = []     # current estimate of each keyframe
        self.kf_step_cov: list[np.ndarray] = []  # VO covariance of the step from the previous keyframe
        self.loops: list[LoopRecord] = []
        self.graph_loops: list[LoopRecord] = []
        self._anchor: dict[int, Anchor] = {}     # per graph loop index: the loop as a gate anchor
        self._support: dict[int, int] = {}       # and how many accepted loops agree with it (itself included)
        self.descriptor_bytes: list[int] = []
        self.similarity: list[tuple] = []
        self.timings: dict[str, list[float]] = {k: [] for k in ("decode", "vo", "loops", "graph", "record", "frame")}
        self._acc_delta = np.zeros(3)            # VO motion since the last keyframe and its covariance
        self._acc_cov = np.zeros((3, 3))
        self._since_kf = 0
        self._last_step = 0.0                    # metres moved by the latest frame (the look-ahead of _is_keyframe)
        self._new_loops = 0
        self._last_image = None
        self.last_result = None
        self._graph_moved = False

    # ------------------------------------------------------------------ per frame
    def _is_keyframe(self, index: int) -> bool:
        if not self.keyframes:
            return True
        kp = self.config.keyframes
        d = self._acc_delta
        # the frame nearest the spacing becomes the keyframe (this one, when the next, at the current speed, would
        # be farther past it than this one is short of it): gaps average one spacing at any frame rate; "the first
        # frame past the spacing" made every second frame a keyframe at steps of 0.35-1 spacing (gaps up to two
        # spacings), and a low-rate run lost half its loop queries
        moved = math.hypot(d[0], d[1])
        return ((moved > 0 and moved + 0.5 * self._last_step >= kp.spacing(self.camera, (d[0], d[1]))) or abs(d[2]) >= math.radians(kp.angle_deg)
                or self._since_kf >= kp.max_frames)

    def slam_pose(self, index: int) -> np.ndarray:
        """The current SLAM estimate of frame `index`: its keyframe's optimised pose plus VO since then."""
        k = int(np.searchsorted(self.keyframes, index, side="right")) - 1
        kf = self.keyframes[k]
        return compose(self.kf_slam[k], between(self.poses_vo[kf], self.poses_vo[index]))

    def step(self, image: np.ndarray | Callable[[], np.ndarray | None] | None, timestamp: float,
             prior: tuple[np.ndarray, np.ndarray] | None = None, decode_seconds: float = 0.0,
             vo: VOEstimate | None = None) -> FrameOutput:
        """Process one frame. `image` may be None (unreadable frame); `prior` is the wheel/gyro motion since the
        previous frame and its covariance (the fallback when vision fails); `vo`, this frame's estimate from an
        earlier VO pass (`odometry`), replaces running VO. With `vo`, `image` may be a loader (no arguments,
        returns the image or None), called only if the frame becomes a keyframe or is recorded."""
        if self.camera is None:
            raise RuntimeError("call reset(camera) first (or give the camera to the constructor)")
        t_frame = time.perf_counter()
        loaded = 0.0                   # seconds spent calling the loader, inside this step
        if callable(image) and (vo is None or self.recorder is not None):
            image, loaded = _load(image)
        index = len(self.timestamps)
        t0 = time.perf_counter()
        est = self.vo.process(image, timestamp, fallback=prior) if vo is None else vo
        t_vo = time.perf_counter() - t0
        self.timestamps.append(float(timestamp))
        pose_vo = np.asarray(est.pose, float)
        self.poses_vo.append(pose_vo)
        self.vo_status.append(est.status.value)
        self.vo_inliers.append(int(est.n_inliers))
        self.vo_orb_images.append(int(est.orb_images))
        if index > 0:
            self._acc_delta, self._acc_cov = compose_with_covariance(self._acc_delta, self._acc_cov, est.delta,
                                                                     est.covariance)
        self._since_kf += 1
        self._last_step = math.hypot(est.delta[0], est.delta[1]) if index > 0 else 0.0
        keyframe = self._is_keyframe(index)
        t_loops = t_graph = 0.0
        found: list[LoopRecord] = []
        if keyframe:
            if callable(image):
                image, loaded = _load(image)
            t_loops, t_graph, found = self._keyframe_work(index, image)
        else:
            self._last_image = image   # kept (one frame) so that finish() can make the last frame a keyframe
        pose_slam = self.slam_pose(index)
        timings = {"decode": decode_seconds + loaded, "vo": t_vo, "loops": t_loops, "graph": t_graph}
        t0 = time.perf_counter()
        if self.recorder is not None:
            self._record(index, timestamp, image, est, pose_vo, pose_slam, found, timings)
        timings["record"] = time.perf_counter() - t0
        timings["frame"] = time.perf_counter() - t_frame + decode_seconds
        for k, v in timings.items():
            self.timings[k].append(v)
        return FrameOutput(index, float(timestamp), est, pose_vo, pose_slam, keyframe, found, timings)

    def _keyframe_work(self, index: int, image: np.ndarray | None) -> tuple[float, float, list[LoopRecord]]:
        t0 = time.perf_counter()
        self._add_keyframe(index)
        found = self._detect_loops(index, image) if self.loop_detector is not None and image is not None else []
        t_loops = time.perf_counter() - t0
        t0 = time.perf_counter()
        self._maybe_optimize()
        self._last_image = None
        return t_loops, time.perf_counter() - t0, found

    def _add_keyframe(self, index: int) -> None:
        if self.keyframes:
            prev = self.keyframes[-1]
            guess = compose(self.kf_slam[-1], self._acc_delta)
            cov = self._acc_cov + np.diag([1e-10, 1e-10, 1e-12])    # never singular (e.g. standing still)
            self.keyframes.append(index)
            self.kf_slam.append(guess)
            self.kf_step_cov.append(floored(cov))
            self.graph.add_node(index, guess)
            rel = between(self.poses_vo[prev], self.poses_vo[index])
            odo_cov = cov if not self.config.loops.gate.drift_in_graph else \
                cov + step_drift_covariance(rel, self.config.loops.gate.drift, self.camera.camera_height)
            self.graph.add_odometry(prev, index, rel, floored(odo_cov))
        else:
            self.keyframes.append(index)
            self.kf_slam.append(self.poses_vo[index].copy())
            self.kf_step_cov.append(np.zeros((3, 3)))
            self.graph.add_node(index, self.poses_vo[index])
        self._acc_delta = np.zeros(3)
        self._acc_cov = np.zeros((3, 3))
        self._since_kf = 0

    def _detect_loops(self, index: int, image: np.ndarray) -> list[LoopRecord]:
        detector = self.loop_detector
        obs = detector.recognizer.observe(image)   # cdvs: the decoded compact bytes, as a robot would store them
        self.descriptor_bytes.append(int(obs.nbytes))
        # similarity to every stored keyframe (recent ones too): the loop-score matrix plot's rows
        ranked = detector.recognizer.query(obs)
        self.similarity.append((index, np.array([int(r.key) for r in ranked], int),
                                np.array([float(r.score) for r in ranked])))
        stamp = float(self.timestamps[index])
        cands = detector.query(obs, key=index, stamp=stamp)
        detector.add(index, obs, stamp, self.poses_vo[index])   # footprint exclusion follows the VO poses
        out = []
        for c in cands:
            v = c.verification
            rec = LoopRecord(query_frame=index, match_frame=int(c.key), global_score=float(c.global_score),
                             local_score=float(c.score),
                             probability=float("nan") if v.probability is None else float(v.probability),
                             accepted=bool(c.accepted), n_inliers=int(v.n_inliers))
            rec.motion_consistent = c.motion_consistent
            if rec.accepted:
                judged = None if self.gate is None else self.gate.results.get((rec.match_frame, index))
                lp = judged.fit if judged is not None else self._loop_fit(v)
                if lp is not None:
                    rec.delta, rec.covariance, rec.pose_inliers = lp.delta, lp.covariance, lp.n_inliers
                    rec.pose_rms = float(lp.rms)
                    rec.loop_index = self.graph.add_loop(rec.match_frame, rec.query_frame, lp.delta,
                                                         floored(self._graph_loop_covariance(lp, not v.accepted)),
                                                         rec.probability)
                    self.graph_loops.append(rec)
                    self._add_anchor(rec)
                    self._new_loops += 1
            out.append(rec)
        self.loops.extend(out)
        return out

    def _graph_loop_covariance(self, lp: LoopPose, below_threshold: bool) -> np.ndarray:
        """The loop's covariance in the graph: its fit's, plus each image's registration error (common to all its
        pairs, so not in the fit's covariance): two images, each `image_sigma_rms` fit RMS residuals per axis; a
        loop accepted below the score threshold (few pairs on a small overlap) has its rotation variance scaled."""
        lc = self.config.loops
        cov = np.array(lp.covariance, float)
        if below_threshold:
            k = math.sqrt(lc.gated_rotation_variance)
            cov[2, :] *= k
            cov[:, 2] *= k
        s2 = 2.0 * (lc.image_sigma_rms * lp.rms) ** 2
        return cov + np.diag([s2, s2, 0.0])

    def _loop_fit(self, v) -> LoopPose | None:
        """The loop's floor motion from its verified pixel pairs (None: too few pairs on one rigid motion)."""
        lc = self.config.loops
        return loop_pose(self.camera, v.inliers_query, v.inliers_candidate, lc.pose_threshold_px,
                         lc.min_pose_inliers, lc.pose_pixel_sigma, self.rng)

    def _keyframe_motion(self, a: int, b: int, drift: DriftModel | None = None) -> tuple[np.ndarray, np.ndarray]:
        """VO motion from keyframe `a` to keyframe `b` (frame ids) and its drift-aware covariance: the chain of
        keyframes in between (the motion gate's odometry)."""
        ia = int(np.searchsorted(self.keyframes, a))
        ib = int(np.searchsorted(self.keyframes, b))
        kfs = self.keyframes[ia:ib + 1]
        chain = ChainMotion(np.array([self.poses_vo[k] for k in kfs]), drift or self.config.loops.gate.drift, keys=kfs,
                            step_cov=np.array(self.kf_step_cov[ia:ib + 1]), height=self.camera.camera_height)
        return chain(a, b)

    def _keyframe_motion_unscaled(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """`_keyframe_motion` without the drift model's scale term (anchored paths add it once, jointly)."""
        return self._keyframe_motion(a, b, self.config.loops.gate.drift.replace(trans_fraction=0.0))

    def _anchors(self) -> list[Anchor]:
        """Accepted loops with a floor fit that the back end has not rejected (the motion gate's anchors)."""
        return [self._anchor[r.loop_index] for r in self.graph_loops
                if r.inlier is not False and self._support[r.loop_index] >= self.config.loops.gate.anchor_support]

    def _add_anchor(self, rec: LoopRecord) -> None:
        """Count the support of a newly accepted loop: earlier accepted loops (the last few) that agree with it."""
        gp = self.config.loops.gate
        # as an anchor, the fit's position error is at least its RMS residual: at aerial scale its errors are
        # systematic (height, tilt, lens; 0.1-0.4 m at 40 m) and do not shrink with the number of inliers as its
        # stated covariance does (on a floor at 0.5 m the RMS is 2 mm and changes nothing)
        cov = np.asarray(rec.covariance, float) + np.diag([rec.pose_rms ** 2, rec.pose_rms ** 2, 0.0])
        x = Anchor(rec.match_frame, rec.query_frame, rec.delta, cov)
        self._anchor[rec.loop_index] = x
        self._support[rec.loop_index] = 1
        for r in self.graph_loops[-1 - 4 * gp.anchor_search:-1]:
            if r.inlier is not False and agree(self._keyframe_motion, x, self._anchor[r.loop_index], gp.chi2,
                                               self._keyframe_motion_unscaled, gp.drift.trans_fraction):
                self._support[rec.loop_index] += 1
                self._support[r.loop_index] += 1

    def _maybe_optimize(self, force: bool = False) -> None:
        """Batch: re-solve after `optimize_every` new loops (and at the end). Incremental: an iSAM2 update whenever
        loops arrived (nodes alone are batched by the back end), then the current estimate."""
        if force:
            self._apply(self.graph.result(warm_start=False))
            self._new_loops = 0
            return
        if self._new_loops == 0:
            return
        if self.graph.incremental:
            ids, poses = self.graph.update()
            k = {int(f): i for i, f in enumerate(self.keyframes)}
            for fid, p in zip(ids, poses):
                self.kf_slam[k[int(fid)]] = np.asarray(p, float)
            # keyframes not yet handed to iSAM2 follow their last estimated predecessor by odometry
            for i in range(len(ids), len(self.keyframes)):
                a, b = self.keyframes[i - 1], self.keyframes[i]
                self.kf_slam[i] = compose(self.kf_slam[i - 1], between(self.poses_vo[a], self.poses_vo[b]))
            inl = self.graph.loop_inliers()
            for rec in self.graph_loops:
                rec.inlier = bool(inl[rec.loop_index])
            self._new_loops = 0
            self._graph_moved = True
            return
        every = self.config.optimize_every
        if every <= 0 or self._new_loops < every:
            return
        self.graph.set_guesses(np.asarray(self.kf_slam))
        self._apply(self.graph.result(warm_start=True))
        self._new_loops = 0

    def _apply(self, res) -> None:
        self.last_result = res
        self._graph_moved = True      # the recording redraws the SLAM trajectory and loops at this frame
        self.kf_slam = [p.copy() for p in res.poses]
        for rec in self.graph_loops:
            rec.inlier = bool(res.loop_inlier[rec.loop_index])

    def finish(self) -> PipelineResult:
        """Final optimisation over all keyframes and loops; the result of the run."""
        last = len(self.timestamps) - 1
        if last > 0 and self.keyframes[-1] != last:
            # the end of the run is a keyframe too: on a closed path it is where the closing loop is found
            image = self._last_image
            _, _, found = self._keyframe_work(last, _load(image)[0] if callable(image) else image)
            if self.recorder is not None:
                for l in found:
                    if l.accepted:
                        self.recorder.log_text(f"loop {l.query_frame} -> {l.match_frame} (end of run)")
        t0 = time.perf_counter()
        if len(self.keyframes) > 1:
            self._maybe_optimize(force=True)
        t_final = time.perf_counter() - t0
        n = len(self.timestamps)
        slam = np.array([self.slam_pose(i) for i in range(n)]) if n else np.zeros((0, 3))
        timings = {k: np.asarray(v) for k, v in self.timings.items()}
        timings["final_optimisation"] = np.array([t_final])
        return PipelineResult(config=self.config, camera=self.camera, timestamps=np.asarray(self.timestamps),
                              poses_vo=np.asarray(self.poses_vo).reshape(-1, 3), poses_slam=slam,
                              keyframes=np.asarray(self.keyframes, int), loops=self.loops, graph=self.graph.to_data(),
                              graph_result=self.last_result, timings=timings, vo_status=np.asarray(self.vo_status),
                              vo_inliers=np.asarray(self.vo_inliers), descriptor_bytes=np.asarray(self.descriptor_bytes),
                              similarity=self.similarity, vo_orb_images=np.asarray(self.vo_orb_images, int))

    # ------------------------------------------------------------------ whole sequences
    def run(self, seq, progress: Callable[[int, int], None] | None = None, max_frames: int | None = None,
            odometry: Sequence[VOEstimate] | None = None) -> PipelineResult:
        """Process a whole `vslam.sequence.Sequence`; wheel/gyro streams (if any) give the fallback motion.
        `odometry`: the per-frame estimates of `odometry(seq)` of a pipeline with the same `vo` and `fusion`
        config, used instead of running VO again (the result is the same)."""
        t_start = time.perf_counter()
        self.reset(seq.require_camera())
        n = len(seq) if max_frames is None else min(len(seq), max_frames)
        if n == 0:
            raise VslamError(f"{seq.root or seq.name}: the sequence has no frames")
        if odometry is not None:
            _check_odometry(seq, n, odometry)
        priors = self._priors(seq, n) if odometry is None else None   # the priors only feed VO
        if self.recorder is not None and seq.groundtruth is not None:
            self.recorder.log_groundtruth(seq.groundtruth_planar()[:n])
        # after a VO pass, a frame's pixels are read only if it becomes a keyframe (about one in 15)
        frames = prefetch(seq, gray=True, stop=n) if odometry is None else lazy_frames(seq, stop=n)
        for fr in frames:
            prior = None if priors is None or fr.index == 0 else priors(fr.index)
            self.step(fr.image, fr.timestamp, prior, decode_seconds=fr.decode_seconds,
                      vo=None if odometry is None else odometry[fr.index])
            if fr.error and self.recorder is not None:
                self.recorder.log_text(f"frame {fr.index}: {fr.error}", "WARN")
            if progress is not None:
                progress(fr.index + 1, n)
        result = self.finish()
        result.wall_seconds = time.perf_counter() - t_start
        result.sequence = str(seq.root or seq.name)
        if self.recorder is not None:
            self.recorder.replace_trajectory("slam", result.poses_slam)
            self._record_final_loops(result)
        return result

    def odometry(self, seq, max_frames: int | None = None) -> list[VOEstimate]:
        """Visual odometry alone over a whole sequence, as `run` computes it (same decoding, same wheel/gyro
        fallback), for `run(seq, odometry=...)` of pipelines that differ only after VO."""
        n = len(seq) if max_frames is None else min(len(seq), max_frames)
        vo = VisualOdometry(seq.require_camera(), self.config.vo)
        priors = self._priors(seq, n)
        return [vo.process(fr.image, fr.timestamp, fallback=None if priors is None or fr.index == 0
                           else priors(fr.index)) for fr in prefetch(seq, gray=True, stop=n)]

    def _priors(self, seq, n: int):
        """relative(i-1, i) of the fused wheel/gyro trajectory at the frame times, or None without streams."""
        odo, imu = seq.odometry, seq.imu
        if odo is None and imu is None:
            return None
        fused = fuse_wheel_gyro(None if odo is None else odo.timestamps, None if odo is None else odo.v,
                                None if odo is None else odo.omega, None if imu is None else imu.timestamps,
                                None if imu is None else imu.gyro_z, seq.timestamps[:n], self.config.fusion)
        return lambda i: fused.relative(i - 1, i)

    # ------------------------------------------------------------------ recording
    def _record(self, index, timestamp, image, est: VOEstimate, pose_vo, pose_slam, found, timings) -> None:
        r = self.recorder
        r.set_frame(index, timestamp)
        if image is not None:
            m = est.matches
            pair = None
            if m is not None and len(m) and est.inliers is not None and len(est.inliers) == len(m):
                inl = m[np.asarray(est.inliers, bool)]
                pair = (inl[:, 0:2], inl[:, 2:4])
            r.log_image(index, image, keypoints=est.keypoints, matches=pair)
        r.log_pose(pose_vo, "vo")
        r.log_pose(pose_slam, "slam")
        vals = {"vo/inliers": est.n_inliers, "vo/inlier_ratio": est.inlier_ratio,
                "timing/vo_ms": timings["vo"] * 1000, "timing/loops_ms": timings["loops"] * 1000,
                "timing/graph_ms": timings["graph"] * 1000,
                "timing/frame_ms": (sum(timings.values())) * 1000}
        if found:
            best = max(found, key=lambda l: l.local_score)
            vals.update({"loops/local_score": best.local_score, "loops/global_score": best.global_score,
                         "loops/probability": best.probability})
        r.log_scalars(**vals)
        moved, self._graph_moved = self._graph_moved, False
        if moved:   # the optimiser moved the poses: redraw what depends on them (this frame's loops included)
            r.replace_trajectory("slam", np.array([self.slam_pose(i) for i in range(index + 1)]))
            self._record_loops(lambda i: self.slam_pose(i), self.loops)
        for l in found:
            if l.accepted:   # candidates below threshold show in the score time series (and at the end, hidden)
                if not moved:
                    r.log_loop(self.slam_pose(l.query_frame), self.slam_pose(l.match_frame), True)
                r.log_text(f"loop {l.query_frame} -> {l.match_frame}: local score {l.local_score:.1f}, "
                           f"P = {l.probability:.2f}, {l.pose_inliers} pose inliers")
        if est.status not in (VOStatus.OK, VOStatus.INIT):
            r.log_text(f"frame {index}: VO {est.status.value} ({est.reason})", "WARN")

    def _record_final_loops(self, result: PipelineResult) -> None:
        self._record_loops(lambda i: result.poses_slam[i], result.loops, candidates=True)

    def _record_loops(self, pose, loops: list[LoopRecord], candidates: bool = False) -> None:
        """Loops accepted by the detector, kept / rejected by the back end (during the run a loop not yet judged
        counts as kept; at the end one the back end never saw counts as rejected); verified candidates below the
        detector's threshold only with `candidates` (at the end: drawn once, in an entity hidden by default)."""
        def seg(l):
            return np.array([pose(l.query_frame)[:2], pose(l.match_frame)[:2]])

        def kept(l):
            return bool(l.inlier) if candidates else l.inlier is not False

        acc = [l for l in loops if l.accepted]
        self.recorder.set_loops([seg(l) for l in acc if kept(l)], [seg(l) for l in acc if not kept(l)],
                                [seg(l) for l in loops if not l.accepted] if candidates else None)


def _check_odometry(seq, n: int, odometry: Sequence[VOEstimate]) -> None:
    """Precomputed VO must cover the frames and belong to this sequence (same timestamps)."""
    name = seq.root or seq.name
    if len(odometry) < n:
        raise VslamError(f"{name}: the precomputed odometry has {len(odometry)} frames, the run needs {n}")
    for i in (0, n - 1):
        if odometry[i].index != i or odometry[i].timestamp != float(seq.timestamps[i]):
            raise VslamError(f"{name}: precomputed odometry frame {odometry[i].index} (t = {odometry[i].timestamp}) "
                             f"does not match frame {i} (t = {float(seq.timestamps[i])}) of the sequence")


def _load(loader: Callable[[], np.ndarray | None]) -> tuple[np.ndarray | None, float]:
    t0 = time.perf_counter()
    image = loader()
    return image, time.perf_counter() - t0
