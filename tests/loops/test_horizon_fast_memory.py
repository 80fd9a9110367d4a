"""Preset fast in the landmark memory, the recogniser / verifier and the pair files: they take the packed path
(loops.horizon.packed through loops.horizon.views), whose scores are those of match_bands with the same
parameters; packed memories survive a save / load; bad input is a typed error."""
from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest

from loops.errors import LoopsError
from loops.horizon import HorizonError, HorizonLine, HorizonParams, LandmarkMemory, load_memory, match_bands
from loops.horizon.bands import extract_bands
from loops.horizon.memory import MemoryFormatError
from loops.horizon.packed import PackedBands, PackedMatch
from loops.horizon.pairs_file import score_pairs_file
from loops.horizon.recognizer import HorizonRecognizer, HorizonVerifier
from tests.loops.test_horizon_bands import scene

FAST = HorizonParams.preset("fast")
ROW = 60.0
STORED = [scene(s, shift=4.0) for s in range(5)] + [scene(s + 50) for s in range(3)]


def band_scores(test_img, stored_imgs, p=FAST) -> np.ndarray:
    t = extract_bands(test_img, ROW, p)
    return np.array([match_bands(t, extract_bands(s, ROW, p), p).score_ransac for s in stored_imgs])


def fast_recognizer() -> HorizonRecognizer:
    rec = HorizonRecognizer(ROW, FAST)
    for k, im in enumerate(STORED):
        rec.add(f"v{k}", rec.observe(im))
    return rec


def test_the_recognizer_with_preset_fast_scores_all_bands_as_match_bands():
    rec = fast_recognizer()
    obs = rec.observe(scene(2))
    assert isinstance(obs, PackedBands) and obs.keys.shape[0] == FAST.bands
    ranked = rec.query(obs)
    ref = band_scores(scene(2), STORED)
    got = {r.key: r.score for r in ranked}
    np.testing.assert_allclose([got[f"v{k}"] for k in range(len(STORED))], ref, rtol=1e-5)
    assert ranked[0].key == "v2" and ranked[0].score > ranked[1].score
    among = rec.query(obs, among=2)
    assert [r.key for r in among] == sorted(("v0", "v1"), key=lambda k: -got[k])


def test_the_memory_recognises_with_the_packed_scores_and_reports_the_turn():
    rec = fast_recognizer()
    r = rec.memory.recognise(rec.observe(scene(2)), threshold=0.0)
    assert r.best == r.name == "v2" and isinstance(r.result, PackedMatch)
    np.testing.assert_allclose(r.score, band_scores(scene(2), STORED)[2], rtol=1e-5)
    # the stored view is the place shifted by 4 px: x_test - x_stored = -4 on average
    assert r.result.b_s == 1.0 and abs(r.result.b_d + 4.0) <= 2.0 and r.result.n_inliers >= FAST.ransac_min_inliers


def test_the_verifier_with_preset_fast_returns_the_consensus_columns():
    v = HorizonVerifier(FAST, threshold=0.0).verify(extract_bands_view(scene(2)), extract_bands_view(STORED[2]))
    assert v.accepted and v.n_inliers == len(v.inliers_query) == len(v.inliers_candidate) > 0
    np.testing.assert_allclose(v.score, band_scores(scene(2), [STORED[2]])[0], rtol=1e-5)
    shifts = v.inliers_query[:, 0] - v.inliers_candidate[:, 0]
    assert np.ptp(shifts) <= 2 * FAST.ransac_tolerance and v.transform[0] == 1.0


def extract_bands_view(img) -> PackedBands:
    return HorizonRecognizer(ROW, FAST).observe(img)


def test_a_packed_memory_survives_save_and_load(tmp_path):
    rec = fast_recognizer()
    rec.memory.save(tmp_path / "m.npz")
    back = load_memory(tmp_path / "m.npz")
    assert back.packed and back.names == rec.memory.names
    q = rec.observe(scene(3))
    np.testing.assert_array_equal(back.scores(q), rec.memory.scores(q))


def test_a_version_1_memory_with_fast_parameters_is_refused_naming_the_file(tmp_path):
    rec = fast_recognizer()
    rec.memory.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as z:
        data = {k: z[k] for k in z.files if not k.startswith("packed_")}
    data["version"] = np.array(1)
    with open(tmp_path / "old.npz", "wb") as fh:
        np.savez(fh, **data)
    with pytest.raises(MemoryFormatError, match="old.npz.*packed_x is missing"):
        load_memory(tmp_path / "old.npz")


def test_packed_and_per_pair_views_are_not_mixed():
    mem = LandmarkMemory(FAST)
    with pytest.raises(LoopsError, match="landmark 'a'"):
        mem.add("a", extract_bands(scene(1), ROW, FAST)[3])
    with pytest.raises(LoopsError, match="query view"):
        HorizonVerifier(FAST).verify(extract_bands(scene(1), ROW, FAST)[3], extract_bands_view(scene(1)))


def test_a_tilted_horizon_is_refused_on_the_packed_path_and_a_level_line_accepted():
    rec = HorizonRecognizer(HorizonLine(55, 65), FAST)
    with pytest.raises(HorizonError, match="level horizon"):
        rec.observe(scene(1))
    lvl = HorizonRecognizer(HorizonLine.level(ROW), FAST).observe(scene(1))
    np.testing.assert_array_equal(lvl.keys, extract_bands_view(scene(1)).keys)


def test_pairs_file_with_preset_fast_scores_as_match_bands(tmp_path):
    names = []
    for k, im in enumerate([scene(2), *STORED[:4]]):
        cv2.imwrite(str(tmp_path / f"i{k}.png"), im)
        names.append(f"i{k}.png")
    with open(tmp_path / "pairs.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["a", "b", "row_a", "row_b"])
        for a in names[1:]:
            w.writerow([a, names[0], ROW, ROW])
        w.writerow([names[0], names[1], ROW, ROW])     # a second test view, between the first one's pairs
    rows = score_pairs_file(tmp_path / "pairs.csv", tmp_path / "scores.csv", FAST)
    ref = band_scores(scene(2), STORED[:4])
    np.testing.assert_allclose([r["score_ransac"] for r in rows[:4]], ref, rtol=1e-5)
    np.testing.assert_allclose(rows[4]["score_ransac"], band_scores(STORED[0], [scene(2)])[0], rtol=1e-5)
    assert [r["a"] for r in rows] == [*names[1:], names[0]]


@pytest.mark.parametrize("field,value,message", [
    ("packed_keys", np.zeros((8, 7, 16, 6), np.float32), "field packed_keys has shape"),
    ("packed_valid", np.zeros((8, 7, 16)), "field packed_valid has shape"),
    ("packed_x", np.full((8, 7, 16), np.nan), "non-finite"),
])
def test_a_damaged_packed_memory_names_the_file_and_field(tmp_path, field, value, message):
    fast_recognizer().memory.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz") as z:
        data = {k: z[k] for k in z.files}
    data[field] = value
    with open(tmp_path / "bad.npz", "wb") as fh:
        np.savez(fh, **data)
    with pytest.raises(MemoryFormatError, match=f"bad.npz.*{message}"):
        load_memory(tmp_path / "bad.npz")
