"""Packed multi-band 1D SURF (loops.horizon.packed): the same features and scores as extract_bands / match_bands
with the same parameters, on synthetic scenes and on real frames, on both paths (the compiled kernels of
loops.horizon.packed_jit, and the numpy fallback with numba hidden); the shift consensus; bad input."""
from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from loops.horizon import HorizonError, HorizonParams, extract_bands, match, match_bands
from loops.horizon import packed as packed_module
from loops.horizon.matching import shift_consensus
from loops.horizon.packed import compiled_kernels, extract_packed, match_packed, stack_packed
from loops.horizon.surf1d import HorizonFeatures
from tests.loops.test_horizon_bands import scene

if sys.version_info >= (3, 11):
    import tomllib
else:       # Python 3.10: the tomli backport, a core dependency there
    import tomli as tomllib

FAST = HorizonParams.preset("fast")
NO_NUMBA = "numba is not installed (pip install 'vslam[fast]'): no compiled path to compare"


@pytest.fixture(params=["numpy", "numba"])
def backend(request, monkeypatch):
    """A test on each path: the compiled kernels (skipped without numba), and the numpy fallback as it runs on a
    machine without numba (the kernels hidden, extract_packed / match_packed left on their default)."""
    if request.param == "numba":
        if compiled_kernels() is None:
            pytest.skip(NO_NUMBA)
    else:
        monkeypatch.setattr(packed_module, "_JIT", [None])
    return request.param


def same_features(packed, reference: list[HorizonFeatures]) -> None:
    assert packed.x.shape[0] == len(reference)
    for k, f in enumerate(reference):
        v = packed.valid[k]
        assert v.sum() == len(f)
        # Each reference feature has its own packed one: same column, same sign, descriptor within float32
        # rounding (two levels can share a column, so pair them by descriptor rather than by a sort order).
        x, keys = packed.x[k][v], packed.keys[k][v]
        free = np.ones(len(f), bool)
        for i in range(len(f)):
            cand = np.flatnonzero(free & (x == f.x[i]) & (np.sign(keys[:, -1]) == f.sign[i])
                                  & (np.abs(keys[:, :-1] - f.descriptor[i]).max(axis=1) <= 1e-6))
            assert cand.size, f"band {k}: no packed feature like the reference one at column {f.x[i]}"
            free[cand[0]] = False
        assert not packed.keys[k][~v].any()      # empty slots are all zero


def reference_scores(test_img, stored_imgs, row, p):
    t = extract_bands(test_img, row, p)
    out = [match_bands(t, extract_bands(s, row, p), p) for s in stored_imgs]
    return np.array([m.score for m in out]), np.array([m.score_ransac for m in out])


def test_the_cap_keeps_the_strongest_features_of_each_band():
    img = scene(3)
    full = extract_bands(img, 60.0, FAST.replace(max_features=0))
    capped = extract_bands(img, 60.0, FAST)
    for f, c in zip(full, capped):
        assert len(f) > FAST.max_features            # the scene has more: the cap acts
        assert len(c) == FAST.max_features
        strongest = np.sort(np.argsort(-np.abs(f.response), kind="stable")[:FAST.max_features])
        np.testing.assert_array_equal(c.x, f.x[strongest])


@pytest.mark.parametrize("row", [60.0, 30.0, 100.0])   # centred, and bands pushed inside the image at either edge
def test_packed_extraction_gives_the_reference_features(row, backend):
    for seed in range(3):
        img = scene(seed)
        same_features(extract_packed(img, row, FAST), extract_bands(img, row, FAST))


@pytest.mark.parametrize("over", [{}, {"step": 1}, {"bands": 1, "threshold": 0.0}, {"max_features": 400},
                                  {"sample_mode": "box", "step": 4, "band_height": 30}])
def test_lone_preset_and_other_settings_give_the_reference_features(over, backend):
    # lone: three 16-row bands every 4 columns; max_features 400 exceeds the candidates of a 160-px frame (the
    # slots past them stay empty); box sampling over 4 x 30 pixels no longer fits the 16-bit accumulator.
    p = HorizonParams.preset("lone").replace(**over)
    for seed in range(3):
        img = scene(seed)
        same_features(extract_packed(img, 60.0, p), extract_bands(img, 60.0, p))


