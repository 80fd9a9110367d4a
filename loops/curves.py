"""Scoring a recogniser's decisions against ground truth: ROC curve and its area, true-positive rate at a
false-positive budget, precision-recall of accepting each query's best candidate, and plain confusion counts.

Scores are "higher = more alike"; a pair or query is accepted when its score >= the threshold.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from loops.errors import LoopsError


# ---------------------------------------------------------------------------------------------- ROC
def _check(scores: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    s = np.asarray(scores, dtype=np.float64).ravel()
    y = np.asarray(labels).ravel().astype(bool)
    if s.shape != y.shape:
        raise LoopsError(f"scores ({s.size}) and labels ({y.size}) differ in length")
    if not np.all(np.isfinite(s)):
        raise LoopsError("scores must be finite")
    if y.all() or not y.any():
        raise LoopsError("an ROC needs both matched (label 1) and unmatched (label 0) pairs")
    return s, y


def roc_curve(scores: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(false-positive rate, true-positive rate, threshold) as the threshold falls; a pair is called matched
    when score >= threshold. Starts at (0, 0, +inf) and ends at (1, 1); tied scores form one step."""
    s, y = _check(scores, labels)
    order = np.argsort(-s, kind="stable")
    s, y = s[order], y[order]
    last_of_group = np.r_[np.flatnonzero(np.diff(s)), s.size - 1]
    tp = np.cumsum(y)[last_of_group]
    fp = np.cumsum(~y)[last_of_group]
    tpr = np.r_[0.0, tp / y.sum()]
    fpr = np.r_[0.0, fp / (~y).sum()]
    return fpr, tpr, np.r_[np.inf, s[last_of_group]]


def auc(scores: np.ndarray, labels: np.ndarray) -> float:
    """Area under the ROC curve: the probability a matched pair outscores an unmatched one (ties count half)."""
    fpr, tpr, _ = roc_curve(scores, labels)
    return float(np.sum(np.diff(fpr) * (tpr[1:] + tpr[:-1]) / 2.0))


def tpr_at_fpr(scores: np.ndarray, labels: np.ndarray, max_fpr: float) -> tuple[float, float]:
    """Best true-positive rate with false-positive rate <= max_fpr, and the lowest threshold achieving it."""
    fpr, tpr, thr = roc_curve(scores, labels)
    ok = np.flatnonzero(fpr <= max_fpr)
    k = ok[np.argmax(tpr[ok])]
    return float(tpr[k]), float(thr[k])


# ---------------------------------------------------------------------------------------------- precision-recall
@dataclass(frozen=True)
class PRCurve:
    precision: np.ndarray
    recall: np.ndarray
    thresholds: np.ndarray
    average_precision: float


def pr_curve(top_scores: np.ndarray, top_correct: np.ndarray) -> PRCurve:
    """Precision-recall of accepting each query's top-1 candidate when its score passes a threshold. Queries
    without any candidate carry score -inf (never accepted) and still count in the recall denominator."""
    s = np.asarray(top_scores, float)
    c = np.asarray(top_correct, bool)
    n = len(s)
    order = np.argsort(-s, kind="stable")
    s, c = s[order], c[order]
    valid = np.isfinite(s)
    s, c = s[valid], c[valid]
    tp = np.cumsum(c)
    k = np.arange(1, len(s) + 1)
    precision = tp / k
    recall = tp / max(n, 1)
    # average precision: precision summed at each correct acceptance, over all queries
    ap = float(precision[c].sum() / max(n, 1))
    return PRCurve(precision, recall, s, ap)


@dataclass(frozen=True)
class Confusion:
    """Counts of accepted / truly positive items at one operating point."""

    true_positives: int
    false_positives: int
    positives: int                  # truly positive items, accepted or not

    @property
    def precision(self) -> float:
        """True positives among the accepted (nan when nothing was accepted)."""
        accepted = self.true_positives + self.false_positives
        return self.true_positives / accepted if accepted else float("nan")

    @property
    def recall(self) -> float:
        """Accepted among the true positives (nan when there are none)."""
        return float(self.true_positives / self.positives) if self.positives else float("nan")


def confusion(accepted: np.ndarray, positive: np.ndarray) -> Confusion:
    """Confusion counts of boolean decisions against boolean truth (same length)."""
    a = np.asarray(accepted, bool)
    y = np.asarray(positive, bool)
    return Confusion(int(np.sum(a & y)), int(np.sum(a & ~y)), int(y.sum()))
