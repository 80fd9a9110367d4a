"""Hierarchical vocabulary tree (Nister & Stewenius 2006): k-means++ with branch factor k, recursively, to depth L.

The tree is stored as flat arrays (node 0 = root), so it serialises to one contiguous block and a query descends
it level by level for all descriptors at once:

    centres  (n_nodes, D)  uint8 bit rows (binary kind) or float32 (float kind); the root's row is unused
    children (n_nodes, k)  int32 child node ids, -1 where absent; a node without children is a leaf = a word
    word     (n_nodes,)    int32 word id of each leaf, -1 for inner nodes

Like DBoW2, a node with at most k descriptors gets one child per distinct descriptor, so leaves can sit above
depth L. The tree is built level by level, all nodes of a level clustered in one vectorised k-means (kmeans.py);
the same descriptors and seed give the same tree.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .fileformat import VocabFileError, load_arrays, save_arrays
from .kinds import DescriptorKind, as_storage, batched_distances, kind_of
from .kmeans import grouped_kmeans


@dataclass(frozen=True)
class VocabularyTree:
    kind: DescriptorKind
    k: int
    depth: int
    centres: np.ndarray
    children: np.ndarray
    word: np.ndarray

    @property
    def n_words(self) -> int:
        return int((self.word >= 0).sum())

    @property
    def n_nodes(self) -> int:
        return len(self.children)

    @property
    def dim(self) -> int:
        return self.centres.shape[1]

    def transform(self, descriptors: np.ndarray) -> np.ndarray:
        """Word id of every descriptor row: descend from the root to the nearest child centre at each level."""
        x = as_storage(descriptors, self.kind)
        if x.ndim != 2 or x.shape[1] != self.dim:
            raise ValueError(f"descriptors of shape {descriptors.shape} do not fit a vocabulary of "
                             f"{self.dim}-{'byte' if self.kind is DescriptorKind.BINARY else 'float'} rows")
        node = np.zeros(len(x), np.int64)
        active = np.arange(len(x))
        for _ in range(self.depth + 1):
            ch = self.children[node[active]]
            inner = ch[:, 0] >= 0
            active, ch = active[inner], ch[inner]
            if len(active) == 0:
                break
            d = batched_distances(self.kind, x[active], self.centres[np.maximum(ch, 0)])
            d[ch < 0] = np.inf
            node[active] = ch[np.arange(len(active)), np.argmin(d, axis=1)]
        return self.word[node].astype(np.int64)

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        return {f"{prefix}centres": self.centres, f"{prefix}children": self.children, f"{prefix}word": self.word}

    def meta(self) -> dict:
        return {"kind": self.kind.value, "k": self.k, "depth": self.depth}

    @classmethod
    def from_arrays(cls, meta: dict, arrays: dict[str, np.ndarray], prefix: str = "") -> "VocabularyTree":
        """A vocabulary from its file arrays; anything inconsistent raises VocabFileError."""
        names = [f"{prefix}{n}" for n in ("children", "word", "centres")]
        if not isinstance(meta, dict) or any(n not in arrays for n in names):
            raise VocabFileError(f"vocabulary arrays or description missing ({', '.join(names)})")
        children, word, centres = (arrays[n] for n in names)
        k, depth, kind = meta.get("k"), meta.get("depth"), meta.get("kind")
        if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in (k, depth)):
            raise VocabFileError(f"vocabulary k={k!r} L={depth!r}: expected positive integers")
        if kind not in [m.value for m in DescriptorKind]:
            raise VocabFileError(f"unknown descriptor kind {kind!r}")
        want = np.uint8 if DescriptorKind(kind) is DescriptorKind.BINARY else np.float32
        if (children.ndim != 2 or word.ndim != 1 or centres.ndim != 2 or len(centres) == 0
                or not np.issubdtype(children.dtype, np.signedinteger)
                or not np.issubdtype(word.dtype, np.signedinteger) or centres.dtype != want):
            raise VocabFileError("vocabulary arrays have the wrong types or dimensions")
        if centres.shape[1] == 0:    # rows of no bytes would reach the distance kernels as empty words
            raise VocabFileError("vocabulary centres have width 0 (field 'centres' shape)")
        if not (len(children) == len(word) == len(centres)) or children.shape[1] != meta["k"]:
            raise VocabFileError("vocabulary arrays have inconsistent shapes")
        if (children.max(initial=-1) >= len(children) or children.min(initial=-1) < -1
                or (word >= 0).sum() != word.max(initial=-1) + 1):
            raise VocabFileError("vocabulary arrays are inconsistent (child or word ids out of range)")
        return cls(DescriptorKind(meta["kind"]), int(meta["k"]), int(meta["depth"]), centres, children, word)


def build_tree(descriptors: np.ndarray, k: int, depth: int, seed: int = 0, iters: int = 10,
               max_train: int | None = None, restarts: int = 1) -> VocabularyTree:
    """Build a vocabulary from training descriptors (binary uint8 rows or float rows). With more than `max_train`
    rows, a seeded random subsample of that size is clustered. `restarts` k-means++ runs per node, keeping the
    one of lowest inertia.

    The tree grows level by level: all nodes of a level are clustered together (kmeans.grouped_kmeans), with the
    level's draws from a generator seeded by (seed, level). A node stops splitting at depth L, when it holds one
    row, or when its rows all coincide; a node of at most k distinct rows gets one child per distinct row (k-means++
    seeds exactly those), as in DBoW2."""
    kind = kind_of(descriptors)
    x = as_storage(descriptors, kind)
    if x.ndim != 2 or len(x) == 0:
        raise ValueError("cannot build a vocabulary from zero descriptors")
    if max_train is not None and len(x) > max_train:
        pick = np.sort(np.random.default_rng([seed, 0x7EA1]).choice(len(x), max_train, replace=False))
        x = x[pick]
    new_centres: list[np.ndarray] = [np.zeros((1, x.shape[1]), x.dtype)]
    parents: list[np.ndarray] = [np.full(1, -1, np.int64)]
    n_nodes = 1
    rows = np.arange(len(x))               # rows still being split, sorted by node
    node = np.zeros(len(x), np.int64)      # their node
    for level in range(depth):
        ids, inverse, counts = np.unique(node, return_inverse=True, return_counts=True)
        splittable = counts >= 2
        if not splittable.any():
            break
        keep = splittable[inverse]
        rows, ids, group = rows[keep], ids[splittable], np.cumsum(splittable)[inverse[keep]] - 1
        labels, c, used = grouped_kmeans(kind, x[rows], group, len(ids), k, np.random.default_rng([seed, level]),
                                         iters, restarts)
        split = used.sum(axis=1) >= 2    # a node whose rows all fell in one cluster (all equal) stays a leaf
        made = used & split[:, None]
        child = np.full(made.shape, -1, np.int64)
        child[made] = n_nodes + np.arange(int(made.sum()))   # breadth-first ids: by parent, then by cluster
        new_centres.append(c[made])
        parents.append(np.repeat(ids, made.sum(axis=1)))
        n_nodes += int(made.sum())
        node = child[group, labels]
        keep = node >= 0
        rows, node = rows[keep], node[keep]
        order = np.argsort(node, kind="stable")
        rows, node = rows[order], node[order]
        if len(rows) == 0:
            break
    centres = np.concatenate(new_centres)
    parent = np.concatenate(parents)
    child_table = np.full((n_nodes, k), -1, np.int32)
    ch = np.arange(1, n_nodes)
    p = parent[1:]
    # children of a parent have consecutive ids: slot = id - first child id of that parent
    first = np.full(n_nodes, n_nodes, np.int64)
    np.minimum.at(first, p, ch)
    child_table[p, ch - first[p]] = ch
    leaves = child_table[:, 0] < 0
    word = np.full(n_nodes, -1, np.int32)
    word[leaves] = np.arange(int(leaves.sum()), dtype=np.int32)
    return VocabularyTree(kind, k, depth, centres, child_table, word)


VOCAB_FILE_KIND = "vslam-vocabulary"


def save_vocabulary(path, tree: VocabularyTree, info: dict | None = None) -> None:
    """Write one vocabulary to a compact binary file (see fileformat); `info` is free metadata (e.g. params)."""
    save_arrays(path, {"kind": VOCAB_FILE_KIND, "tree": tree.meta(), "info": info or {}}, tree.to_arrays())


def load_vocabulary(path) -> tuple[VocabularyTree, dict]:
    """Read a vocabulary written by save_vocabulary -> (tree, info)."""
    meta, arrays = load_arrays(path)
    if meta.get("kind") != VOCAB_FILE_KIND:
        raise VocabFileError(f"{path}: not a vocabulary file (kind {meta.get('kind')!r})")
    try:
        tree = VocabularyTree.from_arrays(meta.get("tree"), arrays)
    except VocabFileError as exc:
        raise VocabFileError(f"{path}: {exc}") from None
    info = meta.get("info", {})
    return tree, info if isinstance(info, dict) else {}
