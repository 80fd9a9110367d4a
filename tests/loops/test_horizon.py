"""1D SURF horizon landmarks: signal extraction, detector/descriptor, matching, RANSAC line, errors."""
from __future__ import annotations

import numpy as np
import pytest

from loops.horizon import (
    HorizonError,
    HorizonLine,
    HorizonParams,
    SampleMode,
    detect_and_describe,
    extract_features,
    fit_line_ransac,
    horizon_signal,
    lobe_sizes,
    match,
    nn_matches,
    sample_columns,
)


def texture(x: np.ndarray, seed: int) -> np.ndarray:
    """A deterministic 1D 'skyline': grey levels in [40, 200] from Gaussian bumps of many widths."""
    rng = np.random.default_rng(seed)
    f = np.zeros_like(x, dtype=np.float64)
    for _ in range(90):
        c, w, a = rng.uniform(-200, 1100), rng.uniform(2, 40), rng.uniform(-1, 1)
        f += a * np.exp(-0.5 * ((x - c) / w) ** 2)
    f = (f - f.min()) / (f.max() - f.min())
    return 40 + 160 * f


def horizon_image(f_of_x, width: int = 640, height: int = 120, row: int = 60, band: int = 40) -> np.ndarray:
    """Grey image whose rows around `row` hold f(x) (the horizon band); the rest is a flat grey."""
    img = np.full((height, width), 90.0)
    img[row - band // 2:row + band // 2, :] = f_of_x(np.arange(width, dtype=np.float64))[None, :]
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def shifted_scaled_pair(b_s: float, b_d: float, seed: int = 3):
    """Stored image shows f(x); the test image shows the same landscape with x_test = b_s * x_stored + b_d."""
    stored = horizon_image(lambda x: texture(x, seed))
    test = horizon_image(lambda x: texture((x - b_d) / b_s, seed))
    return stored, test


# --- signal ---------------------------------------------------------------------------------------------------

def test_signal_is_band_sum_every_step_columns():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (100, 640), dtype=np.uint8)
    p = HorizonParams()
    sig = horizon_signal(img, 50, p)
    assert sig.shape == (160,)
    expected = img[35:65, ::4].astype(np.int64).sum(axis=0)
    np.testing.assert_array_equal(sig, expected)
    assert sample_columns(160, p)[:3].tolist() == [0, 4, 8]


def test_box_sampling_sums_each_step_block():
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, (100, 643), dtype=np.uint8)   # a width that is not a multiple of the step
    p = HorizonParams(sample_mode=SampleMode.BOX, band_height=10)
    sig = horizon_signal(img, 50, p)
    expected = img[45:55, :640].astype(np.int64).reshape(10, 160, 4).sum(axis=(0, 2))
    np.testing.assert_array_equal(sig, expected)
    assert sample_columns(160, p)[0] == pytest.approx(1.5)


def test_tilted_horizon_line_follows_the_line():
    # Texture along a line through (0, 40) and (639, 80); a level horizon at either row would miss it.
    f = texture(np.arange(640.0), 9)
    img = np.full((130, 640), 90, np.uint8)
    line = HorizonLine(40.0, 80.0)
    rows = np.floor(line.row_at(np.arange(640), 640) + 0.5).astype(int)
    for x in range(640):
        img[rows[x] - 15:rows[x] + 15, x] = np.rint(f[x])
    sig = horizon_signal(img, line)
    np.testing.assert_array_equal(sig, 30 * np.rint(f[::4]))
    assert not np.allclose(horizon_signal(img, 60.0), sig)
    assert horizon_signal(img, HorizonLine.level(60.0)).tolist() == horizon_signal(img, 60).tolist()


def test_colour_image_is_converted_to_grey():
    rng = np.random.default_rng(2)
    grey = rng.integers(0, 256, (80, 320), dtype=np.uint8)
    colour = np.repeat(grey[:, :, None], 3, axis=2)
    np.testing.assert_array_equal(horizon_signal(colour, 40), horizon_signal(grey, 40))


@pytest.mark.parametrize("row", [-5, 10, 110, 130, float("nan")])
def test_horizon_outside_the_image_is_a_clear_error(row):
    img = np.zeros((120, 640), np.uint8)
    with pytest.raises(HorizonError, match="horizon row") as exc:
        horizon_signal(img, row)
    assert isinstance(exc.value, ValueError)
    if np.isfinite(row):
        assert "rows 0..119" in str(exc.value)


def test_tilted_line_leaving_the_image_is_a_clear_error():
    img = np.zeros((120, 640), np.uint8)
    with pytest.raises(HorizonError, match="horizon line from row 20 .* to 110"):
        horizon_signal(img, HorizonLine(20.0, 110.0))


def test_too_short_signal_is_a_clear_error():
    img = np.zeros((60, 40), np.uint8)  # 10 samples; the smallest filter alone spans 9
    with pytest.raises(HorizonError, match="too short: 10 samples"):
        extract_features(img, 30)
    with pytest.raises(HorizonError, match="one-dimensional"):
        detect_and_describe(np.zeros((5, 5)))


