import math

import numpy as np
import pytest

from loops.vocab import BowDatabase, Distance, EmptyMemoryError, similarity_dense


def _vec(db, image):
    """Dense normalised vector of a key image, read back from the inverted index."""
    v = np.zeros(db.n_words)
    for w in range(db.n_words):
        sl = slice(db.post_ptr[w], db.post_ptr[w + 1])
        hit = db.post_img[sl] == image
        if hit.any():
            v[w] = db.post_w[sl][hit][0]
    return v


def test_tfidf_matches_a_hand_computed_case():
    words = [np.array([0, 0, 1, 2]), np.array([1, 3]), np.array([2, 2, 3, 4])]
    db = BowDatabase.from_words(words, 5, Distance.CHI2)
    l3, l15 = math.log(3), math.log(1.5)
    assert np.allclose(db.idf, [l3, l15, l15, l15, l3])
    raw0 = np.array([2 / 4 * l3, 1 / 4 * l15, 1 / 4 * l15, 0, 0])            # eq. 1 for image 0
    assert np.allclose(_vec(db, 0), raw0 / raw0.sum())                       # L1-normalised for chi2
    raw2 = np.array([0, 0, 2 / 4 * l15, 1 / 4 * l15, 1 / 4 * l3])
    assert np.allclose(_vec(db, 2), raw2 / raw2.sum())
    dot_db = BowDatabase.from_words(words, 5, Distance.DOT)
    assert np.allclose(_vec(dot_db, 0), raw0 / np.linalg.norm(raw0))        # L2-normalised for dot / L2
    u, v = db.query_vector(np.array([4, 4, 0]))
    assert u.tolist() == [0, 4] and np.allclose(v, np.array([1 / 3 * l3, 2 / 3 * l3]) / l3)


def test_a_word_in_every_key_image_carries_no_weight():
    db = BowDatabase.from_words([np.array([0, 1]), np.array([0, 2])], 3, Distance.CHI2)
    assert db.idf[0] == 0.0 and _vec(db, 0)[0] == 0.0


@pytest.mark.parametrize("distance", list(Distance))
def test_each_distance_matches_its_dense_formula(distance):
    rng = np.random.default_rng(1)
    n_words = 60
    keys = [rng.integers(0, n_words, rng.integers(20, 60)) for _ in range(12)]
    db = BowDatabase.from_words(keys, n_words, distance)
    query = np.concatenate([keys[3][:25], rng.integers(0, n_words, 15)])
    res = db.score(query, min_shared=1)
    qv = np.zeros(n_words)
    u, c = np.unique(query, return_counts=True)
    qv[u] = c / c.sum() * db.idf[u]
    for key, s in zip(res.keys, res.scores):
        kv = np.zeros(n_words)
        u, c = np.unique(keys[key], return_counts=True)
        kv[u] = c / c.sum() * db.idf[u]
        assert s == pytest.approx(similarity_dense(distance, qv, kv), abs=1e-9)
    assert res.keys[0] == 3                                  # the key the query was cut from wins
    assert np.all(np.diff(res.scores) <= 0)


def test_dense_formulas_on_a_hand_case():
    a, b = np.array([0.5, 0.5, 0.0]), np.array([0.5, 0.0, 0.5])
    assert similarity_dense(Distance.CHI2, a, b) == pytest.approx(0.5)    # chi2 = 0.25/0.5 * 2 = 1
    assert similarity_dense(Distance.L1, a, b) == pytest.approx(0.5)      # |a - b|_1 = 1
    assert similarity_dense(Distance.BHATTACHARYYA, a, b) == pytest.approx(0.5)
    assert similarity_dense(Distance.DOT, a, b) == pytest.approx(0.5)     # unit vectors at 60 degrees
    assert similarity_dense(Distance.L2, a, b) == pytest.approx(1 - 1 / math.sqrt(2))
    for d in Distance:
        assert similarity_dense(d, a, a) == pytest.approx(1.0)


def test_candidates_need_min_shared_words():
    keys = [np.arange(0, 10), np.arange(6, 16), np.arange(20, 30)]
    db = BowDatabase.from_words(keys, 40, Distance.CHI2)
    res = db.score(np.arange(0, 10), min_shared=5)
    assert res.keys.tolist() == [0] and res.shared.tolist() == [10]          # key 1 shares only 4 words
    assert db.score(np.arange(0, 10), min_shared=4).keys.tolist() == [0, 1]
    assert len(db.score(np.array([35, 36]), min_shared=1).keys) == 0        # words no key image has


def test_empty_memory_is_a_clear_error():
    with pytest.raises(EmptyMemoryError, match="no key images"):
        BowDatabase.from_words([], 10, Distance.CHI2)
    with pytest.raises(EmptyMemoryError, match="no descriptors"):
        BowDatabase.from_words([np.array([], np.int64)], 10, Distance.CHI2)
