"""Low-rate VO where the independent renderer's mosaic holds a rotated copy of a texture patch (issue 13).

Every 38th frame of `render_floor.py --textures grass dry-grass --seed 3` at 30 fps, up to frame 342, is frames 0-9 of
the benchmark's "render_floor grass+dry-grass s3 1/38" sequence (every 38th frame: 59 % of the footprint between
frames, turns up to 56 degrees, no wheel odometry). At frame 8 the ORB matches hold two consensus sets: the true
motion (LK tracks about 51 of the 79 keyframe corners it puts in view) and a rotated copy 118 degrees and 0.22 m
away (about 30 of 45). Compared by the share of the corners in view the two tied, and the LK fit's own RANSAC seed
decided (wrong at seeds 2, 4, 5). The views are rendered here with the renderer's own floor, trajectory and image
model (its random numbers drawn in the same order), which takes seconds instead of rendering the whole lap.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from odometry.vo import VisualOdometry, VOConfig, VOStatus
from tests._tools import render_floor_scene, render_floor_tool
from tests.odometry._floor import camera, step_errors

pytestmark = pytest.mark.skipif(render_floor_tool() is None, reason="needs VSLAM_SHARED_DATA and ../tools/render_floor.py")

W, H, F = 640, 480, 500.0
STEP = 38
FRAMES = list(range(0, 9 * STEP + 1, STEP))   # frames 0-9 of the benchmark sequence


@pytest.fixture(scope="module")
def views():
    sc = render_floor_scene(["skimage_cc0/grass.png", "gazebo_models_ccby3/vrc_driving_terrain__grass_dry.png"],
                            laps=1, seed=3, size=(W, H), focal=F)
    rng, t, xs, ys = sc.rng, sc.t, sc.xs, sc.ys
    images, bright = {}, 0.0
    for i in range(FRAMES[-1] + 1):
        # render_floor's image model, drawing its random numbers in the same order (so the frames are the
        # sequence's own): height wobble, warp, motion blur, exposure, vignetting, noise, JPEG 95; only every
        # STEP-th frame is warped
        bright = 0.9 * bright + rng.normal(0, 1.0)
        noise = rng.normal(0, 2.0, (H, W))
        if i not in FRAMES:
            continue
        hh = sc.height(i)
        img = sc.warp(i)
        if i > 0:
            k = int(round(math.hypot(xs[i] - xs[i - 1], ys[i] - ys[i - 1]) / (hh / F) / 3))
            if k >= 2:
                ker = np.zeros((k, k), np.float32)
                ker[k // 2, :] = 1.0 / k
                img = cv2.filter2D(img, -1, ker)
        img = img * (1.0 + 0.15 * math.sin(0.2 * t[i]) + 0.01 * bright) * sc.vignette + noise
        _, buf = cv2.imencode(".jpg", np.clip(img, 0, 255).astype(np.uint8), [cv2.IMWRITE_JPEG_QUALITY, 95])
        images[i] = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    return images, t, np.column_stack([xs, ys, sc.th])


def _errors(views, config: VOConfig):
    images, t, gt = views
    vo = VisualOdometry(camera(), config)
    ests = [vo.process(images[f], t[f]) for f in FRAMES]
    return ests, step_errors(ests, gt, FRAMES)


@pytest.mark.parametrize("seed", range(6))
def test_a_rotated_copy_of_a_texture_patch_does_not_win_at_any_seed(views, seed):
    """Every frame measured by vision at the true place, whatever the RANSAC seed."""
    ests, err = _errors(views, VOConfig(seed=seed))
    assert all(e.status == VOStatus.OK for e in ests[1:]), [(e.index, e.status, e.reason) for e in ests]
    assert err[:, :2].max() < 5e-3 and err[:, 2].max() < 5e-3, err
