"""The loop detector of a SLAM run, built from its config: `loops.recognizer` picks the place recogniser (cdvs
compact descriptors, or the vocabulary tree over ORB with the shipped floor vocabulary), `loops.database` the
shared acceptance policy (loops.loop_detector). The pipeline only sees the contract of loops.recognition:
observe an image, query, add, and verified candidates with inlier pixel pairs.
"""
from __future__ import annotations

import dataclasses

from loops.cdvs.database import cdvs_loop_detector
from loops.cdvs.model import LoopModel
from loops.cdvs.params import CdvsParams
from loops.geometry import GeometryModel
from loops.loop_detector import LoopDetector, MotionGate
from loops.vocab.floor_vocabulary import load_floor_vocabulary
from loops.vocab.recognizer import VerifyParams, VocabRecognizer, VocabVerifier
from odometry.shared.camera import CameraModel
from vslam.pipeline.config import PipelineConfig

# a downward camera at a fixed height sees the floor at one scale: a verified transform must keep it
FLOOR_SCALE_RANGE = (0.8, 1.25)


def default_loop_model() -> LoopModel | None:
    """The loop model shipped with the package (None if this installation lacks it: the cdvs verifier then uses
    its trained per-mode local-score threshold)."""
    try:
        return LoopModel.default()
    except FileNotFoundError:
        return None


def cdvs_detector(config: PipelineConfig, camera: CameraModel | None = None,
                  gate: MotionGate | None = None) -> LoopDetector:
    lc = config.loops
    model = LoopModel.load(lc.model) if lc.model else default_loop_model()
    params = CdvsParams.floor(lc.mode) if lc.floor_preset else CdvsParams.for_mode(lc.mode)
    return cdvs_loop_detector(lc.mode, params, config.database_params(camera), model=model, camera=camera, gate=gate)


def vocab_detector(config: PipelineConfig, camera: CameraModel | None = None,
                   gate: MotionGate | None = None) -> LoopDetector:
    vc = config.loops.vocab
    tree, params = load_floor_vocabulary(vc.vocabulary)
    params = dataclasses.replace(params, n_features=vc.n_features, min_shared_words=vc.min_shared_words)
    verify = VerifyParams(ratio=vc.ratio, min_inliers=vc.min_inliers, threshold_px=vc.threshold_px,
                          geometry=GeometryModel.SIMILARITY, scale_range=FLOOR_SCALE_RANGE)
    return LoopDetector(VocabRecognizer(tree, params), VocabVerifier(verify), config.database_params(camera), camera=camera,
                        gate=gate)


def build_loop_detector(config: PipelineConfig, camera: CameraModel | None = None,
                        gate: MotionGate | None = None) -> LoopDetector | None:
    """The configured loop detector (None when loop detection is disabled). With the downward `camera`, keyframes
    added with their VO pose become candidates only once the camera has left their footprint (on top of the
    configured exclusion; loops.loop_detector); `gate` checks verified candidates against the motion."""
    if not config.loops.enabled:
        return None
    if config.loops.recognizer == "vocab":
        return vocab_detector(config, camera, gate)
    return cdvs_detector(config, camera, gate)
