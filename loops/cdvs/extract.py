"""Keypoints, relevance-based selection and ORB descriptors for the compact descriptor.

Detection is ORB's FAST + Harris on a small pyramid. Selection happens BEFORE descriptors are computed: every
keypoint gets a relevance (product of trained lookup tables on its normalised response, pyramid level and
distance from the image centre, as the CDVS "pdf"), and only the most relevant ones are described.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from loops.cdvs.params import ExtractionParams
from loops.cdvs.trained import TrainedParams
from loops.errors import LoopsError


@dataclass(frozen=True)
class Features:
    """Described keypoints of one image, most relevant first."""

    orig_size: tuple[int, int]   # (width, height) of the input image
    proc_size: tuple[int, int]   # (width, height) after resizing to max_side
    xy: np.ndarray               # (N, 2) float32 keypoints in processed-image pixels
    relevance: np.ndarray        # (N,) float32
    desc: np.ndarray             # (N, 32) uint8 ORB descriptors


def to_gray_u8(image: np.ndarray) -> np.ndarray:
    """Accept gray or BGR/BGRA images, uint8 or uint16 or float in [0, 1]; return a contiguous uint8 gray image."""
    im = np.asarray(image)
    if im.ndim == 3 and im.shape[2] == 1:
        im = im[:, :, 0]
    if im.ndim == 3:
        if im.shape[2] not in (3, 4):
            raise LoopsError(f"image must be gray or BGR(A), got shape {im.shape}")
        im = cv2.cvtColor(im, cv2.COLOR_BGR2GRAY if im.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if im.ndim != 2:
        raise LoopsError(f"image must be a 2-D gray or 3-D colour array, got shape {im.shape}")
    if im.shape[0] < 16 or im.shape[1] < 16 or max(im.shape) > 65535:
        raise LoopsError(f"image size {im.shape[1]}x{im.shape[0]} is outside 16..65535 pixels")
    if im.dtype == np.uint16:
        im = (im >> 8).astype(np.uint8)
    elif im.dtype.kind == "f":
        im = np.clip(im * 255.0 + 0.5, 0, 255).astype(np.uint8)
    elif im.dtype != np.uint8:
        raise LoopsError(f"unsupported image dtype {im.dtype}")
    return np.ascontiguousarray(im)


def processed_size(width: int, height: int, max_side: int) -> tuple[int, int]:
    s = min(1.0, max_side / max(width, height))
    return max(1, int(width * s + 0.5)), max(1, int(height * s + 0.5))


@functools.lru_cache(maxsize=16)
def _orb(params: ExtractionParams, threshold: int | None = None) -> cv2.ORB:
    return cv2.ORB_create(nfeatures=params.n_detect, scaleFactor=params.scale_factor, nlevels=params.n_levels,
                          edgeThreshold=19, patchSize=31,
                          fastThreshold=params.fast_threshold if threshold is None else threshold)


@functools.lru_cache(maxsize=4)
def _fast(threshold: int) -> cv2.FastFeatureDetector:
    return cv2.FastFeatureDetector_create(threshold, True)


def detector_for(gray: np.ndarray, params: ExtractionParams) -> cv2.ORB:
    """ORB with the low FAST threshold, or the high one on corner-dense textures: same keypoints where it matters,
    several times faster on carpet. A FAST count on the central quarter of the image decides (counting on the
    whole image cost as much as ORB itself on carpet)."""
    h, w = gray.shape
    crop = gray[h // 4: h // 4 + h // 2, w // 4: w // 4 + w // 2]
    n = 4 * len(_fast(params.fast_threshold).detect(crop))
    return _orb(params, params.dense_threshold if n > params.dense_corners else None)


def keypoint_attributes(kps, proc_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(xy, log response ratio, octave, normalised radius) of OpenCV keypoints."""
    xy = cv2.KeyPoint_convert(kps).reshape(-1, 2).astype(np.float32)
    resp = np.array([k.response for k in kps], dtype=np.float64)
    octave = np.array([k.octave for k in kps], dtype=np.int64)
    med = np.median(resp) if len(resp) else 1.0
    lresp = np.log(np.maximum(resp, 1e-12) / max(med, 1e-12))
    w, h = proc_size
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    radius = np.linalg.norm(xy - centre, axis=1) / (0.5 * np.hypot(w, h))
    return xy, lresp, octave, radius


def relevance(lresp: np.ndarray, octave: np.ndarray, radius: np.ndarray, trained: TrainedParams | None,
              centre_prior: bool = True) -> np.ndarray:
    """The CDVS-style relevance: product of per-attribute probabilities that a keypoint is matched."""
    if trained is None:  # used only while training the tables themselves
        return lresp.astype(np.float32)
    r = trained.resp_p[np.searchsorted(trained.resp_edges, lresp)]
    o = trained.octave_p[np.clip(octave, 0, len(trained.octave_p) - 1)]
    table = trained.radius_p_central if centre_prior else trained.radius_p
    q = table[np.searchsorted(trained.radius_edges, radius)]
    return (r * o * q).astype(np.float32)


def extract_features(image: np.ndarray, params: ExtractionParams, trained: TrainedParams | None,
                     n_described: int | None = None) -> Features:
    """Detect, rank by relevance, describe the top `n_described` keypoints."""
    gray = to_gray_u8(image)
    oh, ow = gray.shape
    pw, ph = processed_size(ow, oh, params.max_side)
    if (pw, ph) != (ow, oh):
        gray = cv2.resize(gray, (pw, ph), interpolation=cv2.INTER_AREA)
    orb = detector_for(gray, params)
    kps = orb.detect(gray, None)
    n_desc = params.n_described if n_described is None else n_described
    empty = Features((ow, oh), (pw, ph), np.zeros((0, 2), np.float32), np.zeros(0, np.float32),
                     np.zeros((0, 32), np.uint8))
    if not kps:
        return empty
    _, lresp, octave, radius = keypoint_attributes(kps, (pw, ph))
    rel = relevance(lresp, octave, radius, trained, params.centre_prior)
    order = np.argsort(-rel, kind="stable")[:n_desc]
    chosen = [kps[i] for i in order]
    chosen, desc = orb.compute(gray, chosen)
    if desc is None or not chosen:
        return empty
    # orb.compute may drop or reorder keypoints: recompute attributes of what it returned
    xy = cv2.KeyPoint_convert(chosen).reshape(-1, 2).astype(np.float32)
    resp = np.array([k.response for k in chosen])
    octs = np.array([k.octave for k in chosen], dtype=np.int64)
    med = np.median(np.array([k.response for k in kps]))
    lr = np.log(np.maximum(resp, 1e-12) / max(med, 1e-12))
    centre = np.array([(pw - 1) / 2.0, (ph - 1) / 2.0])
    rad = np.linalg.norm(xy - centre, axis=1) / (0.5 * np.hypot(pw, ph))
    rel2 = relevance(lr, octs, rad, trained, params.centre_prior)
    o2 = np.argsort(-rel2, kind="stable")
    return Features((ow, oh), (pw, ph), xy[o2], rel2[o2], np.ascontiguousarray(desc[o2]))
