"""Rerun recording of a SLAM run as a 3D scene (entity layout and blueprint: vslam.recording_layout).

The robot moves over a floor plane; its camera hangs under it with a Pinhole, so the viewer draws the frustum and
the (downscaled, JPEG) image where it lies on the floor. Trajectories are line strips (SLAM redrawn whenever the
pose graph is optimised, so scrubbing the timeline shows the correction), loops are arcs between the two poses,
coloured by the back end's verdict. The file is written to a temporary name and renamed into place by `close()`.
"""
from __future__ import annotations

import os
from datetime import timedelta
from pathlib import Path

import numpy as np

from odometry.shared.rotations import yaw_to_quat
from vslam import recording_layout as lay
from vslam.evaluation.plots import start_anchored
from vslam.recording_camera import encode_image, mount_transform, pinhole, scale_pixels, scaled_size

_CHUNK = 10          # poses per trajectory segment: the drawn line lags the robot by at most this many frames
_SCALAR_FLUSH = 200  # frames of buffered time series per send_columns call (one log call per value costs ~1 ms)
_ARC_POINTS = 13     # points per loop arc
_Z_LINES = 0.003     # trajectories and loops drawn 3 mm above the floor plane so that the plane never hides them


def loop_arc(a: np.ndarray, b: np.ndarray, rise: float) -> np.ndarray:
    """A loop edge from a to b (x, y) as a 3D arc that rises `rise` metres plus a quarter of its length: a loop
    joins two visits of one place, so a straight segment between them is often too short to see."""
    a, b = np.asarray(a, float)[:2], np.asarray(b, float)[:2]
    t = np.linspace(0.0, 1.0, _ARC_POINTS)[:, None]
    xy = a + t * (b - a)
    top = rise + 0.25 * float(np.linalg.norm(b - a))
    return np.column_stack([xy, _Z_LINES + 4.0 * top * t[:, 0] * (1.0 - t[:, 0])]).astype(np.float32)


def loop_ring(centre: np.ndarray, radius: float, z: float) -> np.ndarray:
    """A circle on the floor around a loop's query pose: the place of a loop stays visible when the arc is a
    vertical line (both visits at one spot) or hidden in the camera's frustum."""
    a = np.linspace(0.0, 2 * np.pi, 25)
    c = np.asarray(centre, float)[:2]
    return np.column_stack([c[0] + radius * np.cos(a), c[1] + radius * np.sin(a), np.full(len(a), z)]).astype(
        np.float32)


def _on_floor(xy: np.ndarray) -> np.ndarray:
    xy = np.asarray(xy, np.float32).reshape(-1, 2)
    return np.column_stack([xy, np.full(len(xy), _Z_LINES, np.float32)])


