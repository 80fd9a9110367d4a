"""The floor vocabulary shipped with the toolkit: ORB words of ground-texture photographs, so that a downward camera
can detect loops with the vocabulary tree from its first keyframe (a vocabulary must exist before keys arrive).

Build it (deterministic: the same photographs give the same file):

    python -m loops.vocab.floor_vocabulary TEXTURES_DIR loops/data/floor_orb.voc

Each photograph is resampled at a few scales (a floor seen from different heights and by different cameras) and
ORB descriptors are detected on every scale; a k = 10, depth 3 tree (1000 words, ~85 kB) is built from all of them.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from loops.errors import LoopsError

from .features import NoFeaturesError, extract
from .params import DescriptorName, VocabParams
from .tree import VocabularyTree, build_tree, load_vocabulary, save_vocabulary

FLOOR_VOCABULARY = Path(__file__).resolve().parents[1] / "data" / "floor_orb.voc"
FLOOR_PARAMS = VocabParams(descriptor=DescriptorName.ORB, k=10, depth=3, n_features=500)
TRAINING_SCALES = (0.5, 0.75, 1.0, 1.5, 2.0)
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
_REFERENCE_AREA = 640 * 480      # n_features ORB keypoints per this many pixels of a resampled photograph


def training_descriptors(images: Sequence[np.ndarray], params: VocabParams = FLOOR_PARAMS,
                         scales: Sequence[float] = TRAINING_SCALES) -> np.ndarray:
    """ORB descriptors of every grey image at every scale (keypoints in proportion to the resampled area)."""
    out = []
    for image in images:
        for s in scales:
            im = cv2.resize(image, None, fx=s, fy=s, interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR)
            n = max(params.n_features, int(params.n_features * im.size / _REFERENCE_AREA))
            try:
                out.append(extract(im, dataclasses.replace(params, n_features=n))[0])
            except NoFeaturesError:
                continue
    if not out:
        raise LoopsError("no ORB features in the training images")
    return np.concatenate(out)


def read_textures(texture_dir: str | Path) -> list[np.ndarray]:
    """The grey images of a directory, in name order."""
    files = sorted(p for p in Path(texture_dir).iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in files]
    if not files or any(im is None for im in images):
        raise LoopsError(f"{texture_dir}: no readable images ({', '.join(IMAGE_SUFFIXES)})")
    return images


def build_floor_vocabulary(texture_dir: str | Path, params: VocabParams = FLOOR_PARAMS) -> VocabularyTree:
    d = training_descriptors(read_textures(texture_dir), params)
    return build_tree(d, params.k, params.depth, seed=params.seed, iters=params.kmeans_iters,
                      max_train=params.max_train_descriptors, restarts=params.kmeans_restarts)


def floor_info(params: VocabParams) -> dict:
    """What a vocabulary file records about how its words were made (extraction must match it)."""
    return {"descriptor": params.descriptor.value, "n_features": params.n_features, "k": params.k,
            "depth": params.depth, "seed": params.seed}


def load_floor_vocabulary(path: str | Path | None = None) -> tuple[VocabularyTree, VocabParams]:
    """A floor vocabulary (default: the shipped one) and the extraction parameters it was built with."""
    tree, info = load_vocabulary(FLOOR_VOCABULARY if path is None else path)
    try:
        params = dataclasses.replace(FLOOR_PARAMS, descriptor=DescriptorName(info["descriptor"]),
                                     n_features=int(info["n_features"]), k=tree.k, depth=tree.depth)
    except (KeyError, ValueError) as exc:
        raise LoopsError(f"{path or FLOOR_VOCABULARY}: not a floor vocabulary ({exc})") from None
    return tree, params


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m loops.vocab.floor_vocabulary", description=__doc__.split("\n\n")[0])
    ap.add_argument("textures", type=Path, help="directory of ground-texture photographs")
    ap.add_argument("out", type=Path, help="vocabulary file to write (.voc)")
    a = ap.parse_args(argv)
    tree = build_floor_vocabulary(a.textures)
    save_vocabulary(a.out, tree, floor_info(FLOOR_PARAMS))
    print(f"{a.out}: {tree.n_words} words, {a.out.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
