import numpy as np
import pytest

from loops.vocab import full_ranks, mu1, mu2, pr_curve, recall_at, repeatability


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


def test_recall_pr_and_repeatability():
    assert recall_at(np.array([3, 1, 2]), [1], 1) is False
    assert recall_at(np.array([3, 1, 2]), [1], 2) is True
    assert recall_at(np.array([], np.int64), [1], 5) is False
    pr = pr_curve(np.array([0.9, 0.8, -np.inf, 0.7]), np.array([True, False, False, True]))
    assert pr.precision.tolist() == [1.0, 0.5, pytest.approx(2 / 3)]
    assert pr.recall.tolist() == [0.25, 0.25, 0.5]
    assert pr.average_precision == pytest.approx((1.0 + 2 / 3) / 4)
    top1 = np.array([[0, 5, 7], [0, 5, 8], [0, 6, 9], [0, 5, 9]])
    assert repeatability(top1) == pytest.approx((1.0 + 0.75 + 0.5) / 3)