class RunRecorder:
    """Log a run to an .rrd file without a viewer.

    image_every: log every n-th camera image (with its keypoints and matches); image_scale: fraction of the full
    resolution the image is logged at; jpeg_quality: 0-100. The defaults keep the demo at a few kB per frame."""

    def __init__(self, path: str | Path, camera=None, recording_id: str = "vslam", jpeg_quality: int = 60,
                 image_every: int = 3, application_id: str = "vslam", image_scale: float = 0.5):
        import rerun as rr

        self.rr = rr
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.name}.partial")
        # chunks cut by size, never by a wall-clock tick: the default 0.2 s tick makes the file's size depend on
        # the machine's load (small chunks each carry their own schema)
        batching = rr.ChunkBatcherConfig(flush_tick=timedelta(hours=1), flush_num_bytes=1 << 20)
        self.rec = rr.RecordingStream(application_id, recording_id=recording_id, send_properties=False,
                                      batcher_config=batching)
        self.rec.save(str(self._tmp))       # the blueprint is sent by close(), when the scene's extent is known
        try:
            self._start(camera, jpeg_quality, image_every, image_scale)
        except BaseException:   # e.g. SIGTERM while the static scene is logged: leave no .partial behind
            self.abort()
            raise

    def _start(self, camera, jpeg_quality: int, image_every: int, image_scale: float) -> None:
        rr = self.rr
        self.rec.set_log_time_enabled(False)
        self.jpeg_quality = int(jpeg_quality)
        self.image_every = max(1, int(image_every))
        self.image_scale = float(image_scale)
        self.camera = camera
        self._seg: dict[str, list] = {"vo": [], "slam": []}
        self._seg_id: dict[str, int] = {"vo": 0, "slam": 0}
        self._loops: dict[str, list] = {"kept": [], "rejected": [], "candidates": []}
        self._scalars: dict[str, tuple[list, list, list]] = {}
        self._frame, self._time, self._flushed_at = 0, 0.0, 0
        self._lo, self._hi = np.full(2, np.inf), np.full(2, -np.inf)   # extent of everything drawn on the floor
        rec = self.rec
        rec.log("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for series in lay.SERIES.values():
            for path_, name in series:
                rec.log(f"/metrics/{path_}", rr.SeriesLines(names=name), static=True)
        self._size = None
        if camera is not None:
            self._size = scaled_size(camera, self.image_scale)
            self._sx, self._sy = self._size[0] / camera.width, self._size[1] / camera.height
            if camera.camera_height is not None:
                rec.log(lay.CAMERA, mount_transform(camera), static=True)
                rec.log(lay.IMAGE, pinhole(camera, self.image_scale), static=True)
                fp = camera.footprint()
                rec.log(lay.FOOTPRINT, rr.LineStrips3D([_on_floor(np.vstack([fp, fp[:1]]))], colors=[lay.YELLOW],
                                                       radii=0.004), static=True)

    # ------------------------------------------------------------------ per frame
    def set_frame(self, index: int, timestamp: float) -> None:
        self._frame, self._time = int(index), float(timestamp)
        self.rec.set_time("frame", sequence=int(index))
        self.rec.set_time("time", duration=float(timestamp))

    def log_image(self, index: int, image: np.ndarray, keypoints: np.ndarray | None = None,
                  matches: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Every `image_every`-th frame: the image (downscaled, JPEG), its keypoints and VO inlier matches."""
        rr = self.rr
        if index % self.image_every:
            return
        size = self._size or (image.shape[1], image.shape[0])
        sx, sy = (self._sx, self._sy) if self._size else (1.0, 1.0)
        blob = encode_image(image, size, self.jpeg_quality)
        if blob is not None:
            self.rec.log(lay.IMAGE, rr.EncodedImage(contents=blob, media_type="image/jpeg"))
        if keypoints is not None and len(keypoints):
            self.rec.log(lay.KEYPOINTS, rr.Points2D(scale_pixels(keypoints, sx, sy), radii=1.0, colors=[lay.YELLOW]))
        if matches is not None and len(matches[0]):
            a, b = scale_pixels(matches[0], sx, sy), scale_pixels(matches[1], sx, sy)
            self.rec.log(lay.MATCHES, rr.LineStrips2D(np.stack([a, b], axis=1), colors=[lay.GREEN], radii=0.4))

    def log_pose(self, pose: np.ndarray, which: str = "vo") -> None:
        """Append the current pose to a trajectory; the robot follows the `slam` pose when given, else `vo`."""
        rr = self.rr
        xy = np.asarray(pose[:2], dtype=np.float32)
        self._grow(xy[None])
        seg = self._seg[which]
        seg.append(xy)
        if len(seg) >= _CHUNK:
            self._flush_segment(which)
        if which == "slam" or not self._seg["slam"]:
            q = [float(v) for v in yaw_to_quat(pose[2])]
            self.rec.log(lay.ROBOT, rr.Transform3D(translation=[float(pose[0]), float(pose[1]), 0.0], quaternion=q))

    def _grow(self, xy: np.ndarray) -> None:
        xy = np.asarray(xy, float).reshape(-1, 2)
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if len(xy):
            self._lo = np.minimum(self._lo, xy.min(axis=0))
            self._hi = np.maximum(self._hi, xy.max(axis=0))

    def _strip(self, which: str, k: int, pts: np.ndarray) -> None:
        radius = 0.006 if which == "slam" else 0.004
        self.rec.log(f"{lay.TRAJECTORY}/{which}/{k}", self.rr.LineStrips3D([_on_floor(pts)], colors=[lay.COLOURS[which]],
                                                                          radii=radius))

    def _flush_segment(self, which: str, keep_last: bool = True) -> None:
        seg = self._seg[which]
        if len(seg) < 2:
            return
        k = self._seg_id[which]
        self._strip(which, k, np.asarray(seg))
        self._seg_id[which] = k + 1
        self._seg[which] = [seg[-1]] if keep_last else []

    def replace_trajectory(self, which: str, poses: np.ndarray) -> None:
        """Redraw a whole trajectory (after an optimisation moved it): one strip replaces the segments, logged at
        the current frame, so the timeline shows the trajectory before and after."""
        pts = np.asarray(poses, dtype=np.float32).reshape(-1, 3)[:, :2] if len(poses) else np.zeros((0, 2))
        for k in range(1, self._seg_id[which]):
            self.rec.log(f"{lay.TRAJECTORY}/{which}/{k}", self.rr.Clear(recursive=False))
        if len(pts) >= 2:
            self._strip(which, 0, pts)
        self._grow(pts)
        self._seg_id[which] = 1
        self._seg[which] = [pts[-1]] if len(pts) else []

    def log_groundtruth(self, poses: np.ndarray) -> None:
        """Ground truth (N, 3), drawn from where the estimate starts (the frame of its first valid pose)."""
        p = start_anchored(poses).astype(np.float32)
        p = p[~np.isnan(p[:, 0])]
        if len(p) < 2:
            return
        self._grow(p[:, :2])
        self.rec.log(f"{lay.TRAJECTORY}/gt", self.rr.LineStrips3D([_on_floor(p[:, :2])], colors=[lay.COLOURS["gt"]],
                                                                  radii=0.003), static=True)

    def log_scalars(self, **values: float) -> None:
        """Time series, e.g. log_scalars(**{"vo/inliers": 120, "timing/vo_ms": 4.2}); buffered, sent as columns."""
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

    # ------------------------------------------------------------------ loops
    def log_loop(self, query_pose: np.ndarray, match_pose: np.ndarray, accepted: bool | str = True) -> None:
        """Add one loop edge: True / "kept" (green), False / "rejected" (red, by the back end), or "candidates"
        (grey: verified but below the detector's threshold; hidden in the default view)."""
        kind = accepted if isinstance(accepted, str) else ("kept" if accepted else "rejected")
        self._loops[kind].append(np.array([query_pose[:2], match_pose[:2]], dtype=np.float32))
        self._draw_loops(kind)

    def set_loops(self, kept: list, rejected: list, candidates: list | None = None) -> None:
        """Replace the loop edges (after the back end relabelled some, or the poses moved); candidates are kept
        as they are when None."""
        self._loops["kept"] = [np.asarray(s, np.float32) for s in kept]
        self._loops["rejected"] = [np.asarray(s, np.float32) for s in rejected]
        kinds = ["kept", "rejected"]
        if candidates is not None:
            self._loops["candidates"] = [np.asarray(s, np.float32) for s in candidates]
            kinds.append("candidates")
        for kind in kinds:
            self._draw_loops(kind)

    def _draw_loops(self, kind: str) -> None:
        rr = self.rr
        segs = self._loops[kind]
        path = f"{lay.LOOPS}/{kind}"
        if not segs:
            self.rec.log(path, rr.Clear(recursive=False))
            return
        h = self.camera.camera_height if self.camera is not None and self.camera.camera_height else 0.5
        # low arcs (a loop at one spot is a pin 0.3 h tall) with a small ring at the foot, just above the image plane
        # (0.02 h above the floor): visible, yet dozens of them do not bury the trajectory
        strips = [loop_arc(s[0], s[1], 0.3 * h) for s in segs]
        if kind != "candidates":
            strips += [loop_ring(s[0], 0.08 * h, 0.03 * h) for s in segs]
        radius = 0.002 if kind == "candidates" else 0.005
        self.rec.log(path, rr.LineStrips3D(strips, colors=[lay.LOOP_COLOURS[kind]], radii=radius))

    def log_text(self, message: str, level: str = "INFO") -> None:
        rr = self.rr
        self.rec.log(lay.LOG, rr.TextLog(message, level=getattr(rr.TextLogLevel, level, rr.TextLogLevel.INFO)))

    # ------------------------------------------------------------------ end
    def _log_floor(self) -> np.ndarray | None:
        """The floor plane under everything drawn (static); returns the scene's (xmin, ymin, xmax, ymax)."""
        if not np.all(np.isfinite(self._lo)):
            return None
        margin = 0.5
        if self.camera is not None and self.camera.camera_height is not None:
            margin = float(np.abs(self.camera.footprint()).max()) + 0.1
        (x0, y0), (x1, y1) = self._lo - margin, self._hi + margin
        quad = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], np.float32)
        self.rec.log(lay.FLOOR, self.rr.Mesh3D(vertex_positions=quad, triangle_indices=[[0, 1, 2], [0, 2, 3]],
                                               vertex_normals=[[0, 0, 1]] * 4, albedo_factor=(215, 215, 210)),
                     static=True)
        return np.array([x0, y0, x1, y1])

    def close(self) -> Path:
        self._flush_scalars()
        for which in ("vo", "slam"):
            self._flush_segment(which, keep_last=False)
        bounds = self._log_floor()
        self.rec.send_blueprint(lay.blueprint(bounds), make_active=True, make_default=True)
        self.rec.disconnect()   # finalises the file (footer)
        os.replace(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        try:
            self.rec.disconnect()
        finally:
            if self._tmp.exists():
                self._tmp.unlink()