# --- detector and descriptor ----------------------------------------------------------------------------------

def test_descriptor_is_six_dimensional_and_unit_length():
    img = horizon_image(lambda x: texture(x, 4))
    f = extract_features(img, 60)
    assert len(f) > 20
    assert f.descriptor.shape == (len(f), 6) and f.descriptor.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(f.descriptor, axis=1), 1.0, atol=1e-5)
    # Layout: (sum dx, sum |dx|) per subregion, so every odd entry is non-negative and >= |its even neighbour|.
    d = f.descriptor.astype(np.float64)
    assert np.all(d[:, 1::2] >= -1e-7)
    assert np.all(d[:, 1::2] + 1e-6 >= np.abs(d[:, 0::2]))
    four = extract_features(img, 60, HorizonParams(subregions=4))
    assert four.descriptor.shape[1] == 8
    np.testing.assert_allclose(np.linalg.norm(four.descriptor, axis=1), 1.0, atol=1e-5)


def test_features_are_extrema_above_threshold_with_signs():
    img = horizon_image(lambda x: texture(x, 5))
    f = extract_features(img, 60)
    assert np.all(np.abs(f.response) > HorizonParams().threshold)
    assert set(np.unique(f.sign)) <= {-1, 1}
    assert np.all(np.sign(f.response) == f.sign)
    assert np.all((f.x >= 0) & (f.x < 640))
    # Every scale level of the deduplicated ladder is distinct.
    lobes = lobe_sizes(HorizonParams())
    assert lobes.tolist() == [3, 5, 7, 9, 13, 17, 25, 33, 49]
    higher = extract_features(img, 60, HorizonParams(threshold=20.0))
    assert 0 < len(higher) < len(f)


def test_a_bright_blob_is_found_at_its_position_and_scale():
    # One bright Gaussian bump of sigma 24 px (6 samples) at x = 320: the strongest feature sits there.
    img = horizon_image(lambda x: 60 + 120 * np.exp(-0.5 * ((x - 320) / 24.0) ** 2))
    f = extract_features(img, 60)
    k = int(np.argmax(np.abs(f.response)))
    assert f.sign[k] == -1                      # bright blob: negative second derivative
    assert abs(f.x[k] - 320) <= 8
    assert 8 <= f.scale[k] <= 48                # the blob's scale in pixels, within the ladder's resolution


def test_features_survive_a_brightness_change():
    base = horizon_image(lambda x: texture(x, 6))
    p = HorizonParams()
    f0 = extract_features(base, 60, p)
    brighter = np.clip(base.astype(np.int16) + 40, 0, 255).astype(np.uint8)   # no clipping: max 200 + 40
    f1 = extract_features(brighter, 60, p)
    np.testing.assert_array_equal(f0.x, f1.x)
    np.testing.assert_array_equal(f0.level, f1.level)
    np.testing.assert_allclose(f0.descriptor, f1.descriptor, atol=1e-5)
    # A 30% contrast gain changes responses, not descriptors: the features near the threshold aside, all match.
    gain = np.clip(np.rint(base * 1.3), 0, 255).astype(np.uint8)
    f2 = extract_features(gain, 60, p)
    common = set(zip(f0.x.tolist(), f0.level.tolist())) & set(zip(f2.x.tolist(), f2.level.tolist()))
    assert len(common) >= 0.9 * len(f0)
    r = match(f2, f0, p)
    assert r.n_inliers >= 0.6 * len(f0)
    assert r.b_s == pytest.approx(1.0, abs=0.01) and r.b_d == pytest.approx(0.0, abs=2.0)


# --- matching -------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("b_s,b_d,tol_d", [(1.0, 64.0, 2.0), (1.0, -101.0, 2.0), (1.15, -30.0, 6.0), (0.87, 70.0, 6.0)])
def test_shifted_scaled_signal_yields_known_bs_bd(b_s, b_d, tol_d):
    stored_img, test_img = shifted_scaled_pair(b_s, b_d)
    p = HorizonParams()
    stored, test = extract_features(stored_img, 60, p), extract_features(test_img, 60, p)
    r = match(test, stored, p)
    assert r.n_inliers >= 15
    assert r.b_s == pytest.approx(b_s, abs=0.02)
    # Positions are whole samples (4 px, no interpolation); with a scale change, 1% of scale error moves the
    # fitted intercept by a few pixels.
    assert r.b_d == pytest.approx(b_d, abs=tol_d)
    xt = test.x[r.matches[r.inliers, 0]]
    xs = stored.x[r.matches[r.inliers, 1]]
    assert np.median(np.abs(xt - (b_s * xs + b_d))) <= 4.0     # inliers really are true correspondences
    assert r.score_ransac <= r.score


