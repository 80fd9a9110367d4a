"""Key-image database: TF-IDF word histograms (eq. 1 of the paper), an inverted index, candidate restriction to
key images sharing at least `min_shared` words with the query, and the five histogram comparisons.

    v_i(I) = c_i(I) / c(I) * log(n / n_i)                                       (eq. 1)

c_i = descriptors of I in word i, c = all descriptors of I, n = key images, n_i = key images containing word i.
Vectors are then normalised (L1 or L2, depending on the comparison, see params.Distance). Every comparison is a
sum over the words both images contain, so a query touches only the inverted-index postings of its own words.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loops.errors import LoopsError

from .params import Distance


class EmptyMemoryError(LoopsError):
    """A visual memory without key images (or without any descriptor) cannot localise anything."""


@dataclass(frozen=True)
class Scores:
    """Candidate key images (indices) and their similarity in [0, 1], plus how many words each shares."""

    keys: np.ndarray
    scores: np.ndarray
    shared: np.ndarray


@dataclass(frozen=True)
class BowDatabase:
    n_words: int
    distance: Distance
    idf: np.ndarray            # (n_words,) log(n / n_i), 0 for words absent from every key image
    post_ptr: np.ndarray       # (n_words + 1,) inverted index in CSR form: postings of word w are
    post_img: np.ndarray       #   post_img[post_ptr[w]:post_ptr[w+1]] with normalised weights post_w[...]
    post_w: np.ndarray
    counts_ptr: np.ndarray     # (n_images + 1,) per-image word counts (what gets saved; the rest is derived)
    counts_word: np.ndarray
    counts_n: np.ndarray

    @property
    def n_images(self) -> int:
        return len(self.counts_ptr) - 1

    # ---- construction ---------------------------------------------------------------------------------------
    @classmethod
    def from_words(cls, words_per_image: list[np.ndarray], n_words: int, distance: Distance) -> "BowDatabase":
        """Build from the word ids of each key image's descriptors."""
        if len(words_per_image) == 0:
            raise EmptyMemoryError("the visual memory has no key images")
        ptr, cw, cn = [0], [], []
        for w in words_per_image:
            u, c = np.unique(np.asarray(w, np.int64), return_counts=True)
            cw.append(u)
            cn.append(c)
            ptr.append(ptr[-1] + len(u))
        return cls.from_counts(np.asarray(ptr, np.int64), np.concatenate(cw).astype(np.int32),
                               np.concatenate(cn).astype(np.int32), n_words, distance)

    @classmethod
    def from_counts(cls, counts_ptr: np.ndarray, counts_word: np.ndarray, counts_n: np.ndarray, n_words: int,
                    distance: Distance) -> "BowDatabase":
        distance = Distance(distance)
        n = len(counts_ptr) - 1
        if n <= 0:
            raise EmptyMemoryError("the visual memory has no key images")
        if len(counts_word) == 0:
            raise EmptyMemoryError("the visual memory's key images have no descriptors")
        if counts_word.max() >= n_words or counts_word.min() < 0:
            raise ValueError("word ids out of the vocabulary's range")
        img = np.repeat(np.arange(n), np.diff(counts_ptr))
        n_i = np.bincount(counts_word, minlength=n_words)
        idf = np.zeros(n_words)
        present = n_i > 0
        idf[present] = np.log(n / n_i[present])
        total = np.bincount(img, weights=counts_n, minlength=n)          # c(I)
        v = counts_n / total[img] * idf[counts_word]                    # eq. 1
        v = v / np.maximum(_group_norm(v, img, n, distance.norm)[img], 1e-300)
        order = np.lexsort((img, counts_word))                           # by word, then image
        post_ptr = np.concatenate(([0], np.cumsum(n_i))).astype(np.int64)
        return cls(n_words, distance, idf, post_ptr, img[order].astype(np.int32), v[order],
                   np.asarray(counts_ptr, np.int64), np.asarray(counts_word, np.int32), np.asarray(counts_n, np.int32))

    # ---- queries ------------------------------------------------------------------------------------------
    def query_vector(self, words: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sparse TF-IDF vector (word ids, normalised weights) of a query's descriptor words."""
        u, c = np.unique(np.asarray(words, np.int64), return_counts=True)
        if len(u) == 0:
            return u, np.zeros(0)
        v = c / c.sum() * self.idf[u]
        norm = np.abs(v).sum() if self.distance.norm == "l1" else np.sqrt((v * v).sum())
        return u, v / max(norm, 1e-300)

    def score(self, words: np.ndarray, min_shared: int = 5) -> Scores:
        """Similarity of a query (its descriptors' word ids) to every key image sharing >= min_shared words,
        sorted best first (ties: lower key index first)."""
        u, v = self.query_vector(words)
        starts, stops = self.post_ptr[u], self.post_ptr[u + 1]
        lens = stops - starts
        total = int(lens.sum())
        if total == 0:
            return Scores(np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64))
        # gather every posting of the query's words without a Python loop
        offs = np.repeat(starts - np.concatenate(([0], np.cumsum(lens)[:-1])), lens) + np.arange(total)
        img = self.post_img[offs]
        w = self.post_w[offs]
        q = np.repeat(v, lens)
        shared = np.bincount(img, minlength=self.n_images)
        s = np.bincount(img, weights=pair_terms(self.distance, q, w), minlength=self.n_images)
        s = finish_score(self.distance, s)
        keys = np.nonzero(shared >= min_shared)[0]
        order = np.lexsort((keys, -s[keys]))
        keys = keys[order]
        return Scores(keys, s[keys], shared[keys])

    def image_words(self, i: int) -> np.ndarray:
        """The word ids of key image i's descriptors (each repeated by its count), as stored."""
        sl = slice(self.counts_ptr[i], self.counts_ptr[i + 1])
        return np.repeat(self.counts_word[sl].astype(np.int64), self.counts_n[sl])

    def score_image(self, i: int, min_shared: int = 5) -> Scores:
        """Key image i, as stored, scored against every key image (itself included, with similarity 1)."""
        return self.score(self.image_words(i), min_shared)

    def to_arrays(self, prefix: str = "") -> dict[str, np.ndarray]:
        return {f"{prefix}counts_ptr": self.counts_ptr, f"{prefix}counts_word": self.counts_word,
                f"{prefix}counts_n": self.counts_n}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray], n_words: int, distance: Distance,
                    prefix: str = "") -> "BowDatabase":
        return cls.from_counts(arrays[f"{prefix}counts_ptr"], arrays[f"{prefix}counts_word"],
                               arrays[f"{prefix}counts_n"], n_words, distance)