@pytest.mark.parametrize("preset", ["fast", "lone", "lone_compiled"])
def test_wide_frames_with_empty_slots_give_the_reference_features(preset, backend):
    # 1200 px: the gather path (not the dense product of short signals); 300 slots per band, more than the scene's
    # features, so empty slots must come out all zero there too.
    p = HorizonParams.preset(preset).replace(max_features=300)
    for seed in range(2):
        img = scene(seed, width=1200)
        packed = extract_packed(img, 60.0, p)
        assert (~packed.valid).any()
        same_features(packed, extract_bands(img, 60.0, p))


def test_a_float_image_gives_the_reference_features(backend):
    img = scene(6).astype(np.float32) / 255.0 * 100.0     # not integers: the float64 path
    p = FAST.replace(threshold=0.1)
    same_features(extract_packed(img, 60.0, p), extract_bands(img, 60.0, p))


def test_overlapping_bands_of_a_low_image_give_the_reference_features(backend):
    img = scene(2)[:40]                            # seven 12-row bands overlap inside 40 rows
    same_features(extract_packed(img, 20.0, FAST), extract_bands(img, 20.0, FAST))


def test_packed_box_sampling_and_colour_input_give_the_reference_features(backend):
    p = FAST.replace(sample_mode="box", step=3)
    img = cv2.cvtColor(scene(4), cv2.COLOR_GRAY2BGR)
    same_features(extract_packed(img, 60.0, p), extract_bands(img, 60.0, p))


def test_packed_matching_gives_the_reference_scores_for_one_view_a_subset_and_all(backend):
    stored_imgs = [scene(s, shift=4.0) for s in range(5)] + [scene(s + 50) for s in range(3)]
    test_img = scene(2)
    ref_nn, ref_cons = reference_scores(test_img, stored_imgs, 60.0, FAST)
    db = stack_packed([extract_packed(s, 60.0, FAST) for s in stored_imgs])
    t = extract_packed(test_img, 60.0, FAST)
    every = match_packed(t, db, FAST)
    np.testing.assert_allclose(every.score, ref_nn, rtol=1e-5)
    np.testing.assert_allclose(every.score_ransac, ref_cons, rtol=1e-5)
    which = np.array([6, 2, 2])
    sub = match_packed(t, db, FAST, which)
    np.testing.assert_allclose(sub.score_ransac, ref_cons[which], rtol=1e-5)
    # The same place (shifted 4 px) scores above every other place.
    assert ref_cons[2] > np.delete(ref_cons, 2).max()


def test_packed_matching_with_the_geometric_check_off_and_one_view_of_few_features(backend):
    flat = np.full((120, 160), 128, np.uint8)            # no features at all: every slot empty
    stored_imgs = [scene(1), flat]
    p = FAST.replace(ransac_min_inliers=5, ratio=0.8)
    ref_nn, ref_cons = reference_scores(scene(1, shift=3.0), stored_imgs, 60.0, p)
    db = stack_packed([extract_packed(s, 60.0, p) for s in stored_imgs])
    got = match_packed(extract_packed(scene(1, shift=3.0), 60.0, p), db, p)
    np.testing.assert_allclose(got.score, ref_nn, rtol=1e-5)
    np.testing.assert_allclose(got.score_ransac, ref_cons, rtol=1e-5)
    assert got.score[1] == 0 and got.score_ransac[1] == 0
    assert got.score_ransac[0] > 0