def test_different_landscapes_score_lower_than_the_same_one():
    p = HorizonParams()
    a = extract_features(horizon_image(lambda x: texture(x, 10)), 60, p)
    same = extract_features(horizon_image(lambda x: texture((x - 40) / 1.05, 10)), 60, p)
    others = [extract_features(horizon_image(lambda x, s=s: texture(x, s)), 60, p) for s in range(11, 16)]
    good = match(same, a, p).score_ransac
    bad = [match(o, a, p).score_ransac for o in others]
    assert good > 2 * max(bad)


def test_matching_is_deterministic_and_seeded():
    stored_img, test_img = shifted_scaled_pair(1.05, 20.0, seed=7)
    p = HorizonParams(ransac_iterations=10)  # fewer hypotheses than pairs: the random draw is used
    s, t = extract_features(stored_img, 60, p), extract_features(test_img, 60, p)
    r1, r2 = match(t, s, p), match(t, s, p)
    assert (r1.score_ransac, r1.b_s, r1.b_d) == (r2.score_ransac, r2.b_s, r2.b_d)
    np.testing.assert_array_equal(r1.inliers, r2.inliers)


def test_nn_matches_respect_ratio_and_sign():
    img = horizon_image(lambda x: texture(x, 8))
    f = extract_features(img, 60)
    pairs, dist = nn_matches(f, f)
    # Matching a horizon to itself: every accepted match is the feature itself, at distance ~0.
    assert len(pairs) > 0.5 * len(f)
    assert np.all(pairs[:, 0] == pairs[:, 1])
    assert np.all(dist < 1e-3)
    strict, _ = nn_matches(f, f, HorizonParams(ratio=1e-9))
    assert len(strict) <= len(pairs)
    assert np.all(f.sign[pairs[:, 0]] == f.sign[pairs[:, 1]])


def test_one_to_one_keeps_one_match_per_stored_feature():
    stored_img, test_img = shifted_scaled_pair(1.1, 10.0, seed=12)
    p = HorizonParams(one_to_one=True)
    s, t = extract_features(stored_img, 60, p), extract_features(test_img, 60, p)
    pairs, _ = nn_matches(t, s, p)
    assert len(np.unique(pairs[:, 1])) == len(pairs)


def test_ransac_finds_the_line_among_outliers_and_rejects_reversal():
    rng = np.random.default_rng(0)
    xs = rng.uniform(0, 640, 60)
    xt = 1.2 * xs - 50 + rng.normal(0, 1.0, 60)
    xt[40:] = rng.uniform(0, 640, 20)           # a third outliers
    b_s, b_d, inl = fit_line_ransac(xt, xs)
    assert b_s == pytest.approx(1.2, abs=0.01) and b_d == pytest.approx(-50, abs=3)
    assert inl[:40].mean() > 0.95 and inl[40:].mean() < 0.3
    # A mirrored horizon (b_s < 0) is not a landmark seen again: no consensus.
    b_s, b_d, inl = fit_line_ransac(-xs + 600, xs)
    assert np.isnan(b_s) and not inl.any()
    # Scale consistency: with the wrong feature-scale ratio the same points are rejected.
    p = HorizonParams(scale_tolerance=0.5)
    ok = fit_line_ransac(xt[:40], xs[:40], p, np.full(40, np.log2(1.2)))
    bad = fit_line_ransac(xt[:40], xs[:40], p, np.full(40, 2.0))
    assert ok[2].sum() >= 38 and np.isnan(bad[0])


def test_empty_and_tiny_feature_sets_do_not_crash():
    p = HorizonParams()
    flat = extract_features(np.full((100, 640), 128, np.uint8), 50, p)
    assert len(flat) == 0 and flat.descriptor.shape == (0, 6)
    some = extract_features(horizon_image(lambda x: texture(x, 1)), 60, p)
    for a, b in ((flat, some), (some, flat), (flat, flat)):
        r = match(a, b, p)
        assert r.score == 0.0 and r.score_ransac == 0.0 and np.isnan(r.b_s)


# --- parameters and ROC ---------------------------------------------------------------------------------------

def test_params_validate_and_round_trip():
    p = HorizonParams.preset("robust")
    assert HorizonParams.from_dict(p.to_dict()) == p
    assert HorizonParams.from_dict(HorizonParams(sample_mode="box").to_dict()).sample_mode is SampleMode.BOX
    for bad in ({"band_height": 0}, {"step": 2.5}, {"ratio": 1.5}, {"threshold": -1.0}, {"ransac_min_inliers": 1},
                {"max_scale_change": 0.5}, {"sample_mode": "median"}):
        with pytest.raises(ValueError):
            HorizonParams(**bad)
    with pytest.raises(ValueError, match="unknown HorizonParams field"):
        HorizonParams.from_dict({"band": 3})
    with pytest.raises(ValueError, match="unknown horizon preset"):
        HorizonParams.preset("quickest")
