"""Several bands around the horizon (loops.horizon.bands)."""
from __future__ import annotations

import numpy as np

from loops.horizon import HorizonParams, band_rows, extract_bands, match, match_bands


def scene(seed: int, shift: float = 0.0, width: int = 160, height: int = 120) -> np.ndarray:
    """Each row band holds its own 1D texture (what a level camera sees at different heights), shifted by `shift`."""
    rng = np.random.default_rng(seed)
    x = np.arange(width, dtype=float) - shift
    img = np.zeros((height, width))
    for r0 in range(0, height, 12):
        f = np.zeros(width)
        for _ in range(12):
            c, w, a = rng.uniform(-20, width + 20), rng.uniform(2, 10), rng.uniform(-1, 1)
            f += a * np.exp(-0.5 * ((x - c) / w) ** 2)
        img[r0:r0 + 12] = 120 + 80 * f / (np.abs(f).max() + 1e-9)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def test_band_rows_are_centred_and_stay_inside_the_image():
    p = HorizonParams.preset("bands")
    rows = band_rows(60.0, 120, p)
    assert len(rows) == p.bands and np.isclose(np.mean(rows), 60.0)
    assert np.allclose(np.diff(rows), p.band_height)
    edge = band_rows(5.0, 120, p)
    assert min(edge) >= p.band_height / 2 and max(edge) <= 120 - p.band_height / 2


def test_one_band_is_the_papers_method():
    p = HorizonParams.preset("paper").replace(step=1)
    a, b = scene(1), scene(1, shift=6.0)
    one = match_bands(extract_bands(b, 60.0, p), extract_bands(a, 60.0, p), p)
    assert np.isclose(one.score_ransac, match(*(extract_bands(b, 60.0, p) + extract_bands(a, 60.0, p)), p)
                      .score_ransac)


def test_bands_separate_the_same_place_from_another_better_than_the_middle_band_alone():
    multi = HorizonParams.preset("bands")
    single = multi.replace(bands=1)
    same = [(scene(s), scene(s, shift=5.0)) for s in range(6)]
    other = [(scene(s), scene(s + 100, shift=5.0)) for s in range(6)]

    def margin(p):
        sc = lambda a, b: match_bands(extract_bands(b, 60.0, p), extract_bands(a, 60.0, p), p).score_ransac
        return min(sc(a, b) for a, b in same) - max(sc(a, b) for a, b in other)

    assert margin(multi) > 0
    assert margin(multi) > margin(single)