def test_real_frames_give_the_reference_features_and_scores(shared_data, backend):
    c = shared_data / "places" / "corridor"
    names = ["ref/0000010.jpg", "ref/0000050.jpg", "query/0000010.jpg", "query/0000011.jpg", "query/0000090.jpg"]
    imgs = [cv2.imread(str(c / n), cv2.IMREAD_GRAYSCALE) for n in names]
    if any(i is None for i in imgs):
        pytest.skip("corridor frames not readable")
    kitti = cv2.imread(str(shared_data / "pairs" / "images" / "kitti06-12.png"), cv2.IMREAD_GRAYSCALE)
    if kitti is not None:
        same_features(extract_packed(kitti, 183.0, FAST), extract_bands(kitti, 183.0, FAST))
    packed = [extract_packed(i, 60.0, FAST) for i in imgs]
    for pk, img in zip(packed, imgs):
        same_features(pk, extract_bands(img, 60.0, FAST))
    ref_nn, ref_cons = reference_scores(imgs[0], imgs[2:], 60.0, FAST)
    got = match_packed(packed[0], stack_packed(packed[2:]), FAST)
    np.testing.assert_allclose(got.score, ref_nn, rtol=1e-5)
    np.testing.assert_allclose(got.score_ransac, ref_cons, rtol=1e-5)
    lone = HorizonParams.preset("lone")
    for img in imgs:
        same_features(extract_packed(img, 60.0, lone), extract_bands(img, 60.0, lone))
    lone_nn, lone_cons = reference_scores(imgs[2], imgs[:2] + imgs[3:], 60.0, lone)
    sub = match_packed(extract_packed(imgs[2], 60.0, lone),
                       stack_packed([extract_packed(i, 60.0, lone) for i in imgs[:2] + imgs[3:]]), lone, [2, 0])
    np.testing.assert_allclose(sub.score, lone_nn[[2, 0]], rtol=1e-5)
    np.testing.assert_allclose(sub.score_ransac, lone_cons[[2, 0]], rtol=1e-5)
    # Reference place 10 is query place 10 or 11 (the traverses are aligned), not query place 90.
    assert min(got.score_ransac[:2]) > got.score_ransac[2]


def test_shift_consensus_takes_the_heaviest_window_with_enough_matches():
    p = HorizonParams(ransac_tolerance=8.0, ransac_min_inliers=2)
    shift = np.array([0.0, 3.0, 7.0, 40.0, 41.0, -60.0])
    w = np.array([1.0, 1.0, 1.0, 5.0, 5.0, 50.0])
    score, b_d, inl = shift_consensus(shift, w, p)
    assert score == 10.0                              # 40 and 41; the single -60 has too few matches
    np.testing.assert_array_equal(inl, [False, False, False, True, True, False])
    assert b_d == 40.5
    assert shift_consensus(shift[:2], w[:2], p.replace(ransac_min_inliers=3))[0] == 0.0


def test_shift_consensus_in_match_reports_the_turn():
    p = FAST.replace(bands=1)
    a, b = scene(5), scene(5, shift=10.0)
    r = match(extract_bands(b, 60.0, p)[0], extract_bands(a, 60.0, p)[0], p)
    assert r.b_s == 1.0
    assert r.b_d == pytest.approx(10.0, abs=p.ransac_tolerance)
    assert r.n_inliers >= p.ransac_min_inliers


def test_bad_input_raises_horizon_errors(backend):
    img = scene(0)
    with pytest.raises(HorizonError, match="max_features"):
        extract_packed(img, 60.0, FAST.replace(max_features=0))
    with pytest.raises(HorizonError, match="too short"):
        extract_packed(img[:, :20], 60.0, FAST)
    with pytest.raises(HorizonError, match="rows"):
        extract_packed(img[:8], 4.0, FAST)         # not even one 12-row band fits
    with pytest.raises(HorizonError, match="cannot be stacked"):
        stack_packed([extract_packed(img, 60.0, FAST), extract_packed(img, 60.0, FAST.replace(max_features=8))])
    with pytest.raises(HorizonError, match="no views"):
        stack_packed([])
    db = stack_packed([extract_packed(img, 60.0, FAST)])
    with pytest.raises(HorizonError, match="shift"):
        match_packed(extract_packed(img, 60.0, FAST), db, FAST.replace(consensus="ransac"))
    with pytest.raises(HorizonError, match="different bands"):
        match_packed(extract_packed(img, 60.0, FAST.replace(max_features=8)), db, FAST)
    assert match_packed(extract_packed(img, 60.0, FAST), db, FAST, which=np.zeros(0, int)).score.shape == (0,)
    if backend == "numba":       # the kernel checks its indices (it has no bounds checks of its own)
        with pytest.raises(HorizonError, match="outside the 1 stored views"):
            match_packed(extract_packed(img, 60.0, FAST), db, FAST, which=np.array([0, 1]))


def _real_or_scenes(shared_data) -> list[np.ndarray]:
    names = ["ref/0000010.jpg", "ref/0000050.jpg", "query/0000010.jpg", "query/0000011.jpg", "query/0000090.jpg",
             "ref/0000120.jpg", "query/0000121.jpg"]
    imgs = [cv2.imread(str(shared_data / "places" / "corridor" / n), cv2.IMREAD_GRAYSCALE) for n in names]
    return [i for i in imgs if i is not None]


