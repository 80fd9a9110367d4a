"""The classification bank of `vslam bench horizon`: matched / unmatched pairs of 640-pixel crops of the real, wide
KITTI frames in ../shared/data/places/kitti_snippets (see `build_bank` for the exact recipe)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from odometry.shared.tum import tum_to_se3_matrices
from vslam.io import read_kitti

SNIPPETS = ("KITTI_sequence_1_kitti06_f0000-0050", "KITTI_sequence_2_unidentified_seq00-02calib")
# KITTI pairs from ../shared/data/pairs where a horizon row makes sense (the level car camera, row = cy).
# The other pairs there are hand-held / tilted views (TUM office) or planar and object scenes (graf, churchill,
# box, mars, ship, bicycle, SOH, kn_church) that have no horizon to read.
KITTI_PAIR_ROW = 183  # cy = 183.1 for KITTI 06 (calibration in kitti_snippets)


@dataclass(frozen=True)
class View:
    snippet: int        # index into SNIPPETS
    frame: int
    offset: int         # crop's first column in the full frame
    path: Path
    row: int            # horizon row (the principal point row cy, rounded: the KITTI camera is level)
    heading_deg: float  # world heading of the crop centre's ray
    position: tuple[float, float, float]


@dataclass(frozen=True)
class Bank:
    views: list[View]
    pairs: np.ndarray       # (P, 2) view indices
    labels: np.ndarray      # (P,) bool: matched
    kind: np.ndarray        # (P,) str: rotation | rotation+translation | unmatched-same-drive | unmatched-other-drive
    crop: int


def read_kitti_snippet(folder: Path) -> tuple[dict, np.ndarray, list[Path]]:
    """(calibration {fx, cx, cy}, (N, 3, 4) camera poses, image paths) of a kitti_snippets folder, via the
    toolkit's KITTI reader."""
    seq = read_kitti(folder)
    if seq.groundtruth is None:
        raise ValueError(f"{folder}: no poses.txt (the bank needs ground-truth headings)")
    poses = tum_to_se3_matrices(seq.groundtruth.poses)[:, :3, :]
    cam = seq.camera
    return {"fx": cam.fx, "cx": cam.cx, "cy": cam.cy}, poses, [seq.images.path(i) for i in range(len(seq))]


def _ray_heading(rotation: np.ndarray, u: float, fx: float, cx: float) -> float:
    # KITTI camera: x right, y down, z forward. Heading of the ray through column u, on the ground plane (x-z).
    d = rotation @ np.array([(u - cx) / fx, 0.0, 1.0])
    return float(np.degrees(np.arctan2(d[0], d[2])))


def build_bank(data_dir: Path, frame_step: int = 2, n_offsets: int = 12, crop: int = 640, match_deg: float = 20.0,
               max_baseline: float = 2.5, n_matched: int = 480, n_unmatched: int = 2065, seed: int = 0) -> Bank:
    """The classification bank (deterministic for a seed).

    Views: frames 0, frame_step, ... of each snippet; in each, n_offsets crops of `crop` px at offsets
    round(linspace(0, W - crop, n_offsets)) (about 4.3 degrees apart, like the paper's 4-degree turns).
    Labels: matched when the crop-centre rays differ by < match_deg in heading and the camera centres are at most
    max_baseline metres apart (same frame: pure rotation, the paper's protocol; nearby frames: rotation plus
    translation, i.e. scale change); unmatched when the headings differ by >= match_deg (same drive, any distance)
    or the views come from different drives. Same-drive pairs within match_deg but further apart than max_baseline
    are left out: a heading label only says "same landmark" when the landmarks are far compared to the baseline.
    Then n_matched / n_unmatched pairs are drawn without replacement (the paper's 480 and 2,065), the unmatched
    ones 3:1 from the same drive. Each draw has its own random stream, so banks that differ only in
    max_baseline share their unmatched pairs.
    """
    root = data_dir / "places" / "kitti_snippets"
    views: list[View] = []
    for si, name in enumerate(SNIPPETS):
        calib, poses, images = read_kitti_snippet(root / name)
        first = cv2.imread(str(images[0]), cv2.IMREAD_GRAYSCALE)
        if first is None:
            raise OSError(f"{images[0]}: cannot read image")
        offsets = np.rint(np.linspace(0, first.shape[1] - crop, n_offsets)).astype(int)
        row = int(round(calib["cy"]))
        for f in range(0, len(images), frame_step):
            r, t = poses[f, :, :3], poses[f, :, 3]
            for o in offsets:
                heading = _ray_heading(r, o + (crop - 1) / 2.0, calib["fx"], calib["cx"])
                views.append(View(si, f, int(o), images[f], row, heading, tuple(float(v) for v in t)))

    snip = np.array([v.snippet for v in views])
    head = np.array([v.heading_deg for v in views])
    pos = np.array([v.position for v in views])
    frame = np.array([v.frame for v in views])
    i, j = np.triu_indices(len(views), 1)
    same = snip[i] == snip[j]
    dh = np.abs((head[i] - head[j] + 180.0) % 360.0 - 180.0)
    base = np.linalg.norm(pos[i] - pos[j], axis=1)
    matched = same & (dh < match_deg) & (base <= max_baseline)
    unmatched_same = same & (dh >= match_deg)
    other = ~same

    def draw(mask: np.ndarray, k: int, stream: int) -> np.ndarray:
        idx = np.flatnonzero(mask)
        rng = np.random.default_rng([seed, stream])
        return np.sort(rng.choice(idx, size=min(k, idx.size), replace=False))

    pick_m = draw(matched, n_matched, 1)
    n_same = min(int(round(0.75 * n_unmatched)), int(unmatched_same.sum()))
    pick_u = draw(unmatched_same, n_same, 2)
    pick_o = draw(other, n_unmatched - n_same, 3)
    sel = np.r_[pick_m, pick_u, pick_o]
    kind = np.r_[np.where(frame[i[pick_m]] == frame[j[pick_m]], "rotation", "rotation+translation"),
                 np.full(pick_u.size, "unmatched-same-drive"), np.full(pick_o.size, "unmatched-other-drive")]
    labels = np.r_[np.ones(pick_m.size, bool), np.zeros(pick_u.size + pick_o.size, bool)]
    return Bank(views, np.stack([i[sel], j[sel]], axis=1), labels, kind, crop)


def load_crops(bank: Bank) -> list[np.ndarray]:
    """The grey crop of every view of the bank (each frame read once)."""
    cache: dict[Path, np.ndarray] = {}
    crops = []
    for v in bank.views:
        if v.path not in cache:
            img = cv2.imread(str(v.path), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise OSError(f"{v.path}: cannot read image")
            cache[v.path] = img
        crops.append(np.ascontiguousarray(cache[v.path][:, v.offset:v.offset + bank.crop]))
    return crops
