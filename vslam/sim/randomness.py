"""Order-independent randomness for procedural worlds: every cell of the floor draws from a generator keyed by
(seed, purpose, coordinates), so a tile looks the same whichever order tiles are rendered in."""
from __future__ import annotations

import numpy as np

_OFFSET = 1 << 31  # keeps negative cell indices distinct in SeedSequence entropy (which must be non-negative)


def keyed_rng(seed: int, *key: int) -> np.random.Generator:
    return np.random.default_rng([int(seed) & 0xFFFFFFFF] + [int(k) + _OFFSET for k in key])


def lattice_values(seed: int, purpose: int, ix: np.ndarray, iy: np.ndarray) -> np.ndarray:
    """Uniform [0, 1) values at integer lattice points, vectorised (splitmix64-style hash)."""
    x = (np.asarray(ix, dtype=np.int64).astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
         ^ np.asarray(iy, dtype=np.int64).astype(np.uint64) * np.uint64(0xC2B2AE3D27D4EB4F)
         ^ np.uint64((int(seed) * 0x165667B19E3779F9 + purpose * 0x27D4EB2F165667C5) & 0xFFFFFFFFFFFFFFFF))
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    x = x ^ (x >> np.uint64(31))
    return (x >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def smooth_noise(seed: int, purpose: int, x0: float, y0: float, width: int, height: int, res: float,
                 spacing: float) -> np.ndarray:
    """Smooth value noise in [-1, 1] over a world-aligned pixel grid (top-left pixel centre at (x0, y0) + res/2),
    from lattice values `spacing` metres apart, bicubically interpolated (continuous across tiles)."""
    xs = x0 + (np.arange(width) + 0.5) * res
    ys = y0 + (np.arange(height) + 0.5) * res
    gx = xs / spacing
    gy = ys / spacing
    ix0 = int(np.floor(gx[0])) - 1
    iy0 = int(np.floor(gy[0])) - 1
    ix1 = int(np.floor(gx[-1])) + 3
    iy1 = int(np.floor(gy[-1])) + 3
    lx, ly = np.meshgrid(np.arange(ix0, ix1), np.arange(iy0, iy1))
    lat = lattice_values(seed, purpose, lx, ly) * 2.0 - 1.0
    # Catmull-Rom interpolation, separable
    def interp(v: np.ndarray, g: np.ndarray, i0: int, axis: int) -> np.ndarray:
        i = np.floor(g).astype(int)
        t = g - i
        idx = i - i0
        w = [(-t ** 3 + 2 * t ** 2 - t) / 2, (3 * t ** 3 - 5 * t ** 2 + 2) / 2,
             (-3 * t ** 3 + 4 * t ** 2 + t) / 2, (t ** 3 - t ** 2) / 2]
        out = 0
        for k in range(4):
            taken = np.take(v, idx - 1 + k, axis=axis)
            shape = [1, 1]
            shape[axis] = -1
            out = out + taken * w[k].reshape(shape)
        return out
    rows = interp(lat, gx, ix0, axis=1)
    return interp(rows, gy, iy0, axis=0).astype(np.float32)
