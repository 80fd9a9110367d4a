import numpy as np
import pytest

from loops.vocab import full_ranks, mu1, mu2, recall_at, repeatability


def test_mu1_on_a_toy_ranking():
    ranked = np.array([4, 2, 0])               # 5 keys, keys 1 and 3 are not candidates
    assert mu1(ranked, [2], 5) == 2
    assert mu1(ranked, [0, 4], 5) == 1         # several true keys: the best-ranked counts
    assert mu1(ranked, [3], 5) == 4.5          # unranked keys tie for places 4 and 5
    assert full_ranks(ranked, 5).tolist() == [3, 4.5, 2, 4.5, 1]


def test_mu2_on_a_toy_ranking():
    ranked = np.array([4, 2, 0])
    # true key 2; the key-to-key similarities z_l(I*_2): itself 1.0, key 0 looks like it (0.5), key 3 a bit (0.5)
    z = np.array([0.5, 0.0, 1.0, 0.5, 0.0])
    # (0.5 * 3 + 1.0 * 2 + 0.5 * 4.5) / 2 = 2.875
    assert mu2(ranked, z, 5) == pytest.approx(2.875)
    # a true key resembling nothing else: mu2 = mu1
    assert mu2(ranked, np.array([0, 0, 1.0, 0, 0]), 5) == mu1(ranked, [2], 5)
    with pytest.raises(ValueError):
        mu2(ranked, np.zeros(5), 5)


def test_recall_and_repeatability():
    assert recall_at(np.array([3, 1, 2]), [1], 1) is False
    assert recall_at(np.array([3, 1, 2]), [1], 2) is True
    assert recall_at(np.array([], np.int64), [1], 5) is False
    top1 = np.array([[0, 5, 7], [0, 5, 8], [0, 6, 9], [0, 5, 9]])
    assert repeatability(top1) == pytest.approx((1.0 + 0.75 + 0.5) / 3)


def test_mu2_with_a_near_duplicate_key_by_hand():
    """Key 1 is a near-duplicate of key 0 (5 of their 6 words shared), key 2 is unrelated, key 3 shares 4 words with
    key 0 (below the 5-word candidate rule). Every word occurs once per image, so with idf = log(4 / n_i):
    words 0-3 are in 3 keys (a = log 4/3), word 4 in 2 (b = log 2), words 5 and 6 in one (log 4 = 2b). Key 0's
    L1-normalised TF-IDF vector is (a, a, a, a, b, 2b) / (4a + 3b), key 1's the same with word 6 instead of 5, and
    their chi-square similarity sum 2 v w / (v + w) over the shared words is (4a + b) / (4a + 3b)."""
    import math

    from loops.vocab import BowDatabase, Distance, VisualMemory, preset

    words = [np.array([0, 1, 2, 3, 4, 5]), np.array([0, 1, 2, 3, 4, 6]), np.array([7, 8, 9, 10, 11, 12]),
             np.array([0, 1, 2, 3, 13, 14])]
    db = BowDatabase.from_words(words, 15, Distance.CHI2)
    memory = VisualMemory(preset("paper"), ("k0", "k1", "k2", "k3"), (0.0,), (None,), (db,))
    a, b = math.log(4 / 3), math.log(2)
    z01 = (4 * a + b) / (4 * a + 3 * b)
    z = memory.key_similarity(0)
    # key 3 shares 4 < 5 words with key 0: no similarity at all, whatever its chi-square score would be
    assert z == pytest.approx([1.0, z01, 0.0, 0.0])
    # the query ranked the near-duplicate first, the true key 0 second, key 2 third; key 3 is unranked (rank 4)
    ranked = np.array([1, 0, 2])
    assert mu1(ranked, [0], 4) == 2
    # (1 * rank 2 + z01 * rank 1) / (1 + z01) = 1.64: mu2 < 2.5 although mu1 = 1 is missed
    assert mu2(ranked, z, 4) == pytest.approx((2 + z01) / (1 + z01))
    assert mu2(ranked, z, 4) < 2.5
    # a true key resembling no other key: mu2 falls back to mu1
    assert mu2(ranked, np.array([1.0, 0, 0, 0]), 4) == 2
    # true key first, its near-duplicate unranked (it takes the mean of ranks 3 and 4): (1 + 3.5 z01) / (1 + z01)
    assert mu2(np.array([0, 2]), z, 4) == pytest.approx((1 + 3.5 * z01) / (1 + z01))
