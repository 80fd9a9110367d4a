"""Rerun recording of a SLAM run: one place for entity paths, styles and the default blueprint.

Entities (timelines `frame` and `time`):
    /camera/image                 the camera image (JPEG), with /keypoints and VO inlier /matches
    /world/...                    3D: trajectories (VO, SLAM, ground truth), robot pose, footprint, loop edges
    /map/...                      the same seen from above in 2D (y up: points are logged as (x, -y))
    /metrics/vo/*, /metrics/loops/*, /metrics/timing/*   time series
    /log                          text events (loops closed, tracking lost)
The file is written to a temporary name and renamed into place when `close()` finalises it.
"""
from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from odometry.shared.poses import transform_points
from odometry.shared.rotations import yaw_to_quat

GREEN, RED, GREY = (40, 190, 60), (220, 40, 40), (160, 160, 160)
COLOURS = {"vo": (255, 140, 0), "slam": (30, 120, 230), "gt": (90, 90, 90)}
_CHUNK = 50  # frames per incremental trajectory segment (keeps logging O(N))
_SCALAR_FLUSH = 200  # frames of buffered time series per send_columns call


def _flip(xy: np.ndarray) -> np.ndarray:
    """World (x, y) -> 2D view coordinates: rerun's 2D views have y down; the map keeps y up."""
    xy = np.asarray(xy, dtype=np.float32)
    return np.column_stack([xy[:, 0], -xy[:, 1]])


def blueprint():
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial2DView(origin="/camera/image", name="camera"),
                rrb.TimeSeriesView(origin="/metrics", name="metrics"),
                row_shares=[3, 2],
            ),
            rrb.Vertical(
                rrb.Spatial2DView(origin="/map", name="top-down map"),
                rrb.Horizontal(rrb.Spatial3DView(origin="/world", name="3D"),
                               rrb.TextLogView(origin="/log", name="events")),
                row_shares=[3, 2],
            ),
            column_shares=[2, 3],
        ),
        collapse_panels=True,
    )


