"""The periods of a floor view from its features matched against themselves (odometry.lattice)."""

import numpy as np

from odometry.lattice import view_lattice


def _tiled(period: np.ndarray, tiles: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    base = rng.uniform(0, 1, (60, 2)) * np.linalg.norm(period, axis=1).min()
    desc = rng.integers(0, 256, (60, 32), dtype=np.uint8)
    pts, ds = [], []
    for i in range(tiles):
        for j in range(tiles):
            pts.append(base + i * period[0] + j * period[1])
            ds.append(desc)
    return np.vstack(pts), np.vstack(ds)


def test_a_tiled_view_gives_its_two_periods():
    rng = np.random.default_rng(3)
    period = np.array([[0.25, 0.0], [0.03, 0.25]])
    floor, desc = _tiled(period, 2, rng)
    found = view_lattice(floor + rng.normal(0, 5e-4, floor.shape), desc, tol=0.004, min_step=0.01, min_count=10)
    assert len(found) == 2
    # the found generators span the tiling's lattice: integer combinations of its periods, unimodular
    k = found @ np.linalg.inv(period)
    assert np.abs(k - np.round(k)).max() < 0.05
    assert abs(round(np.linalg.det(np.round(k)))) == 1


def test_an_ordinary_view_has_no_period():
    rng = np.random.default_rng(4)
    floor = rng.uniform(0, 0.75, (500, 2))
    desc = rng.integers(0, 256, (500, 32), dtype=np.uint8)
    assert view_lattice(floor, desc, tol=0.004, min_step=0.01, min_count=10).shape == (0, 2)
