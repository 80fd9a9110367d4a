"""The pipeline takes its place recogniser from the config: cdvs by default, the vocabulary tree on request."""
import json
from dataclasses import replace

import pytest

from loops.cdvs.recognizer import CdvsRecognizer
from loops.vocab.recognizer import VocabRecognizer
from odometry.shared.errors import ConfigError
from vslam.io import open_sequence
from vslam.pipeline import Pipeline, PipelineConfig
from vslam.pipeline.recognizers import build_loop_detector
from vslam.sim import SimConfig, simulate

SIM = SimConfig(length=6.0, fps=15.0, speed=0.5, seed=4)


def test_cdvs_is_the_default_and_vocab_is_chosen_by_the_config():
    assert PipelineConfig().loops.recognizer == "cdvs"
    assert isinstance(build_loop_detector(PipelineConfig()).recognizer, CdvsRecognizer)
    cfg = PipelineConfig.from_dict({"loops": {"recognizer": "vocab", "vocab": {"min_inliers": 30}}})
    det = build_loop_detector(cfg)
    assert isinstance(det.recognizer, VocabRecognizer) and det.verifier.params.min_inliers == 30
    assert det.policy.exclude_recent == cfg.database_params().exclude_recent     # the one acceptance policy
    assert build_loop_detector(PipelineConfig.from_dict({"loops": {"enabled": False}})) is None
    assert PipelineConfig.from_dict(cfg.to_dict()) == cfg


@pytest.mark.parametrize("loops,match", [
    ({"recognizer": "horizon"}, "forward-looking camera"),
    ({"recognizer": "dbow"}, "must be one of cdvs, vocab"),
    ({"vocab": {"min_inliers": 1}}, "min_inliers"),
    ({"vocab": {"ratio": 1.5}}, "ratio"),
])
def test_bad_recognizer_settings_are_config_errors(loops, match):
    with pytest.raises(ConfigError, match=match):
        PipelineConfig.from_dict({"loops": loops})


def test_slam_with_the_vocabulary_tree_closes_the_loop(tmp_path):
    simulate(SIM, tmp_path / "seq")
    seq = open_sequence(tmp_path / "seq")
    cfg = PipelineConfig.from_dict({"loops": {"recognizer": "vocab"}})
    cfg = replace(cfg, recording=replace(cfg.recording, enabled=False))
    res = Pipeline(cfg).run(seq)
    out = res.write(tmp_path / "out", sequence=seq, plots=False)
    m = json.loads((out / "metrics.json").read_text())
    assert m["summary"]["loops_kept"] >= 1
    assert m["evaluation"]["loops"]["accepted"]["precision"] == 1.0
    assert m["evaluation"]["slam"]["start_to_end"]["error_distance"] < 0.05
    assert json.loads((out / "run.json").read_text())["config"]["loops"]["recognizer"] == "vocab"
