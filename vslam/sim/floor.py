"""Procedural floors built from real ground-texture photographs, generated lazily in world-aligned tiles.

Natural floors (carpet, concrete, asphalt, gravel, grass) blend two layers of randomly placed, rotated and
flipped crops of the photographs with overlapping cos^2 windows; the blend preserves the texture's variance
(so contrast does not fade where crops overlap) and the two layers have incommensurate cell sizes, so no
region of the floor repeats. Low-frequency albedo variation and sparse stains add more uniqueness.
Tiles are a grid of ceramic tiles with grout whose surfaces are random crops; wood is planks cut at random
from a wood photograph. Printed wood is the deliberate exception: laminate planks whose print is one of a
few fixed designs, repeated across the floor - seed 001's false-loop worst case.
"""
from __future__ import annotations

import enum
import math
from collections import OrderedDict
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from odometry.shared.config import Config, setting
from vslam.paths import PACKAGE_DATA
from vslam.sim.randomness import keyed_rng, lattice_values, smooth_noise

TEXTURE_DIR = PACKAGE_DATA / "textures"


class FloorType(str, enum.Enum):
    CARPET = "carpet"
    CONCRETE = "concrete"
    ASPHALT = "asphalt"
    GRAVEL = "gravel"
    GRASS = "grass"
    TILES = "tiles"
    WOOD = "wood"
    PRINTED_WOOD = "printed-wood"


NATURAL_FLOORS = (FloorType.CARPET, FloorType.CONCRETE, FloorType.ASPHALT, FloorType.TILES)


@dataclass(frozen=True)
class Source:
    file: str
    scale: float  # metres per texture pixel


@dataclass(frozen=True)
class Finish:
    """How a floor type departs from its photographs: contrast gain and fine surface grain (std, grey levels)."""

    contrast: float = 1.0
    grain: float = 0.0
    grain_sigma: float = 1.0  # pixels


# Texture photographs per floor and the physical size of one of their pixels.
FLOOR_SOURCES: dict[FloorType, tuple[Source, ...]] = {
    FloorType.CARPET: (Source("carpet.jpg", 0.0016),),
    FloorType.CONCRETE: (Source("concrete.jpg", 0.0007),),
    FloorType.ASPHALT: (Source("road.jpg", 0.0012), Source("gravel.jpg", 0.0005)),
    FloorType.GRAVEL: (Source("gravel.jpg", 0.0012),),
    FloorType.GRASS: (Source("grass.jpg", 0.0012), Source("grass_dirt.jpg", 0.0009)),
    FloorType.TILES: (Source("concrete.jpg", 0.0006),),
    FloorType.WOOD: (Source("wood_slats.jpg", 0.0010),),
    FloorType.PRINTED_WOOD: (Source("wood_planks.jpg", 0.0030),),
}

# Concrete and wood photographs are smooth game textures: a real floor under a close camera shows more micro-texture.
FLOOR_FINISH: dict[FloorType, Finish] = {
    FloorType.CONCRETE: Finish(contrast=3.0, grain=7.0, grain_sigma=1.3),
    FloorType.WOOD: Finish(contrast=1.3, grain=6.0, grain_sigma=1.5),
    FloorType.TILES: Finish(contrast=1.0, grain=4.0, grain_sigma=1.0),
    FloorType.CARPET: Finish(contrast=1.0, grain=5.0, grain_sigma=0.8),
    FloorType.ASPHALT: Finish(contrast=1.0, grain=9.0, grain_sigma=1.0),
}

# purposes for keyed randomness
_P_CELL, _P_MIX, _P_ALBEDO, _P_STAIN, _P_ROW, _P_PLANK, _P_TILE, _P_GRAIN = range(1, 9)


@lru_cache(maxsize=32)
def load_texture(file: str, gray: bool, texture_dir: str | None = None) -> np.ndarray:
    """A bundled texture as float32 (H, W) or (H, W, 3) in [0, 255]."""
    path = Path(texture_dir) / file if texture_dir else TEXTURE_DIR / file
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR)
    if img is None:
        raise FileNotFoundError(f"texture {path} is missing or unreadable")
    return img.astype(np.float32)


@lru_cache(maxsize=32)
def texture_mean(file: str, gray: bool) -> float:
    return float(load_texture(file, gray).mean())


