"""A visual memory: the key images' vocabulary tree(s) and database(s); a query returns the ranked key images.

For every descriptor but BRIEFROT there is one (tree, database) pair. BRIEFROT keeps three, built from the key
images' BRIEF descriptors with the test pattern at 0, +theta and -theta; a query (plain pattern) is scored in each
and a key image's score is the maximum over the three (eq. 2).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from odometry.shared.errors import ToolkitError

from .database import BowDatabase, EmptyMemoryError
from .features import NoFeaturesError, brief_angles, extract
from .fileformat import VocabFileError, load_arrays, save_arrays
from .params import VocabParams
from .tree import VocabularyTree, build_tree

FILE_KIND = "vslam-visual-memory"


def check_tree(tree: VocabularyTree, params: VocabParams) -> None:
    """A vocabulary read from a file fits the memory's parameters (raises VocabFileError)."""
    if tree.k != params.k or tree.depth != params.depth:
        raise VocabFileError(f"vocabulary k={tree.k} L={tree.depth}, parameters k={params.k} L={params.depth}")
    if tree.centres.ndim != 2 or tree.children.ndim != 2 or tree.word.ndim != 1 or len(tree.centres) == 0:
        raise VocabFileError("vocabulary arrays have the wrong number of dimensions")
    if tree.children.min(initial=0) < -1 or not np.issubdtype(tree.children.dtype, np.integer):
        raise VocabFileError("vocabulary child ids out of range")


def check_counts(arrays: dict[str, np.ndarray], prefix: str, n_keys: int) -> None:
    """The word counts of a database read from a file are consistent with its key images (VocabFileError)."""
    ptr, word, n = (arrays[f"{prefix}{k}"] for k in ("counts_ptr", "counts_word", "counts_n"))
    if ptr.ndim != 1 or word.ndim != 1 or n.ndim != 1 or len(ptr) != n_keys + 1 or len(word) != len(n):
        raise VocabFileError(f"database of {len(ptr) - 1} key images for {n_keys} names")
    if ptr[0] != 0 or ptr[-1] != len(word) or np.any(np.diff(ptr) < 0) or np.any(n <= 0):
        raise VocabFileError("database word counts are inconsistent")


def vocabulary_seed(params: VocabParams, o: int) -> int:
    """Build seed of vocabulary o (pattern angle index): the vocabularies of a BRIEFROT memory get distinct seeds,
    three independent internal vocabularies; vocabulary 0 is the BRIEF vocabulary of the same seed."""
    return params.seed + 7919 * o


@dataclass(frozen=True)
class Ranking:
    """Candidate key images, best first: indices into the memory, scores in [0, 1], and for each the vocabulary
    (index into the memory's pattern angles) that gave the maximum (always 0 unless BRIEFROT)."""

    keys: np.ndarray
    scores: np.ndarray
    vocab: np.ndarray

    def __len__(self) -> int:
        return len(self.keys)

    def dense_scores(self, n_keys: int) -> np.ndarray:
        """Score of every key image (0 for non-candidates)."""
        z = np.zeros(n_keys)
        z[self.keys] = self.scores
        return z


def merge_max(scores: Sequence) -> Ranking:
    """Eq. 2: per key image, the maximum score over several vocabularies' candidate lists."""
    if len(scores) == 1:
        s = scores[0]
        return Ranking(s.keys, s.scores, np.zeros(len(s.keys), np.int64))
    keys = np.concatenate([s.keys for s in scores])
    vals = np.concatenate([s.scores for s in scores])
    vocab = np.concatenate([np.full(len(s.keys), o, np.int64) for o, s in enumerate(scores)])
    if len(keys) == 0:
        return Ranking(keys, vals, vocab)
    # best score per key (earliest vocabulary wins ties), then rank by score, ties by key index
    order = np.lexsort((vocab, -vals, keys))
    keys, vals, vocab = keys[order], vals[order], vocab[order]
    first = np.concatenate(([True], keys[1:] != keys[:-1]))
    keys, vals, vocab = keys[first], vals[first], vocab[first]
    order = np.lexsort((keys, -vals))
    return Ranking(keys[order], vals[order], vocab[order])