@pytest.mark.parametrize("preset", ["fast", "lone", "lone_compiled"])
def test_the_compiled_and_the_numpy_path_give_the_same_features_and_scores(shared_data, preset):
    if compiled_kernels() is None:
        pytest.skip(NO_NUMBA)
    p = HorizonParams.preset(preset)
    imgs = _real_or_scenes(shared_data) + [scene(s) for s in range(4)] + [scene(1, shift=5.0)]
    if len(imgs) < 10:
        pytest.skip("corridor frames not readable")
    views = {}
    for compiled in (True, False):
        views[compiled] = [extract_packed(i, 60.0, p, compiled=compiled) for i in imgs]
    for a, b in zip(views[True], views[False]):
        np.testing.assert_array_equal(a.x, b.x)            # the same features in the same slots
        np.testing.assert_array_equal(a.valid, b.valid)
        np.testing.assert_allclose(a.keys, b.keys, rtol=0, atol=1e-6)
        assert a.width == b.width
    db = stack_packed(views[False])
    which = np.array([3, 0, 5, -1, 2])
    for t in views[False]:
        got = match_packed(t, db, p, which, compiled=True)
        want = match_packed(t, db, p, which, compiled=False)
        assert got.score.dtype == want.score.dtype and got.score_ransac.dtype == want.score_ransac.dtype
        np.testing.assert_allclose(got.score, want.score, rtol=1e-5)
        np.testing.assert_allclose(got.score_ransac, want.score_ransac, rtol=1e-5)
        every = match_packed(t, db, p, compiled=True)
        np.testing.assert_allclose(every.score_ransac, match_packed(t, db, p, compiled=False).score_ransac, rtol=1e-5)
    assert (got.score_ransac > 0).any()                      # the scores compared are not all zero


def test_without_numba_the_numpy_path_runs_and_asking_for_the_compiled_one_is_an_error(monkeypatch):
    monkeypatch.setattr(packed_module, "_JIT", [None])       # as on a machine without numba
    img = scene(0)
    f = extract_packed(img, 60.0, FAST)
    assert f.valid.any()
    with pytest.raises(HorizonError, match="numba"):
        extract_packed(img, 60.0, FAST, compiled=True)
    with pytest.raises(HorizonError, match="numba"):
        match_packed(f, stack_packed([f, f]), FAST, compiled=True)
    assert match_packed(f, stack_packed([f, f]), FAST).score_ransac[0] > 0


def test_the_test_extra_installs_numba_so_ci_compares_both_paths():
    # CI (.ci/run) installs ".[test]" and runs the README's command: numba must be in that extra, or the comparison
    # tests above would skip there too.
    extras = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    for extra in ("test", "fast", "bench"):
        assert any(r.split(">")[0].split("=")[0].strip() == "numba" for r in extras[extra]), extra


def test_vslam_numba_0_turns_the_compiled_path_off(monkeypatch):
    monkeypatch.setattr(packed_module, "_JIT", [])           # not loaded yet in this "process"
    monkeypatch.setenv("VSLAM_NUMBA", "0")
    assert compiled_kernels() is None
    with pytest.raises(HorizonError, match="VSLAM_NUMBA"):
        extract_packed(scene(0), 60.0, FAST, compiled=True)


def test_a_numba_that_cannot_load_falls_back_to_numpy_with_a_warning(monkeypatch):
    # e.g. numba present but broken, or no writable cache directory for cache=True (numba raises RuntimeError)
    def broken(name):
        raise RuntimeError("cannot cache function 'extract_kernel': no locator available")

    monkeypatch.setattr(packed_module, "_JIT", [])
    monkeypatch.delenv("VSLAM_NUMBA", raising=False)
    monkeypatch.setattr(packed_module.importlib.util, "find_spec", lambda name: object())
    monkeypatch.setattr(packed_module.importlib, "import_module", broken)
    with pytest.warns(RuntimeWarning, match="numpy code runs instead"):
        f = extract_packed(scene(0), 60.0, FAST)
    assert f.valid.any() and compiled_kernels() is None