def _group_norm(v: np.ndarray, group: np.ndarray, n: int, norm: str) -> np.ndarray:
    if norm == "l1":
        return np.bincount(group, weights=np.abs(v), minlength=n)
    return np.sqrt(np.bincount(group, weights=v * v, minlength=n))


def pair_terms(distance: Distance, q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per shared word contribution to the similarity (q, w: the two normalised weights)."""
    if distance is Distance.CHI2:
        den = q + w
        return np.divide(2.0 * q * w, den, out=np.zeros_like(den), where=den > 0)
    if distance is Distance.BHATTACHARYYA:
        return np.sqrt(q * w)
    if distance is Distance.L1:
        return np.minimum(q, w)
    return q * w  # DOT and L2 both start from the dot product of unit vectors


def finish_score(distance: Distance, s: np.ndarray) -> np.ndarray:
    if distance is Distance.L2:
        # |v - w|^2 = 2 - 2 v.w for unit vectors; 1 - |v - w| / sqrt(2) maps [0, sqrt(2)] onto [1, 0]
        return 1.0 - np.sqrt(np.maximum(1.0 - s, 0.0))
    return np.minimum(s, 1.0)


def similarity_dense(distance: Distance, a: np.ndarray, b: np.ndarray) -> float:
    """Reference implementation on dense, unnormalised non-negative vectors (for tests and checks): normalise, then
    apply each comparison's textbook formula."""
    distance = Distance(distance)
    na = a / (a.sum() if distance.norm == "l1" else np.linalg.norm(a))
    nb = b / (b.sum() if distance.norm == "l1" else np.linalg.norm(b))
    if distance is Distance.CHI2:
        den = na + nb
        chi2 = np.sum(np.divide((na - nb) ** 2, den, out=np.zeros_like(den), where=den > 0))
        return float(1.0 - chi2 / 2.0)
    if distance is Distance.BHATTACHARYYA:
        return float(np.sum(np.sqrt(na * nb)))
    if distance is Distance.L1:
        return float(1.0 - np.abs(na - nb).sum() / 2.0)
    if distance is Distance.DOT:
        return float(na @ nb)
    return float(1.0 - np.linalg.norm(na - nb) / np.sqrt(2.0))