@lru_cache(maxsize=32)
def _prefiltered(file: str, gray: bool, ratio: float) -> np.ndarray:
    """The texture blurred for sampling at `ratio` floor pixels per texture pixel > 1 (anti-aliasing)."""
    tex = load_texture(file, gray)
    if ratio <= 1.0:
        return tex
    sigma = 0.5 * math.sqrt(ratio * ratio - 1.0)
    return cv2.GaussianBlur(tex, (0, 0), sigma)


@dataclass(frozen=True)
class FloorParams(Config):
    """Shape of the procedural floor; defaults give a realistic, non-repeating floor."""

    cell_sizes: tuple[float, float] = setting((0.22, 0.31), range="(0, inf)", unit="m",
                                              doc="two incommensurate layers")
    albedo_amplitude: float = setting(0.10, range="[0, 1]", doc="+-10 % slow brightness variation")
    albedo_spacing: float = setting(0.6, range="(0, inf)", unit="m", doc="between albedo lattice points")
    stain_density: float = setting(6.0, range="[0, inf)", unit="1/m^2", doc="stains per square metre")
    stain_strength: float = setting(0.18, range="[0, 1]")
    tile_size: float = setting(0.30, range="(0, inf)", unit="m", doc="ceramic tiles")
    grout_width: float = setting(0.004, range="[0, inf)", unit="m")
    plank_width: float = setting(0.125, range="(0, inf)", unit="m", doc="printed and natural wood")
    plank_length: float = setting(1.24, range="(0, inf)", unit="m")
    printed_designs: int = setting(6, range="[1, inf)", doc="distinct laminate prints")
    plank_gap: float = setting(0.0015, range="[0, inf)", unit="m")


