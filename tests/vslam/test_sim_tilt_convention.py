"""The simulator's tilted view (vslam.sim.render.pixel_to_world_homography) uses the same roll/pitch convention
as CameraModel: the floor point of every pixel agrees with a CameraModel given that tilt and height (the VO's tilt
refinement estimates tilts in CameraModel's convention, so a mismatch would be a bias of every tilted frame)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from odometry.shared.camera import CameraModel
from vslam.sim.render import pixel_to_world_homography


@pytest.mark.parametrize("tilt", [(0.004, 0.0), (0.0, 0.004), (-0.03, 0.02)])
@pytest.mark.parametrize("mount", [(0.0, 0.0, 0.0), (0.2, -0.1, 0.5)])
def test_simulator_tilt_matches_the_camera_model(tilt, mount):
    cam = CameraModel(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5, camera_height=0.5,
                      mount=mount)
    h = 0.507
    px = np.array([[0.0, 0.0], [639.0, 0.0], [0.0, 479.0], [639.0, 479.0], [319.5, 239.5], [100.0, 400.0]])
    hom = pixel_to_world_homography(cam, np.zeros(3), h, tilt) @ np.column_stack([px, np.ones(len(px))]).T
    sim = (hom[:2] / hom[2]).T
    model = replace(cam, camera_height=h, tilt=tilt).pixel_to_floor(px)
    np.testing.assert_allclose(sim, model, atol=1e-9)
    # and the tilt matters at this size (a wrong sign or axis would be seen): 0.004 rad at 0.5 m is 2 mm
    assert np.max(np.abs(model - replace(cam, camera_height=h).pixel_to_floor(px))) > 1e-3
