"""1D SURF on real KITTI frames (../shared/data/places/kitti_snippets): a turn, a forward move, another place."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from loops.horizon import HorizonParams, extract_features, match

ROW = 183  # KITTI 06 principal point row cy = 183.1: the level car camera's horizon


@pytest.fixture(scope="module")
def frames(shared_data):
    root = shared_data / "places" / "kitti_snippets"
    seq1 = root / "KITTI_sequence_1_kitti06_f0000-0050" / "image_l"
    seq2 = root / "KITTI_sequence_2_unidentified_seq00-02calib" / "image_l"
    paths = {"f0": seq1 / "000000.png", "f2": seq1 / "000002.png", "other": seq2 / "000020.png"}
    out = {}
    for k, p in paths.items():
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if img is None:
            pytest.skip(f"{p} not readable")
        out[k] = img
    return out


def test_turning_gives_the_crop_shift_and_unit_scale(frames):
    p = HorizonParams()
    stored = extract_features(frames["f0"][:, 300:940], ROW, p)
    # The robot turned: the same frame seen through a crop 63 px to the left (not a multiple of the 4-px step).
    test = extract_features(frames["f0"][:, 237:877], ROW, p)
    r = match(test, stored, p)
    assert r.b_s == pytest.approx(1.0, abs=0.01)
    assert r.b_d == pytest.approx(63.0, abs=4.0)
    assert r.score_ransac >= p.recognition_threshold


def test_driving_forward_scales_up_and_other_places_score_lower(frames):
    p = HorizonParams()
    stored = extract_features(frames["f0"][:, 300:940], ROW, p)
    closer = match(extract_features(frames["f2"][:, 300:940], ROW, p), stored, p)   # 2.4 m further
    assert 1.0 <= closer.b_s <= 1.25          # landmarks ahead grow as the car approaches
    assert closer.score_ransac >= p.recognition_threshold
    other = [match(extract_features(frames["other"][:, o:o + 640], 185, p), stored, p).score_ransac
             for o in (0, 300, 600)]
    # Another drive scores far lower (the threshold allows ~5% false positives, so compare, don't threshold).
    assert closer.score_ransac > 2 * max(other)
    assert np.isfinite(closer.b_d)
