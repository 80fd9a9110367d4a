"""The `pydbow` package behind the VisualMemory query interface, for `vslam bench localize`'s comparison."""
from __future__ import annotations

import numpy as np

from loops.vocab import Ranking


class PydbowMemory:
    """The `pydbow` package (PyPI, pure-Python DBoW) behind the VisualMemory query interface, fed with our
    descriptors. Its Vocabulary() runs ORB itself, so the tree is built with its own initialize_tree() on our
    descriptors instead; its k-means draws from numpy's global generator, which is seeded here. It has no notion of
    key-to-key similarity restricted to candidates (it scores every key; wrong keys ~0.5 on the pairs set), so mu2
    is not computed for it."""

    def __init__(self, key_descs: list[np.ndarray], key_names: list[str], params, k: int, depth: int,
                 max_train: int, seed: int = 0, replicate: int = 1):
        import dbow  # optional (the `bench` extra): imported only when the comparison runs

        self.dbow, self.params = dbow, params
        train = np.concatenate(key_descs)
        rng = np.random.default_rng(seed)
        if len(train) > max_train:
            train = train[np.sort(rng.choice(len(train), max_train, replace=False))]
        np.random.seed(seed)
        voc = dbow.Vocabulary.__new__(dbow.Vocabulary)
        voc.root_node = dbow.Node([dbow.ORB.from_cv_descriptor(x) for x in train])
        voc.words = [dbow.Word.from_node(n) for n in dbow.dbow.initialize_tree(voc.root_node, k, depth)]
        n_entries = len(key_descs) * replicate
        for w in voc.words:
            w.update_weight(n_entries)
        self.db = dbow.Database(voc)
        for d in key_descs:
            self.db.add(self._convert(d))
        # its query scores every database entry densely, whatever they hold: repeating the entries gives the query
        # cost of a database `replicate` times larger without paying its (Python) insertion again
        self.db.database = self.db.database * replicate
        self.db.descriptors = self.db.descriptors * replicate
        self.key_names = [f"{n}#{r}" if replicate > 1 else n for r in range(replicate) for n in key_names]
        self.n_words = len(voc.words)

    def _convert(self, descs: np.ndarray) -> list:
        return [self.dbow.ORB.from_cv_descriptor(x) for x in descs]

    def __len__(self) -> int:
        return len(self.key_names)

    def query_descriptors(self, descs: np.ndarray) -> Ranking:
        with np.errstate(invalid="ignore", divide="ignore"):
            scores = np.nan_to_num(np.asarray(self.db.query(self._convert(descs)), float), nan=0.0)
        keys = np.lexsort((np.arange(len(scores)), -scores))
        return Ranking(keys, scores[keys], np.zeros(len(keys), np.int64))
