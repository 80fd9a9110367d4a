"""One VO pass shared by pipelines that differ only after VO: `Pipeline.odometry` + `run(odometry=...)`."""
from dataclasses import replace

import numpy as np
import pytest

from vslam.errors import VslamError
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.sim import SimConfig, simulate


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    root = tmp_path_factory.mktemp("shared_vo")
    simulate(SimConfig(length=5.0, fps=15.0, speed=0.5, seed=6), root / "seq")
    return open_sequence(root / "seq")


def _config(mode: int) -> PipelineConfig:
    base = PipelineConfig()
    return base.replace(loops=base.loops.replace(mode=mode), recording=base.recording.replace(enabled=False))


@pytest.mark.parametrize("mode", [2, 5])
def test_a_shared_vo_pass_gives_the_same_run(seq, mode):
    vo = Pipeline(_config(4)).odometry(seq)                 # computed under another mode: VO does not use it
    fresh = Pipeline(_config(mode)).run(seq)
    shared = Pipeline(_config(mode)).run(seq, odometry=vo)
    np.testing.assert_array_equal(shared.poses_vo, fresh.poses_vo)
    np.testing.assert_array_equal(shared.keyframes, fresh.keyframes)
    np.testing.assert_allclose(shared.poses_slam, fresh.poses_slam, atol=1e-9)
    assert [(l.query_frame, l.match_frame, l.accepted, l.inlier) for l in shared.loops] == \
           [(l.query_frame, l.match_frame, l.accepted, l.inlier) for l in fresh.loops]
    assert any(l.accepted for l in fresh.loops)             # the comparison covers loops, not only VO


def test_odometry_of_another_sequence_or_too_short_is_refused(seq):
    vo = Pipeline(_config(4)).odometry(seq, max_frames=20)
    with pytest.raises(VslamError, match="20 frames"):
        Pipeline(_config(4)).run(seq, odometry=vo)
    shifted = [replace(e, timestamp=e.timestamp + 1.0) for e in Pipeline(_config(4)).odometry(seq)]
    with pytest.raises(VslamError, match="does not match frame 0"):
        Pipeline(_config(4)).run(seq, odometry=shifted)


def test_the_replay_reads_only_the_keyframes_images(seq, monkeypatch):
    vo = Pipeline(_config(4)).odometry(seq)
    read = []
    image = type(seq).image
    monkeypatch.setattr(type(seq), "image", lambda self, i, **kw: read.append(i) or image(self, i, **kw))
    res = Pipeline(_config(4)).run(seq, odometry=vo)
    assert sorted(read) == list(res.keyframes) and len(read) < len(seq) / 5
