"""Local descriptors that feed the vocabularies: BRIEF / rotated BRIEF, ORB, SIFT (standing in for SURF), and
hue-saturation histograms of colour patches (random, whole-image grid, upper-half grid)."""
from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from loops.errors import LoopsError

from .brief import brief_describe, brief_pattern, inside, pattern_radius, rotated_offsets, smooth_for_brief
from .params import DescriptorName, VocabParams


class NoFeaturesError(LoopsError):
    """An image gave no descriptor at all (blank, too small, or fully masked)."""


class GrayscaleImageError(LoopsError):
    """A colour vocabulary was given a grayscale image."""


def is_grayscale(image: np.ndarray) -> bool:
    """True for single-channel images and for 3-channel images whose channels are equal (grey saved as RGB)."""
    if image.ndim == 2 or image.shape[2] == 1:
        return True
    sub = image[::4, ::4]
    return bool(np.array_equal(sub[..., 0], sub[..., 1]) and np.array_equal(sub[..., 1], sub[..., 2]))


def prepare(image: np.ndarray, params: VocabParams, mask: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """Upscale images whose shorter side is below params.min_image_side (the mask follows). Colour descriptors are
    left alone: their patches are defined relative to the image size, so upscaling would only cost time."""
    if image is None or image.size == 0:
        raise LoopsError("empty image")
    if image.dtype != np.uint8:
        raise LoopsError(f"images must be 8-bit, got {image.dtype}")
    side = min(image.shape[:2])
    if params.min_image_side and side < params.min_image_side and not params.descriptor.is_color:
        f = params.min_image_side / side
        size = (int(round(image.shape[1] * f)), int(round(image.shape[0] * f)))
        image = cv2.resize(image, size, interpolation=cv2.INTER_LINEAR)
        if mask is not None:
            mask = cv2.resize(mask, size, interpolation=cv2.INTER_NEAREST)
    return image, mask


def _gray(image: np.ndarray) -> np.ndarray:
    if image.ndim == 2:
        return image
    if image.shape[2] == 1:
        return image[..., 0]
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


@lru_cache(maxsize=8)
def _pattern(patch: int, seed: int) -> np.ndarray:
    p = brief_pattern(patch, seed)
    p.setflags(write=False)
    return p


def brief_angles(params: VocabParams) -> tuple[float, ...]:
    """Pattern angles of the vocabularies: (0,) for BRIEF, (0, +theta, -theta) for BRIEFROT."""
    if params.descriptor is DescriptorName.BRIEFROT:
        return (0.0, params.rot_theta_deg, -params.rot_theta_deg)
    return (0.0,)


def extraction_key(params: VocabParams) -> tuple:
    """The parameters that decide what extract() returns for an image (per pattern angle): equal keys give equal
    descriptors, so callers can cache them. BRIEF and BRIEFROT share their plain-pattern descriptors."""
    d = params.descriptor
    if d in (DescriptorName.BRIEF, DescriptorName.BRIEFROT):
        return ("brief", params.n_features, params.min_image_side, params.brief_patch, params.brief_sigma,
                params.brief_pattern_seed)
    if d in (DescriptorName.ORB, DescriptorName.SURF):
        return (d.value, params.n_features, params.min_image_side)
    seed = params.seed if d is DescriptorName.COLOR_RANDOM else None   # random patches are drawn from the seed
    return (d.value, params.color_random_patches, params.color_grid, params.color_patch_fraction, params.hs_bins,
            seed)


def extract(image: np.ndarray, params: VocabParams, mask: np.ndarray | None = None,
            angles: tuple[float, ...] = (0.0,), name: str = "image") -> list[np.ndarray]:
    """Descriptors of one image (BGR or grey uint8), one array per pattern angle (angles other than 0 only for
    BRIEF/BRIEFROT). `mask` (uint8, non-zero = usable) restricts keypoints / patch centres to part of the image.
    Raises NoFeaturesError when nothing is found, GrayscaleImageError for colour descriptors on a grey image."""
    return extract_with_keypoints(image, params, mask, angles, name)[1]


def extract_with_keypoints(image: np.ndarray, params: VocabParams, mask: np.ndarray | None = None,
                           angles: tuple[float, ...] = (0.0,), name: str = "image"
                           ) -> tuple[np.ndarray, list[np.ndarray]]:
    """Like extract(), with the (N, 2) float32 pixel positions of the described keypoints (patch centres for the
    colour descriptors) in the image as given, for a geometric check of matches."""
    d = params.descriptor
    if any(a != 0.0 for a in angles) and d not in (DescriptorName.BRIEF, DescriptorName.BRIEFROT):
        raise ValueError(f"pattern rotation only applies to BRIEF, not {d.value}")
    if d.is_color and is_grayscale(image):
        raise GrayscaleImageError(f"{name}: is a grayscale image; the {d.value} vocabulary needs colour images "
                                  "(use brief, briefrot, orb or surf)")
    size = image.shape[:2] if image is not None else (0, 0)
    image, mask = prepare(image, params, mask)
    if d in (DescriptorName.BRIEF, DescriptorName.BRIEFROT):
        xy, out = _brief(image, params, mask, angles)
    elif d is DescriptorName.ORB:
        kps, des = cv2.ORB_create(nfeatures=params.n_features).detectAndCompute(_gray(image), mask)
        xy, out = _points(kps), [des if des is not None else np.zeros((0, 32), np.uint8)]
    elif d is DescriptorName.SURF:
        kps, des = cv2.SIFT_create(nfeatures=params.n_features).detectAndCompute(_gray(image), mask)
        xy, out = _points(kps), [des.astype(np.float32) if des is not None else np.zeros((0, 128), np.float32)]
    else:
        xy, out = _color(image, params, mask)
    if len(out[0]) == 0:
        raise NoFeaturesError(f"{name}: no {d.value} features found (blank, too small or fully masked image)")
    if image.shape[:2] != size:   # upscaled by prepare(): back to the pixels of the image as given
        xy = xy * np.array([size[1] / image.shape[1], size[0] / image.shape[0]], np.float32)
    return xy.astype(np.float32), out


def _points(kps) -> np.ndarray:
    return cv2.KeyPoint_convert(kps).reshape(-1, 2) if kps else np.zeros((0, 2), np.float32)


def _brief(image: np.ndarray, params: VocabParams, mask: np.ndarray | None,
           angles: tuple[float, ...]) -> tuple[np.ndarray, list[np.ndarray]]:
    gray = _gray(image)
    pattern = _pattern(params.brief_patch, params.brief_pattern_seed)
    radius = pattern_radius(pattern)
    # oFAST keypoints from OpenCV's ORB detector, as the paper does; BRIEF itself ignores scale and orientation
    kps = cv2.ORB_create(nfeatures=params.n_features, edgeThreshold=min(radius, 31)).detect(gray, mask)
    xy = np.rint(cv2.KeyPoint_convert(kps)).astype(np.int32).reshape(-1, 2) if kps else np.zeros((0, 2), np.int32)
    xy = xy[inside(xy, gray.shape, radius)]
    smoothed = smooth_for_brief(gray, params.brief_sigma)
    return xy.astype(np.float32), [brief_describe(smoothed, xy, rotated_offsets(pattern, a)) for a in angles]


def color_patches(shape: tuple[int, int], params: VocabParams, seed: int | None = None) -> np.ndarray:
    """Patch rectangles (P, 4) as x0, y0, w, h for the colour descriptors of an image of this shape.
    Patches are color_patch_fraction of the image (64 x 48 at 640 x 480, as in the paper)."""
    h, w = shape[:2]
    d = params.descriptor
    if d is DescriptorName.COLOR_RANDOM:
        pw, ph = max(2, int(round(w * params.color_patch_fraction))), max(2, int(round(h * params.color_patch_fraction)))
        rng = np.random.default_rng([params.seed if seed is None else seed, 0xC010])
        x0 = rng.integers(0, w - pw + 1, params.color_random_patches)
        y0 = rng.integers(0, h - ph + 1, params.color_random_patches)
        return np.stack([x0, y0, np.full_like(x0, pw), np.full_like(x0, ph)], axis=1)
    region_h = h // 2 if d is DescriptorName.COLOR_HALF else h
    g = params.color_grid
    # g partitions per axis, patches one partition wide, shifted by half a partition: (2g - 1)^2 patches
    xs = np.linspace(0, w, 2 * g + 1).round().astype(int)
    ys = np.linspace(0, region_h, 2 * g + 1).round().astype(int)
    rects = [(xs[i], ys[j], xs[i + 2] - xs[i], ys[j + 2] - ys[j]) for j in range(2 * g - 1) for i in range(2 * g - 1)]
    return np.asarray(rects, np.int64)


def hs_bins(image: np.ndarray, n_bins: int) -> np.ndarray:
    """Per-pixel hue-saturation bin index in [0, n_bins^2) (HLS colour space; lightness is ignored)."""
    hls = cv2.cvtColor(image, cv2.COLOR_BGR2HLS)
    hb = (hls[..., 0].astype(np.int32) * n_bins) // 180
    sb = (hls[..., 2].astype(np.int32) * n_bins) // 256
    return np.minimum(hb, n_bins - 1) * n_bins + sb


def _color(image: np.ndarray, params: VocabParams, mask: np.ndarray | None) -> tuple[np.ndarray, list[np.ndarray]]:
    if image.ndim == 2 or image.shape[2] != 3:
        raise GrayscaleImageError("colour descriptors need a 3-channel BGR image")
    rects = color_patches(image.shape, params)
    if mask is not None:
        cx, cy = rects[:, 0] + rects[:, 2] // 2, rects[:, 1] + rects[:, 3] // 2
        rects = rects[mask[np.minimum(cy, mask.shape[0] - 1), np.minimum(cx, mask.shape[1] - 1)] > 0]
    centres = (rects[:, :2] + rects[:, 2:4] / 2.0).astype(np.float32)
    if len(rects) == 0:
        return centres, [np.zeros((0, params.hs_bins ** 2), np.float32)]
    nb = params.hs_bins ** 2
    bins = hs_bins(image, params.hs_bins)
    # one integral image per bin would be 64 full-size planes; patches are few, so count them directly with one
    # bincount over every patch's pixels (sampled every `step` pixels: patches are large and smooth)
    step = max(1, int(min(rects[:, 2].min(), rects[:, 3].min()) // 24))
    out = np.empty((len(rects), nb), np.float32)
    for (pw, ph), sel in _group_by_size(rects):
        dy, dx = np.mgrid[0:ph:step, 0:pw:step]
        ys = rects[sel, 1, None] + dy.ravel()[None, :]
        xs = rects[sel, 0, None] + dx.ravel()[None, :]
        b = bins[ys, xs] + (np.arange(len(sel)) * nb)[:, None]
        hist = np.bincount(b.ravel(), minlength=len(sel) * nb).reshape(len(sel), nb)
        out[sel] = hist / hist.sum(axis=1, keepdims=True)
    return centres, [out]


def _group_by_size(rects: np.ndarray):
    sizes = rects[:, 2:4]
    keys, inverse = np.unique(sizes, axis=0, return_inverse=True)
    for i, (pw, ph) in enumerate(keys):
        yield (int(pw), int(ph)), np.nonzero(inverse.ravel() == i)[0]
