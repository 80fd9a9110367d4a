"""The real image sets of `vslam bench localize` (from ../shared/data): key images, queries and their ground truth.

corridor (reference traverse = memory, second traverse = queries), corridor-rot (the same queries rotated by 10-30
degrees, alternating sign, seeded), kitti (two KITTI snippets, every 3rd frame a key image), pairs (the 48 labelled
pairs: one key image per scene); and the 640x480 images of the query-time measurement.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from vslam.io.image_folder import read_image
from vslam.io.truth_csv import write_truth

SETS = ("corridor", "corridor-rot", "kitti", "pairs")


@dataclass
class PlaceSet:
    name: str
    note: str
    keys: list      # [(name, image)]
    queries: list   # [(name, image, mask or None)]
    truth: dict     # query name -> [key indices]
    keys_id: str    # identity of the key images (sets with equal keys_id share features and vocabularies)
    queries_id: str
    min_side: int = 0
    grayscale: bool = False

    @property
    def key_names(self) -> list[str]:
        return [n for n, _ in self.keys]


def rotate_with_mask(image: np.ndarray, angle_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Rotate about the centre (OpenCV sign: positive = counter-clockwise) keeping the size; the mask marks the
    pixels that come from the image (eroded, so no keypoint sits on the new black border)."""
    h, w = image.shape[:2]
    m = cv2.getRotationMatrix2D(((w - 1) / 2.0, (h - 1) / 2.0), angle_deg, 1.0)
    out = cv2.warpAffine(image, m, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    mask = cv2.warpAffine(np.full((h, w), 255, np.uint8), m, (w, h), flags=cv2.INTER_NEAREST)
    return out, cv2.erode(mask, np.ones((5, 5), np.uint8))


def rotation_angles(n: int, seed: int = 7, lo: float = 10.0, hi: float = 30.0) -> np.ndarray:
    """Deterministic query rotations: magnitudes uniform in [lo, hi] degrees, signs alternating."""
    mags = np.random.default_rng(seed).uniform(lo, hi, n)
    return mags * np.where(np.arange(n) % 2 == 0, 1.0, -1.0)


def corridor_set(data: Path, rotated: bool = False, stride: int = 1) -> PlaceSet:
    d = data / "places" / "corridor"
    refs, qs = sorted((d / "ref").glob("*.jpg")), sorted((d / "query").glob("*.jpg"))
    gt = np.load(d / "ground_truth_new.npy", allow_pickle=True)
    keys = [(p.name, read_image(p)) for p in refs]
    truth, queries = {}, []
    angles = rotation_angles(len(qs))
    for qi, ks in gt:
        if qi % stride:
            continue
        p = qs[int(qi)]
        img, mask = read_image(p), None
        if rotated:
            img, mask = rotate_with_mask(img, float(angles[int(qi)]))
        queries.append((p.name, img, mask))
        truth[p.name] = [int(k) for k in ks]
    note = ("Milford corridor, 111 ref keys vs second traverse, truth = ref i-2..i+2; 160x120 frames upscaled to "
            "480 lines (the paper's image height)")
    if rotated:
        note += "; queries rotated by 10-30 deg (alternating sign, seed 7), black borders masked"
    return PlaceSet("corridor-rot" if rotated else "corridor", note, keys, queries, truth, "corridor/ref",
                    f"corridor/query{'-rot' if rotated else ''}/{stride}", min_side=480)


def kitti_set(data: Path, key_every: int = 3, radius_m: float = 3.0) -> PlaceSet:
    root = data / "places" / "kitti_snippets"
    keys, queries, truth = [], [], {}
    for seq in sorted(p for p in root.glob("KITTI_sequence_*") if p.is_dir()):
        images = sorted((seq / "image_l").glob("*.png"))
        poses = np.loadtxt(seq / "poses.txt").reshape(-1, 3, 4)[:, :, 3]
        base = len(keys)
        key_frames = [i for i in range(len(images)) if i % key_every == 0]
        keys += [(f"{seq.name[:16]}/{images[i].name}", read_image(images[i])) for i in key_frames]
        kpos = poses[key_frames]
        for i in range(len(images)):
            if i % key_every == 0:
                continue
            name = f"{seq.name[:16]}/{images[i].name}"
            dist = np.linalg.norm(kpos - poses[i], axis=1)
            near = np.nonzero(dist <= max(radius_m, dist.min()))[0]
            queries.append((name, read_image(images[i]), None))
            truth[name] = [base + int(j) for j in near]
    note = (f"two KITTI snippets (51 frames each), every {key_every}rd frame a key image, the others queries; truth = "
            f"keys of the same drive within {radius_m:g} m (ground-truth poses); grayscale")
    return PlaceSet("kitti", note, keys, queries, truth, "kitti/keys", "kitti/queries", grayscale=True)


def pairs_set(data: Path) -> PlaceSet:
    d = data / "pairs"
    parent: dict[str, str] = {}

    def find(a: str) -> str:
        while parent.setdefault(a, a) != a:
            a = parent[a]
        return a

    order: list[str] = []
    for line in (d / "pairs.txt").read_text().splitlines():
        parts = line.split()
        if len(parts) != 3:
            continue
        a, b, label = parts
        for n in (a, b):
            if n not in order:
                order.append(n)
        if label == "1":
            parent[find(b)] = find(a)
    scenes: dict[str, list[str]] = {}
    for n in order:
        scenes.setdefault(find(n), []).append(n)
    keys, queries, truth = [], [], {}
    for members in scenes.values():
        key_index = len(keys)
        keys.append((members[0], read_image(d / "images" / f"{members[0]}.png")))
        for n in members[1:]:
            queries.append((n, read_image(d / "images" / f"{n}.png"), None))
            truth[n] = [key_index]
    note = (f"{len(keys)} scenes from the labelled pairs (same-scene pairs joined): first image of a scene = its key, "
            "the others are queries; grayscale")
    return PlaceSet("pairs", note, keys, queries, truth, "pairs/keys", "pairs/queries", grayscale=True)


def load_set(name: str, data: Path, quick: bool) -> PlaceSet:
    if name == "corridor":
        return corridor_set(data, stride=3 if quick else 1)
    if name == "corridor-rot":
        return corridor_set(data, rotated=True, stride=3 if quick else 1)
    if name == "kitti":
        return kitti_set(data)
    return pairs_set(data)


def write_set_truth(path: Path, ps: PlaceSet) -> None:
    """The set's ground truth as TRUTH.csv (for `vslam localize eval`)."""
    write_truth(path, ps.truth, ps.key_names)


def timing_images(data: Path, n_keys: int, n_queries: int) -> tuple[list, list, str]:
    """A memory of n_keys real-image-derived 640x480 frames (corridor upscaled, KITTI and pairs cropped to 4:3)
    in variants (as is, mirrored, zoomed 1.2x, rotated 4 deg) and n_queries held-out variants (rotated -3 deg,
    zoomed 1.1x)."""
    def to_vga(img):
        h, w = img.shape[:2]
        if w * 3 > h * 4:  # too wide: centre crop to 4:3
            cw = h * 4 // 3
            img = img[:, (w - cw) // 2:(w - cw) // 2 + cw]
        elif w * 3 < h * 4:
            ch = w * 3 // 4
            img = img[(h - ch) // 2:(h - ch) // 2 + ch]
        return cv2.resize(img, (640, 480), interpolation=cv2.INTER_LINEAR)

    def zoom(img, f):
        h, w = img.shape[:2]
        ch, cw = int(h / f), int(w / f)
        return cv2.resize(img[(h - ch) // 2:(h - ch) // 2 + ch, (w - cw) // 2:(w - cw) // 2 + cw], (w, h))

    def rot(img, a):
        return zoom(rotate_with_mask(img, a)[0], 1.25)

    paths = sorted((data / "places" / "corridor").glob("*/*.jpg"))
    paths += sorted((data / "places" / "kitti_snippets").glob("KITTI_sequence_*/image_l/*.png"))
    paths += sorted((data / "pairs" / "images").glob("*.png"))
    pool = []
    for p in paths:
        img = to_vga(read_image(p))
        pool.append(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img)
    variants = [lambda im: im, lambda im: cv2.flip(im, 1), lambda im: zoom(im, 1.2), lambda im: rot(im, 4.0)]
    keys = [variants[(i // len(pool)) % len(variants)](pool[i % len(pool)]) for i in range(n_keys)]
    step = max(1, len(pool) // n_queries)
    queries = [zoom(rot(pool[(j * step) % len(pool)], -3.0), 1.1) for j in range(n_queries)]
    note = (f"{n_keys} key images at 640x480 from {len(pool)} real frames (corridor x4 upscaled, KITTI and pairs "
            "cropped to 4:3) in variants (as is, mirrored, zoomed, rotated); queries = rotated+zoomed variants")
    return keys, queries, note
