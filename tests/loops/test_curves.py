"""ROC, precision-recall and confusion counts (loops.curves), shared by every recogniser's evaluation."""
import numpy as np
import pytest

from loops.curves import auc, confusion, pr_curve, roc_curve, tpr_at_fpr


def test_auc_matches_the_rank_statistic():
    rng = np.random.default_rng(5)
    s = rng.integers(0, 8, 300).astype(float)
    y = rng.random(300) < 0.3
    s[y] += 2
    pos, neg = s[y], s[~y]
    brute = ((pos[:, None] > neg[None, :]).sum() + 0.5 * (pos[:, None] == neg[None, :]).sum()) / (len(pos) * len(neg))
    assert auc(s, y) == pytest.approx(brute)
    assert auc([3, 4, 1, 2], [1, 1, 0, 0]) == 1.0
    assert auc([1, 2, 3, 4], [1, 1, 0, 0]) == 0.0
    fpr, tpr, thr = roc_curve([5, 5, 5, 5], [1, 0, 1, 0])
    assert fpr.tolist() == [0, 1] and tpr.tolist() == [0, 1]
    with pytest.raises(ValueError, match="both matched"):
        auc([1, 2], [1, 1])


def test_tpr_at_fpr_takes_the_lowest_threshold_within_the_budget():
    s = np.array([0.9, 0.8, 0.7, 0.6, 0.5])
    y = np.array([1, 1, 0, 1, 0])
    assert tpr_at_fpr(s, y, 0.0) == (pytest.approx(2 / 3), 0.8)
    assert tpr_at_fpr(s, y, 0.5) == (1.0, 0.6)


def test_top1_precision_recall():
    pr = pr_curve(np.array([0.9, 0.8, -np.inf, 0.7]), np.array([True, False, False, True]))
    assert pr.precision.tolist() == [1.0, 0.5, pytest.approx(2 / 3)]
    assert pr.recall.tolist() == [0.25, 0.25, 0.5]
    assert pr.average_precision == pytest.approx((1.0 + 2 / 3) / 4)


def test_confusion_counts_and_their_empty_cases():
    c = confusion([True, True, False, True], [True, False, True, True])
    assert (c.true_positives, c.false_positives, c.positives) == (2, 1, 3)
    assert c.precision == pytest.approx(2 / 3) and c.recall == pytest.approx(2 / 3)
    none = confusion([False, False], [False, False])
    assert np.isnan(none.precision) and np.isnan(none.recall)