@dataclass(frozen=True)
class VisualMemory:
    params: VocabParams
    key_names: tuple[str, ...]
    angles: tuple[float, ...]
    trees: tuple[VocabularyTree, ...]
    databases: tuple[BowDatabase, ...]
    # key images kept without descriptors (no features, e.g. a blank wall, or unreadable): they never match
    featureless: tuple[int, ...] = ()

    def __len__(self) -> int:
        return len(self.key_names)

    # ---- building ------------------------------------------------------------------------------------------
    @classmethod
    def build(cls, images: Iterable[np.ndarray], names: Sequence[str], params: VocabParams,
              masks: Sequence[np.ndarray | None] | None = None) -> "VisualMemory":
        """Extract descriptors from the key images, build the vocabulary (per pattern angle) and the database.

        A key image without features (a blank wall) or given as None (unreadable) stays a key that never matches;
        their indices are the memory's `featureless`. Raises EmptyMemoryError when no key image has features."""
        angles = brief_angles(params)
        per_angle: list[list[np.ndarray | None]] = [[] for _ in angles]
        names = list(names)
        featureless: list[int] = []
        count = 0
        for i, image in enumerate(images):
            if i >= len(names):
                raise ValueError(f"more key images than names ({len(names)})")
            mask = masks[i] if masks is not None else None
            try:
                descs = extract(image, params, mask, angles, name=names[i]) if image is not None else None
            except NoFeaturesError:
                descs = None
            if descs is None:
                featureless.append(i)
                descs = [None] * len(angles)
            for o, d in enumerate(descs):
                per_angle[o].append(d)
            count += 1
        if count == 0:
            raise EmptyMemoryError("the visual memory has no key images")
        if count != len(names):
            raise ValueError(f"{count} key images for {len(names)} names")
        if len(featureless) == count:
            raise EmptyMemoryError(f"none of the {count} key images has {params.descriptor.value} features")
        # the empty keys get empty descriptor arrays of the vocabulary's row type
        filled = []
        for descs in per_angle:
            like = next(d for d in descs if d is not None)
            filled.append([d if d is not None else like[:0] for d in descs])
        memory = cls.from_descriptors(filled, names, params, angles)
        return replace(memory, featureless=tuple(featureless))

    @classmethod
    def from_descriptors(cls, per_angle: list[list[np.ndarray]], names: Sequence[str], params: VocabParams,
                         angles: tuple[float, ...] | None = None) -> "VisualMemory":
        """Build from precomputed descriptors: per_angle[o][i] = descriptors of key image i under pattern angle o."""
        if len(names) == 0 or len(per_angle) == 0 or len(per_angle[0]) == 0:
            raise EmptyMemoryError("the visual memory has no key images")
        trees = [build_tree(np.concatenate(descs), params.k, params.depth, seed=vocabulary_seed(params, o),
                            iters=params.kmeans_iters, max_train=params.max_train_descriptors,
                            restarts=params.kmeans_restarts)
                 for o, descs in enumerate(per_angle)]
        return cls.from_trees(trees, per_angle, names, params, angles)

    @classmethod
    def from_trees(cls, trees: Sequence[VocabularyTree], per_angle: list[list[np.ndarray]], names: Sequence[str],
                   params: VocabParams, angles: tuple[float, ...] | None = None) -> "VisualMemory":
        """Assemble a memory from vocabularies already built (one per pattern angle) and the key descriptors."""
        angles = brief_angles(params) if angles is None else tuple(angles)
        if len(names) == 0 or len(per_angle) == 0 or len(per_angle[0]) == 0:
            raise EmptyMemoryError("the visual memory has no key images")
        if not (len(trees) == len(per_angle) == len(angles)):
            raise ValueError(f"{len(trees)} vocabularies and {len(per_angle)} descriptor sets for "
                             f"{len(angles)} pattern angles")
        if any(len(descs) != len(names) for descs in per_angle):
            raise ValueError(f"descriptor sets do not match the {len(names)} key names")
        dbs = [BowDatabase.from_words([tree.transform(d) for d in descs], tree.n_words, params.distance)
               for tree, descs in zip(trees, per_angle)]
        return cls(params, tuple(names), tuple(angles), tuple(trees), tuple(dbs))

    # ---- queries -------------------------------------------------------------------------------------------
    def query(self, image: np.ndarray, mask: np.ndarray | None = None, name: str = "query") -> Ranking:
        """Ranked key images for a query image (feature extraction + scoring)."""
        return self.query_descriptors(extract(image, self.params, mask, (0.0,), name=name)[0])

    def query_descriptors(self, descriptors: np.ndarray) -> Ranking:
        dim = self.trees[0].centres.shape[1]
        if descriptors.ndim != 2 or descriptors.shape[1] != dim:
            raise VocabFileError(f"descriptors of {descriptors.shape[-1]} values do not fit the memory's "
                                 f"{dim}-value vocabulary (memory file damaged or of other parameters)")
        return merge_max([db.score(tree.transform(descriptors), self.params.min_shared_words)
                          for tree, db in zip(self.trees, self.databases)])

    def key_similarity(self, k: int) -> np.ndarray:
        """z_l(I*_k) of the paper's eq. 4 for every key image l: the similarity of key image k to key image l as
        the memory represents them (their stored word histograms, compared with the memory's distance; 0 for key
        images sharing fewer than min_shared_words words with k; 1 for k itself). For BRIEFROT it is the maximum
        over the three vocabularies (eq. 2), each comparing the two key images in that vocabulary's own
        representation (both described with the pattern at the same angle): the rotated vocabularies exist to
        absorb the rotation of a query, and matching a key's plain descriptors against other keys' rotated ones
        only adds chance word collisions with unrelated key images."""
        z = merge_max([db.score_image(k, self.params.min_shared_words) for db in self.databases]
                      ).dense_scores(len(self))
        z[k] = 1.0  # also for a key with (almost) no words, which is not a candidate of itself
        return z

    # ---- files ---------------------------------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        arrays: dict[str, np.ndarray] = {}
        for o, (tree, db) in enumerate(zip(self.trees, self.databases)):
            arrays.update(tree.to_arrays(f"v{o}."))
            arrays.update(db.to_arrays(f"v{o}."))
        meta = {"kind": FILE_KIND, "params": self.params.to_dict(), "angles": list(self.angles),
                "trees": [t.meta() for t in self.trees], "key_names": list(self.key_names),
                "featureless": list(self.featureless)}
        save_arrays(path, meta, arrays)

    @classmethod
    def load(cls, path: str | Path) -> "VisualMemory":
        """Read a memory file; anything inconsistent in it is a VocabFileError naming the file."""
        meta, arrays = load_arrays(path)
        if meta.get("kind") != FILE_KIND:
            raise VocabFileError(f"{path}: not a visual memory file (kind {meta.get('kind')!r})")
        try:
            memory = cls._from_file(meta, arrays)
        except VocabFileError as exc:
            raise VocabFileError(f"{path}: {exc}") from None
        except (ToolkitError, KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
            # the JSON header is not under the file's checksum: a hand-edited or damaged one lands here
            raise VocabFileError(f"{path}: invalid visual memory file ({type(exc).__name__}: {exc})") from None
        return memory

    @classmethod
    def _from_file(cls, meta: dict, arrays: dict[str, np.ndarray]) -> "VisualMemory":
        params = VocabParams.from_dict(meta["params"])
        names = meta["key_names"]
        angles = meta["angles"]
        featureless = meta.get("featureless", [])
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names) or not names:
            raise VocabFileError("key_names must be a non-empty list of names")
        if not isinstance(angles, list) or not all(isinstance(a, (int, float)) and not isinstance(a, bool)
                                                   and np.isfinite(a) for a in angles):
            raise VocabFileError("angles must be a list of finite numbers")
        if tuple(float(a) for a in angles) != tuple(float(a) for a in brief_angles(params)):
            raise VocabFileError(f"angles {angles} do not match the parameters {list(brief_angles(params))}")
        if not isinstance(meta["trees"], list) or len(meta["trees"]) != len(angles):
            raise VocabFileError(f"{len(angles)} pattern angles need as many vocabularies")
        if not isinstance(featureless, list) or not all(isinstance(i, int) and 0 <= i < len(names)
                                                        for i in featureless):
            raise VocabFileError("featureless must list key image indices")
        trees, dbs = [], []
        for o, tm in enumerate(meta["trees"]):
            for key in ("children", "word", "counts_ptr", "counts_word", "counts_n"):
                if not np.issubdtype(arrays[f"v{o}.{key}"].dtype, np.signedinteger):
                    raise VocabFileError(f"array v{o}.{key} must hold signed integers")
            tree = VocabularyTree.from_arrays(tm, arrays, f"v{o}.")
            check_tree(tree, params)
            db = BowDatabase.from_arrays(arrays, tree.n_words, params.distance, f"v{o}.")
            check_counts(arrays, f"v{o}.", len(names))
            trees.append(tree)
            dbs.append(db)
        if len({t.centres.shape[1] for t in trees}) != 1 or len({t.kind for t in trees}) != 1:
            raise VocabFileError("the vocabularies of one memory must share their descriptor kind and length")
        return cls(params, tuple(names), tuple(float(a) for a in angles), tuple(trees), tuple(dbs),
                   tuple(featureless))

    def describe(self) -> str:
        words = ", ".join(str(t.n_words) for t in self.trees)
        return (f"visual memory: {len(self)} key images, descriptor {self.params.descriptor.value}, "
                f"k={self.params.k} L={self.params.depth}, words {words}, distance {self.params.distance.value}, "
                f"pattern angles {json.dumps(list(self.angles))}")