class Floor:
    """An infinite floor of one type, sampled at `resolution` metres per pixel in tiles of `tile_px` pixels.

    `region(x0, y0, w, h)` returns the floor image over a pixel-aligned world window; tiles are cached (LRU).
    """

    def __init__(self, floor: FloorType | str, seed: int = 0, resolution: float = 0.001, gray: bool = True,
                 params: FloorParams | None = None, tile_px: int = 512, cache_tiles: int = 96):
        self.type = FloorType(floor)
        self.seed = int(seed)
        self.res = float(resolution)
        self.gray = gray
        self.params = params or FloorParams()
        self.tile_px = tile_px
        self.tile_m = tile_px * self.res
        self.channels = 1 if gray else 3
        self._cache: OrderedDict[tuple[int, int], np.ndarray] = OrderedDict()
        self._cache_size = cache_tiles
        self.sources = FLOOR_SOURCES[self.type]
        self._designs: list[np.ndarray] | None = None

    # ------------------------------------------------------------------ public
    def tile(self, ix: int, iy: int) -> np.ndarray:
        key = (ix, iy)
        t = self._cache.get(key)
        if t is not None:
            self._cache.move_to_end(key)
            return t
        t = self._make_tile(ix, iy)
        t.setflags(write=False)
        self._cache[key] = t
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return t

    def region(self, col0: int, row0: int, width: int, height: int) -> np.ndarray:
        """Floor pixels [row0, row0+height) x [col0, col0+width) of the global pixel grid (pixel (c, r) covers
        world [c*res, (c+1)*res) x [r*res, (r+1)*res)), as float32."""
        T = self.tile_px
        out = np.empty((height, width) if self.gray else (height, width, 3), np.float32)
        for ty in range(row0 // T, (row0 + height - 1) // T + 1):
            for tx in range(col0 // T, (col0 + width - 1) // T + 1):
                tile = self.tile(tx, ty)
                r0, c0 = max(row0, ty * T), max(col0, tx * T)
                r1, c1 = min(row0 + height, (ty + 1) * T), min(col0 + width, (tx + 1) * T)
                out[r0 - row0:r1 - row0, c0 - col0:c1 - col0] = tile[r0 - ty * T:r1 - ty * T, c0 - tx * T:c1 - tx * T]
        return out

    # ------------------------------------------------------------------ tile synthesis
    def _make_tile(self, ix: int, iy: int) -> np.ndarray:
        x0, y0 = ix * self.tile_m, iy * self.tile_m
        n = self.tile_px
        if self.type == FloorType.PRINTED_WOOD:
            img = self._planks(x0, y0, printed=True)
        elif self.type == FloorType.WOOD:
            img = self._planks(x0, y0, printed=False)
        elif self.type == FloorType.TILES:
            img = self._ceramic(x0, y0)
        else:
            img = self._natural(x0, y0)
        finish = FLOOR_FINISH.get(self.type, Finish())
        if finish.contrast != 1.0:
            m = float(img.mean())
            img = m + (img - m) * finish.contrast
        if finish.grain > 0:
            g = keyed_rng(self.seed, _P_GRAIN, ix, iy).normal(0, 1, (n, n)).astype(np.float32)
            g = cv2.GaussianBlur(g, (0, 0), finish.grain_sigma)
            g *= finish.grain / max(float(g.std()), 1e-6)
            img = img + (g if self.gray else g[..., None])
        p = self.params
        albedo = 1.0 + p.albedo_amplitude * smooth_noise(self.seed, _P_ALBEDO, x0, y0, n, n, self.res, p.albedo_spacing)
        img = img * (albedo if self.gray else albedo[..., None])
        img = self._stains(img, x0, y0)
        return np.clip(img, 0, 255).astype(np.float32)

    def _grid(self, x0: float, y0: float) -> tuple[np.ndarray, np.ndarray]:
        n = self.tile_px
        c = x0 + (np.arange(n, dtype=np.float64) + 0.5) * self.res
        r = y0 + (np.arange(n, dtype=np.float64) + 0.5) * self.res
        return c, r

    def _warp_crop(self, src: Source, rng: np.random.Generator, centre: tuple[float, float], roi: tuple[int, int, int, int],
                   x0: float, y0: float, angle: float | None = None, scale_jitter: float = 0.08) -> np.ndarray:
        """Sample a random rotated/flipped crop of `src` onto the tile pixels roi = (c0, r0, c1, r1), with the crop's
        frame centred at world point `centre`."""
        ratio = self.res / src.scale
        tex = _prefiltered(src.file, self.gray, ratio)
        th, tw = tex.shape[:2]
        phi = rng.uniform(0, 2 * math.pi) if angle is None else angle
        flip = -1.0 if rng.random() < 0.5 else 1.0
        s = (1.0 + rng.uniform(-scale_jitter, scale_jitter)) / src.scale   # texture px per metre
        ox, oy = rng.uniform(0.25 * tw, 0.75 * tw), rng.uniform(0.25 * th, 0.75 * th)
        c, sn = math.cos(phi), math.sin(phi)
        # world -> texture: q = s * R(phi) * diag(flip, 1) * (p - centre) + o ; p = pixel centre of tile px
        c0, r0, c1, r1 = roi
        a = s * np.array([[c * flip, -sn], [sn * flip, c]])
        # p = (x0 + (col + .5) res, y0 + (row + .5) res) -> affine in (col, row)
        px0 = x0 + (c0 + 0.5) * self.res - centre[0]
        py0 = y0 + (r0 + 0.5) * self.res - centre[1]
        M = np.array([[a[0, 0] * self.res, a[0, 1] * self.res, a[0, 0] * px0 + a[0, 1] * py0 + ox],
                      [a[1, 0] * self.res, a[1, 1] * self.res, a[1, 0] * px0 + a[1, 1] * py0 + oy]])
        return cv2.warpAffine(tex, M, (c1 - c0, r1 - r0), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                              borderMode=cv2.BORDER_REFLECT_101)

    def _natural(self, x0: float, y0: float) -> np.ndarray:
        n = self.tile_px
        shape = (n, n) if self.gray else (n, n, 3)
        cx_, ry_ = self._grid(x0, y0)
        layers = []
        for li, C in enumerate(self.params.cell_sizes):
            acc = np.zeros(shape, np.float32)
            wsq = np.zeros((n, n), np.float32)
            for gy in range(math.floor(y0 / C), math.floor((y0 + self.tile_m) / C) + 2):
                wy = np.cos(np.pi * (ry_ - gy * C) / (2 * C)) ** 2
                wy[np.abs(ry_ - gy * C) >= C] = 0.0
                rows = np.nonzero(wy > 0)[0]
                if len(rows) == 0:
                    continue
                for gx in range(math.floor(x0 / C), math.floor((x0 + self.tile_m) / C) + 2):
                    wx = np.cos(np.pi * (cx_ - gx * C) / (2 * C)) ** 2
                    wx[np.abs(cx_ - gx * C) >= C] = 0.0
                    cols = np.nonzero(wx > 0)[0]
                    if len(cols) == 0:
                        continue
                    rng = keyed_rng(self.seed, _P_CELL, li, gx, gy)
                    src = self.sources[int(rng.integers(len(self.sources)))]
                    roi = (int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)
                    patch = self._warp_crop(src, rng, (gx * C, gy * C), roi, x0, y0)
                    mu = texture_mean(src.file, self.gray)
                    w = np.outer(wy[roi[1]:roi[3]], wx[roi[0]:roi[2]]).astype(np.float32)
                    sl = (slice(roi[1], roi[3]), slice(roi[0], roi[2]))
                    acc[sl] += (patch - mu) * (w if self.gray else w[..., None])
                    wsq[sl] += w * w
            norm = 1.0 / np.sqrt(np.maximum(wsq, 1e-6))
            layers.append(acc * (norm if self.gray else norm[..., None]))
        mu = float(np.mean([texture_mean(s.file, self.gray) for s in self.sources]))
        alpha = 0.5 + 0.3 * smooth_noise(self.seed, _P_MIX, x0, y0, n, n, self.res, 0.45)
        beta = 1.0 - alpha
        k = 1.0 / np.sqrt(alpha ** 2 + beta ** 2)
        if not self.gray:
            alpha, beta, k = alpha[..., None], beta[..., None], k[..., None]
        return mu + (alpha * layers[0] + beta * layers[1]) * k

    def _ceramic(self, x0: float, y0: float) -> np.ndarray:
        p = self.params
        n = self.tile_px
        cx_, ry_ = self._grid(x0, y0)
        out = np.empty((n, n) if self.gray else (n, n, 3), np.float32)
        G = p.tile_size
        for gy in range(math.floor(y0 / G), math.floor((y0 + self.tile_m) / G) + 1):
            rows = np.nonzero((ry_ >= gy * G) & (ry_ < (gy + 1) * G))[0]
            if len(rows) == 0:
                continue
            for gx in range(math.floor(x0 / G), math.floor((x0 + self.tile_m) / G) + 1):
                cols = np.nonzero((cx_ >= gx * G) & (cx_ < (gx + 1) * G))[0]
                if len(cols) == 0:
                    continue
                rng = keyed_rng(self.seed, _P_TILE, gx, gy)
                roi = (int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)
                angle = float(rng.integers(4)) * math.pi / 2
                patch = self._warp_crop(self.sources[0], rng, ((gx + 0.5) * G, (gy + 0.5) * G), roi, x0, y0,
                                        angle=angle, scale_jitter=0.0)
                gain = 1.0 + rng.uniform(-0.08, 0.08)
                # ceramic glaze: stretch the concrete photograph's contrast so the tile surface carries texture
                m = float(patch.mean())
                out[roi[1]:roi[3], roi[0]:roi[2]] = (m + (patch - m) * 2.2) * gain
        # grout lines
        dx = np.abs(((cx_ + G / 2) % G) - G / 2)
        dy = np.abs(((ry_ + G / 2) % G) - G / 2)
        grout = (dy[:, None] < p.grout_width / 2) | (dx[None, :] < p.grout_width / 2)
        out[grout] = 70.0
        return out

    def _plank_designs(self) -> list[np.ndarray]:
        """The printed-laminate designs: plank columns of the wood photograph, laid along world x, with a fixed
        printed grain. Identical wherever the design is laid - that is what makes printed floors repeat."""
        if self._designs is None:
            src = self.sources[0]
            tex = load_texture(src.file, self.gray)
            p = self.params
            k = p.printed_designs
            w = tex.shape[1] // k
            L = int(round(p.plank_length / self.res))
            W = int(round(p.plank_width / self.res))
            designs = []
            for d in range(k):
                col = tex[:, d * w:(d + 1) * w]
                col = np.ascontiguousarray(np.rot90(col))          # long axis along x
                img = cv2.resize(col, (L, W), interpolation=cv2.INTER_CUBIC)
                rng = keyed_rng(0, _P_PLANK, 999, d)               # print grain: fixed by the design, not the floor
                grain = rng.normal(0, 1, (W // 2 + 1, L // 8 + 1)).astype(np.float32)
                grain = cv2.resize(grain, (L, W), interpolation=cv2.INTER_CUBIC)
                fine = cv2.GaussianBlur(rng.normal(0, 1, (W, L)).astype(np.float32), (0, 0), 1.2)
                pattern = 9.0 * grain + 14.0 * fine
                img = img + (pattern if self.gray else pattern[..., None])
                designs.append(img.astype(np.float32))
            self._designs = designs
        return self._designs

    def _planks(self, x0: float, y0: float, printed: bool) -> np.ndarray:
        p = self.params
        n = self.tile_px
        res = self.res
        W = int(round(p.plank_width / res))
        L = int(round(p.plank_length / res))
        gap = max(1, int(round(p.plank_gap / res)))
        out = np.empty((n, n) if self.gray else (n, n, 3), np.float32)
        col0 = int(round(x0 / res))
        row0 = int(round(y0 / res))
        designs = self._plank_designs() if printed else None
        for j in range(row0 // W, (row0 + n - 1) // W + 1):
            r_a, r_b = max(row0, j * W), min(row0 + n, (j + 1) * W)
            offset = int(lattice_values(self.seed, _P_ROW, np.array([j]), np.array([0]))[0] * L)
            for k in range((col0 - offset) // L, (col0 + n - 1 - offset) // L + 1):
                p_c0 = k * L + offset
                c_a, c_b = max(col0, p_c0), min(col0 + n, p_c0 + L)
                if c_a >= c_b:
                    continue
                if printed:
                    d = int(lattice_values(self.seed, _P_PLANK, np.array([j]), np.array([k]))[0] * len(designs))
                    piece = designs[d][r_a - j * W:r_b - j * W, c_a - p_c0:c_b - p_c0]
                else:
                    rng = keyed_rng(self.seed, _P_PLANK, j, k)
                    centre = ((p_c0 + L / 2) * res, (j * W + W / 2) * res)
                    roi = (c_a - col0, r_a - row0, c_b - col0, r_b - row0)
                    piece = self._warp_crop(self.sources[0], rng, centre, roi, x0, y0,
                                            angle=float(rng.choice([0.0, math.pi])), scale_jitter=0.1)
                    piece = piece * (1.0 + rng.uniform(-0.1, 0.1))
                out[r_a - row0:r_b - row0, c_a - col0:c_b - col0] = piece
            # gaps: along the row boundary and at plank ends
            if j * W >= row0:
                out[j * W - row0:min(n, j * W - row0 + gap)] *= 0.45
            for k in range((col0 - offset) // L, (col0 + n - 1 - offset) // L + 2):
                e = k * L + offset - col0
                if 0 <= e < n:
                    out[r_a - row0:r_b - row0, e:min(n, e + gap)] *= 0.45
        return out

    def _stains(self, img: np.ndarray, x0: float, y0: float) -> np.ndarray:
        """Sparse soft stains, defined on a world lattice of 0.1 m cells (each may hold one)."""
        p = self.params
        if p.stain_density <= 0:
            return img
        cell = 0.1
        prob = min(1.0, p.stain_density * cell * cell)
        n = self.tile_px
        res = self.res
        reach = 0.06
        for gy in range(math.floor((y0 - reach) / cell), math.floor((y0 + self.tile_m + reach) / cell) + 1):
            for gx in range(math.floor((x0 - reach) / cell), math.floor((x0 + self.tile_m + reach) / cell) + 1):
                if lattice_values(self.seed, _P_STAIN, np.array([gx]), np.array([gy]))[0] >= prob:
                    continue
                rng = keyed_rng(self.seed, _P_STAIN, gx, gy)
                cxw, cyw = (gx + rng.random()) * cell, (gy + rng.random()) * cell
                rad = rng.uniform(0.004, 0.03)
                amp = rng.uniform(-1, 1) * p.stain_strength
                c0 = max(0, int((cxw - 3 * rad - x0) / res))
                c1 = min(n, int((cxw + 3 * rad - x0) / res) + 1)
                r0 = max(0, int((cyw - 3 * rad - y0) / res))
                r1 = min(n, int((cyw + 3 * rad - y0) / res) + 1)
                if c0 >= c1 or r0 >= r1:
                    continue
                xs = x0 + (np.arange(c0, c1) + 0.5) * res - cxw
                ys = y0 + (np.arange(r0, r1) + 0.5) * res - cyw
                g = np.exp(-(ys[:, None] ** 2 + xs[None, :] ** 2) / (2 * rad * rad)).astype(np.float32)
                f = 1.0 + amp * g
                img[r0:r1, c0:c1] *= f if self.gray else f[..., None]
        return img
