"""ROC curve and area under it, for scoring matched / unmatched pairs (paper §4.1, Fig. 4)."""
from __future__ import annotations

import numpy as np

from loops.errors import LoopsError


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
