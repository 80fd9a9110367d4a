"""Low-rate nadir lanes cut from a real ground photograph (issue 13): the owners' drone geometry scaled down.

16:9 frames (320 x 180, f scaled from 556 px at 1000 px), 40 m up, 35 % of the footprint along track between
frames, three lanes 37.5 % of the width apart flown in alternating directions (180 degree turns in place between
lanes), small jitter, sensor noise and JPEG. On the robocup carpet photograph the VO used to accept LK fits started
from the constant-velocity guess at the wrong place (20-35 consistent corners on a self-similar floor; both lane
turns landed a lane away): 21 % ATE while every frame counted as tracked.
"""
from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from odometry.shared.camera import CameraModel
from odometry.vo import VisualOdometry, VOConfig, VOStatus
from tests.odometry._floor import FloorRenderer

DATA = os.environ.get("VSLAM_SHARED_DATA")
pytestmark = pytest.mark.skipif(not DATA, reason="needs VSLAM_SHARED_DATA (a real ground photograph)")

W, H, HEIGHT = 320, 180, 40.0
F = 556.0 * W / 1000
S = HEIGHT / F   # metres per photograph pixel: the photograph at the camera's ground resolution


def _lanes(shift: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    step, spacing = shift * H * S, 0.375 * W * S   # along track = image rows; lanes across = image columns
    out = []
    for lane in range(3):
        for k in range(6):
            y = k * step if lane % 2 == 0 else (5 - k) * step
            th = 0.0 if lane % 2 == 0 else np.pi
            out.append([lane * spacing + rng.normal(0, 0.3), y + rng.normal(0, 0.3), th + rng.normal(0, np.radians(2))])
    p = np.array(out)
    return p - p.mean(0) * [1, 1, 0]


def _planar_ate(est: np.ndarray, gt: np.ndarray) -> float:
    a, b = est[:, :2] - est[:, :2].mean(0), gt[:, :2] - gt[:, :2].mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    r = vt.T @ np.diag([1.0, np.sign(np.linalg.det(vt.T @ u.T)) or 1.0]) @ u.T
    return float(np.sqrt(np.mean(np.sum((a @ r.T - b) ** 2, axis=1))))


def _run(config: VOConfig, shift: float = 0.35, seed: int = 2):
    tex = cv2.imread(str(Path(DATA) / "textures" / "gazebo_models_ccby3" / "robocup09_spl_field__carpet.jpg"),
                     cv2.IMREAD_GRAYSCALE)
    cam = CameraModel(width=W, height=H, fx=F, fy=F, cx=(W - 1) / 2, cy=(H - 1) / 2,
                      distortion=(0.0, 0.0, 0.0, 0.0, 0.0), camera_height=HEIGHT, mount=(0.0, 0.0, 0.0))
    half = tex.shape[0] * S / 2
    r = FloorRenderer(cam, tex, S, origin=(-half, half))
    gt = _lanes(shift, seed)
    rng = np.random.default_rng(seed + 100)
    vo = VisualOdometry(cam, config)
    ests = []
    for i, p in enumerate(gt):
        img = r.render(p).astype(np.float32) * rng.uniform(0.9, 1.1) + rng.normal(0, 2.0, (H, W))
        _, buf = cv2.imencode(".jpg", np.clip(img, 0, 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 90])
        ests.append(vo.process(cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE), i / 0.14))
    length = float(np.sum(np.linalg.norm(np.diff(gt[:, :2], axis=0), axis=1)))
    return ests, _planar_ate(vo.poses, gt) / length


def test_lane_turns_on_a_real_photograph_are_not_taken_at_a_wrong_place():
    ests, ate = _run(VOConfig())
    assert all(e.status == VOStatus.OK for e in ests[1:])
    assert ate < 0.005, ate          # under 0.5 % of the path (it is ~0.02 %)


def test_without_the_weak_lk_check_the_turns_go_wrong():
    """The same frames with the check off (the code before): every frame still counts as tracked, but the
    trajectory is wrong by several percent of the path. Guards the test above against a scene that is simply easy."""
    ests, ate = _run(VOConfig(lk_weak_inliers=0))
    assert all(e.status == VOStatus.OK for e in ests[1:])
    assert ate > 0.02, ate