class RunRecorder:
    """Log a run to an .rrd file without a viewer."""

    def __init__(self, path: str | Path, camera=None, recording_id: str = "vslam", jpeg_quality: int = 75,
                 image_every: int = 1, application_id: str = "vslam"):
        import rerun as rr

        self.rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.name}.partial")
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id, send_properties=False)
        self.rec.save(str(self._tmp), default_blueprint=blueprint())
        self.rec.set_log_time_enabled(False)
        self.jpeg = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
        self.image_every = max(1, int(image_every))
        self.camera = camera
        self._seg: dict[str, list] = {"vo": [], "slam": []}
        self._seg_id: dict[str, int] = {"vo": 0, "slam": 0}
        self._loops: dict[str, list] = {"accepted": [], "rejected": []}
        self._scalars: dict[str, tuple[list, list, list]] = {}
        self._frame, self._time, self._flushed_at = 0, 0.0, 0
        rec = self.rec
        rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for path_, names in (("/metrics/vo/inliers", "VO inliers"), ("/metrics/vo/inlier_ratio", "VO inlier ratio"),
                             ("/metrics/loops/local_score", "loop local score"),
                             ("/metrics/loops/global_score", "loop global score"),
                             ("/metrics/loops/probability", "P(loop | score)"),
                             ("/metrics/timing/vo_ms", "VO ms"), ("/metrics/timing/loops_ms", "loops ms"),
                             ("/metrics/timing/graph_ms", "graph ms"), ("/metrics/timing/frame_ms", "frame ms")):
            rec.log(path_, rr.SeriesLines(names=names), static=True)
        if camera is not None and camera.camera_height is not None:
            fp = camera.footprint()
            closed = np.vstack([fp, fp[:1]])
            rec.log("/world/robot/footprint", rr.LineStrips3D([np.column_stack([closed, np.zeros(len(closed))])],
                                                              colors=[(250, 200, 0)]), static=True)

    # ------------------------------------------------------------------ per frame
    def set_frame(self, index: int, timestamp: float) -> None:
        self._frame, self._time = int(index), float(timestamp)
        self.rec.set_time("frame", sequence=int(index))
        self.rec.set_time("time", duration=float(timestamp))

    def log_image(self, index: int, image: np.ndarray, keypoints: np.ndarray | None = None,
                  matches: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        rr = self.rr
        if index % self.image_every:
            return
        ok, buf = cv2.imencode(".jpg", image, self.jpeg)
        if ok:
            self.rec.log("/camera/image", rr.EncodedImage(contents=buf.tobytes(), media_type="image/jpeg"))
        if keypoints is not None and len(keypoints):
            self.rec.log("/camera/image/keypoints", rr.Points2D(np.asarray(keypoints, np.float32), radii=1.5,
                                                                colors=[(255, 230, 0)]))
        if matches is not None and len(matches[0]):
            a, b = (np.asarray(m, np.float32) for m in matches)
            self.rec.log("/camera/image/matches", rr.LineStrips2D(np.stack([a, b], axis=1), colors=[GREEN], radii=0.5))

    def log_pose(self, pose: np.ndarray, which: str = "vo") -> None:
        """Append the current pose to a trajectory; the robot follows the `slam` pose when given, else `vo`."""
        rr = self.rr
        seg = self._seg[which]
        seg.append(np.asarray(pose[:2], dtype=np.float32))
        if len(seg) >= _CHUNK:
            self._flush_segment(which)
        if which == "slam" or not self._seg["slam"]:
            q = [float(v) for v in yaw_to_quat(pose[2])]
            self.rec.log("/world/robot", rr.Transform3D(translation=[float(pose[0]), float(pose[1]), 0.0], quaternion=q))
            if self.camera is not None and self.camera.camera_height is not None:
                fp = transform_points(pose, self.camera.footprint())
                self.rec.log("/map/footprint", rr.LineStrips2D([_flip(np.vstack([fp, fp[:1]]))], colors=[(250, 200, 0)]))

    def _flush_segment(self, which: str, keep_last: bool = True) -> None:
        rr = self.rr
        seg = self._seg[which]
        if len(seg) < 2:
            return
        pts = np.asarray(seg)
        k = self._seg_id[which]
        self.rec.log(f"/world/trajectory/{which}/{k}", rr.LineStrips3D([np.column_stack([pts, np.zeros(len(pts))])],
                                                                       colors=[COLOURS[which]], radii=0.01))
        self.rec.log(f"/map/trajectory/{which}/{k}", rr.LineStrips2D([_flip(pts)], colors=[COLOURS[which]], radii=0.01))
        self._seg_id[which] = k + 1
        self._seg[which] = [seg[-1]] if keep_last else []

    def replace_trajectory(self, which: str, poses: np.ndarray) -> None:
        """Redraw a whole trajectory (after an optimisation moved it): one strip replaces the segments."""
        rr = self.rr
        for k in range(self._seg_id[which]):
            self.rec.log(f"/world/trajectory/{which}/{k}", rr.Clear(recursive=False))
            self.rec.log(f"/map/trajectory/{which}/{k}", rr.Clear(recursive=False))
        self._seg_id[which] = 0
        self._seg[which] = [np.asarray(p[:2], np.float32) for p in poses]
        pts = np.asarray(poses, dtype=np.float32)[:, :2]
        self.rec.log(f"/world/trajectory/{which}/0", rr.LineStrips3D([np.column_stack([pts, np.zeros(len(pts))])],
                                                                     colors=[COLOURS[which]], radii=0.01))
        self.rec.log(f"/map/trajectory/{which}/0", rr.LineStrips2D([_flip(pts)], colors=[COLOURS[which]], radii=0.01))
        self._seg_id[which] = 1
        self._seg[which] = [self._seg[which][-1]] if len(poses) else []

    def log_groundtruth(self, poses: np.ndarray) -> None:
        rr = self.rr
        p = np.asarray(poses, dtype=np.float32)
        p = p[~np.isnan(p[:, 0])]
        if len(p) < 2:
            return
        self.rec.log("/world/trajectory/gt", rr.LineStrips3D([np.column_stack([p[:, :2], np.zeros(len(p))])],
                                                             colors=[COLOURS["gt"]], radii=0.006), static=True)
        self.rec.log("/map/trajectory/gt", rr.LineStrips2D([_flip(p[:, :2])], colors=[COLOURS["gt"]], radii=0.006),
                     static=True)

    def log_scalars(self, **values: float) -> None:
        """Time series, e.g. log_scalars(**{"vo/inliers": 120, "timing/vo_ms": 4.2}).

        Buffered and sent as columns every `_SCALAR_FLUSH` frames: one log call per value cost ~1 ms each."""
        for k, v in values.items():
            if v is not None and np.isfinite(v):
                buf = self._scalars.setdefault(k, ([], [], []))
                buf[0].append(self._frame)
                buf[1].append(self._time)
                buf[2].append(float(v))
        if self._frame - self._flushed_at >= _SCALAR_FLUSH:
            self._flush_scalars()

    def _flush_scalars(self) -> None:
        rr = self.rr
        for k, (frames, times, vals) in self._scalars.items():
            if frames:
                self.rec.send_columns(f"/metrics/{k}", indexes=[rr.TimeColumn("frame", sequence=frames),
                                                                rr.TimeColumn("time", duration=times)],
                                      columns=rr.Scalars.columns(scalars=np.asarray(vals)))
        self._scalars = {}
        self._flushed_at = self._frame

    def log_loop(self, query_pose: np.ndarray, match_pose: np.ndarray, accepted: bool) -> None:
        """Add a loop edge (green accepted, red rejected) and redraw the loop layers."""
        kind = "accepted" if accepted else "rejected"
        self._loops[kind].append(np.array([query_pose[:2], match_pose[:2]], dtype=np.float32))
        self._draw_loops(kind)

    def set_loops(self, accepted: list, rejected: list) -> None:
        """Replace all loop edges (e.g. after the back end relabelled some as outliers)."""
        self._loops = {"accepted": [np.asarray(s, np.float32) for s in accepted],
                       "rejected": [np.asarray(s, np.float32) for s in rejected]}
        self._draw_loops("accepted")
        self._draw_loops("rejected")

    def _draw_loops(self, kind: str) -> None:
        rr = self.rr
        segs = self._loops[kind]
        colour = GREEN if kind == "accepted" else RED
        if not segs:
            self.rec.log(f"/world/loops/{kind}", rr.Clear(recursive=False))
            self.rec.log(f"/map/loops/{kind}", rr.Clear(recursive=False))
            return
        self.rec.log(f"/world/loops/{kind}", rr.LineStrips3D([np.column_stack([s, np.zeros(2)]) for s in segs],
                                                              colors=[colour], radii=0.008))
        self.rec.log(f"/map/loops/{kind}", rr.LineStrips2D([_flip(s) for s in segs], colors=[colour], radii=0.008))

    def log_text(self, message: str, level: str = "INFO") -> None:
        rr = self.rr
        self.rec.log("/log", rr.TextLog(message, level=getattr(rr.TextLogLevel, level, rr.TextLogLevel.INFO)))

    # ------------------------------------------------------------------ end
    def close(self) -> Path:
        self._flush_scalars()
        for which in ("vo", "slam"):
            self._flush_segment(which, keep_last=False)
        self.rec.disconnect()   # finalises the file (footer)
        os.replace(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        try:
            self.rec.disconnect()
        finally:
            if self._tmp.exists():
                self._tmp.unlink()
