"""Keyframe spacing scales with the camera's floor footprint (keyframes.footprint_fraction), not a fixed distance
in metres: a 40 m-high camera is not given a keyframe every frame, a 5 cm camera does not skip its footprint."""
import numpy as np
import pytest

from odometry.shared.camera import CameraModel
from odometry.shared.config import ConfigError
from odometry.vo import VOEstimate, VOStatus
from vslam.pipeline import KeyframePolicy, Pipeline, PipelineConfig


def _camera(height: float, width: int = 640, rows: int = 480, f: float = 500.0) -> CameraModel:
    return CameraModel(width=width, height=rows, fx=f, fy=f, cx=(width - 1) / 2, cy=(rows - 1) / 2,
                       camera_height=height)


def _keyframes(height: float, step: float, frames: int, camera: CameraModel | None = None, **policy) -> int:
    """Keyframes of a straight run along x at `step` metres per frame (VO given, no images, loops off)."""
    base = PipelineConfig()
    cfg = base.replace(keyframes=base.keyframes.replace(**policy), loops=base.loops.replace(enabled=False),
                       recording=base.recording.replace(enabled=False))
    p = Pipeline(cfg, camera or _camera(height))
    cov = np.diag([1e-8, 1e-8, 1e-10])
    for i in range(frames):
        d = np.array([step if i else 0.0, 0.0, 0.0])
        p.step(None, 0.1 * i, vo=VOEstimate(i, 0.1 * i, d, cov, VOStatus.OK if i else VOStatus.INIT,
                                            pose=np.array([step * i, 0.0, 0.0])))
    return len(p.keyframes)


def test_default_spacing_is_a_fraction_of_the_footprint_along_the_travel():
    # the default camera: 0.64 x 0.48 m footprint at 0.5 m -> 0.27 m driving along x, as the former 0.25 m
    # ("the first frame past 0.25 m", 0.275 m on average at 5 cm per frame)
    assert KeyframePolicy().spacing(_camera(0.5), (1.0, 0.0)) == pytest.approx(0.42 * 0.64)
    assert KeyframePolicy().spacing(_camera(0.5), (0.0, -2.0)) == pytest.approx(0.42 * 0.48)
    assert KeyframePolicy().spacing(_camera(40.0), (1.0, 0.0)) == pytest.approx(0.42 * 51.2)
    assert KeyframePolicy().spacing(_camera(40.0)) == pytest.approx(0.42 * 38.4)   # no direction: the shorter extent
    assert KeyframePolicy(distance=0.25).spacing(_camera(40.0)) == 0.25   # the metric spacing stays an option


@pytest.mark.parametrize("height, step", [(40.0, 0.4), (0.5, 0.005), (0.05, 0.0005)])
def test_keyframes_per_footprint_do_not_depend_on_the_height(height, step):
    # the same run in footprints (150 frames, each 1/128 of the footprint's length) at any scale:
    # the same keyframe count; in metres (0.25 m) a 40 m camera made every frame a keyframe and a 5 cm one none
    n = _keyframes(height, step, 150)
    assert n == _keyframes(0.5, 0.005, 150)
    assert 3 <= n <= 6
    metric = _keyframes(height, step, 150, distance=0.25)
    if height != 0.5:
        assert metric == 150 or metric <= 3      # 5 cm: only the 60-frame rule


def test_footprint_spacing_needs_a_camera_height():
    cam = CameraModel(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5)
    with pytest.raises(ConfigError, match="keyframes.distance"):
        KeyframePolicy().spacing(cam)


def test_a_low_rate_run_keeps_every_frame_when_steps_are_a_large_part_of_the_spacing():
    # 14 m per frame under a camera 40 m up (35 % of its 40 m footprint length along the lanes, the drone lanes of
    # issue 13): the spacing is 17 m; "the first frame past it" made every second frame a keyframe (gaps of 28 m,
    # half the loop queries lost); the frame nearest the spacing is every frame here
    drone = _camera(40.0, width=562, rows=1000, f=556.0)
    assert KeyframePolicy().spacing(drone, (1.0, 0.0)) == pytest.approx(0.42 * 40.43, abs=0.01)
    assert _keyframes(40.0, 14.0, 20, drone) == 20
    # and at 5 Hz over the same ground (0.39 m per frame) about one keyframe per spacing, not one per frame
    assert 10 <= _keyframes(40.0, 0.392, 500, drone) <= 14
