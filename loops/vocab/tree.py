"""Hierarchical vocabulary tree (Nister & Stewenius 2006): k-means++ with branch factor k, recursively, to depth L.

The tree is stored as flat arrays (node 0 = root), so it serialises to one contiguous block and a query descends
it level by level for all descriptors at once:

    centres  (n_nodes, D)  uint8 bit rows (binary kind) or float32 (float kind); the root's row is unused
    children (n_nodes, k)  int32 child node ids, -1 where absent; a node without children is a leaf = a word
    word     (n_nodes,)    int32 word id of each leaf, -1 for inner nodes

Like DBoW2, a node with at most k descriptors gets one child per distinct descriptor, so leaves can sit above
depth L. Each node's k-means uses its own generator seeded with (seed, node id): the same descriptors and seed
give the same tree whatever the order in which nodes are processed.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .kinds import DescriptorKind, as_storage, batched_distances, kind_of
from .kmeans import kmeans


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
        children = arrays[f"{prefix}children"]
        word = arrays[f"{prefix}word"]
        centres = arrays[f"{prefix}centres"]
        if not (len(children) == len(word) == len(centres)) or children.shape[1] != meta["k"]:
            raise ValueError("vocabulary arrays have inconsistent shapes")
        if children.max(initial=-1) >= len(children) or (word >= 0).sum() != word.max(initial=-1) + 1:
            raise ValueError("vocabulary arrays are inconsistent (child or word ids out of range)")
        return cls(DescriptorKind(meta["kind"]), int(meta["k"]), int(meta["depth"]), centres, children, word)


def build_tree(descriptors: np.ndarray, k: int, depth: int, seed: int = 0, iters: int = 10,
               max_train: int | None = None) -> VocabularyTree:
    """Build a vocabulary from training descriptors (binary uint8 rows or float rows). With more than `max_train`
    rows, a seeded random subsample of that size is clustered."""
    kind = kind_of(descriptors)
    x = as_storage(descriptors, kind)
    if x.ndim != 2 or len(x) == 0:
        raise ValueError("cannot build a vocabulary from zero descriptors")
    if max_train is not None and len(x) > max_train:
        pick = np.sort(np.random.default_rng([seed, 0x7EA1]).choice(len(x), max_train, replace=False))
        x = x[pick]
    centres = [np.zeros(x.shape[1], x.dtype)]
    children: list[list[int]] = [[]]
    queue = deque([(0, np.arange(len(x)), 0)])
    while queue:
        node, idx, level = queue.popleft()
        if level >= depth or len(idx) <= 1:
            continue
        if len(idx) <= k:
            # DBoW2: few descriptors -> each distinct one becomes a child (and a word)
            first: dict[bytes, int] = {}
            for i in range(len(idx)):
                first.setdefault(x[idx[i]].tobytes(), i)
            groups = [(x[idx[i]], idx[i:i + 1]) for i in sorted(first.values())]
            if len(groups) == 1:
                continue
        else:
            labels, c = kmeans(kind, x[idx], k, np.random.default_rng([seed, node]), iters)
            if len(c) == 1:
                continue  # all descriptors identical: this node stays a leaf
            order = np.argsort(labels, kind="stable")
            bounds = np.cumsum(np.bincount(labels, minlength=len(c)))[:-1]
            groups = list(zip(c, np.split(idx[order], bounds)))
        for centre, members in groups:
            child = len(centres)
            centres.append(centre)
            children.append([])
            children[node].append(child)
            queue.append((child, members, level + 1))
    child_table = np.full((len(children), k), -1, np.int32)
    for i, ch in enumerate(children):
        child_table[i, :len(ch)] = ch
    leaves = child_table[:, 0] < 0
    word = np.full(len(children), -1, np.int32)
    word[leaves] = np.arange(int(leaves.sum()), dtype=np.int32)
    return VocabularyTree(kind, k, depth, np.stack(centres), child_table, word)


VOCAB_FILE_KIND = "vslam-vocabulary"


def save_vocabulary(path, tree: VocabularyTree, info: dict | None = None) -> None:
    """Write one vocabulary to a compact binary file (see fileformat); `info` is free metadata (e.g. params)."""
    from .fileformat import save_arrays

    save_arrays(path, {"kind": VOCAB_FILE_KIND, "tree": tree.meta(), "info": info or {}}, tree.to_arrays())


def load_vocabulary(path) -> tuple[VocabularyTree, dict]:
    """Read a vocabulary written by save_vocabulary -> (tree, info)."""
    from .fileformat import load_arrays

    meta, arrays = load_arrays(path)
    if meta.get("kind") != VOCAB_FILE_KIND:
        raise ValueError(f"{path}: not a vocabulary file (kind {meta.get('kind')!r})")
    return VocabularyTree.from_arrays(meta["tree"], arrays), meta.get("info", {})
