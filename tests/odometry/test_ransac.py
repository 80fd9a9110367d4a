"""The shared RANSAC loop (odometry.shared.ransac): sampling, batched consensus, stopping, refits."""
import numpy as np

from odometry.shared.ransac import (
    all_pairs,
    find_consensus,
    iterations_needed,
    refine_iteratively,
    refit_if_not_worse,
    sample_pairs,
    sample_subsets,
)


def test_samples_are_distinct_and_reproducible():
    for cyclic in (False, True):
        i, j = sample_pairs(np.random.default_rng(3), 7, 500, cyclic=cyclic)
        assert np.all(i != j) and i.min() >= 0 and max(i.max(), j.max()) <= 6
        i2, j2 = sample_pairs(np.random.default_rng(3), 7, 500, cyclic=cyclic)
        assert np.array_equal(i, i2) and np.array_equal(j, j2)
    s = sample_subsets(np.random.default_rng(0), 50, 6, 3)
    assert s.shape == (50, 3) and all(len(set(r)) == 3 for r in s.tolist())
    a, b = all_pairs(4)
    assert list(zip(a.tolist(), b.tolist())) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]


def test_iterations_needed():
    assert iterations_needed(1.0, 2, 0.99, 17) == 17                    # a perfect consensus: stop now
    assert iterations_needed(0.5, 2, 0.99, 0) == 17                     # log(0.01) / log(0.75) = 16.0...
    assert iterations_needed(0.1, 3, 0.99, 0) > iterations_needed(0.1, 2, 0.99, 0)


def _line_problem():
    """y = 2 x + 1 on 30 points, 10 outliers; hypotheses are 2-point lines."""
    rng = np.random.default_rng(1)
    x = rng.uniform(0, 10, 40)
    y = 2 * x + 1 + rng.normal(0, 0.01, 40)
    y[:10] = rng.uniform(-20, 20, 10)
    return x, y


def test_consensus_finds_the_line_and_refits_it():
    x, y = _line_problem()
    rng = np.random.default_rng(0)

    def draw(k):
        i, j = sample_pairs(rng, len(x), k)
        slope = (y[j] - y[i]) / (x[j] - x[i])
        return slope, y[i] - slope * x[i]

    def evaluate(h):
        inl = np.abs(h[0][:, None] * x[None] + h[1][:, None] - y[None]) < 0.1
        return inl.sum(1), inl

    best = find_consensus(draw, evaluate, 400, batch=16, confidence=0.999, n_data=len(x))
    assert best is not None and best.score == 30 and best.drawn < 400        # stopped early
    assert np.array_equal(best.inliers, np.arange(40) >= 10)

    def refit(m):
        a, b = np.polyfit(x[m], y[m], 1)
        return (a, b), np.abs(a * x + b - y) < 0.1

    (a, b), mask = refit_if_not_worse(best.inliers, refit, np.count_nonzero)
    assert abs(a - 2) < 0.01 and abs(b - 1) < 0.05 and mask.sum() == 30
    assert refit_if_not_worse(best.inliers, lambda m: None, np.count_nonzero) is None   # implausible refit

    model, inl = refine_iteratively((0.0, 0.0), lambda h: np.abs(h[0] * x + h[1] - y) < 0.1,
                                    lambda m: tuple(np.polyfit(x[m], y[m], 1)), 3, 2, len(x))
    assert not inl.any() and model == (0.0, 0.0)                            # nothing near y = 0: unchanged


def test_nothing_beats_the_bar():
    assert find_consensus(lambda k: np.zeros(k), lambda h: (np.ones(len(h)), np.ones((len(h), 3), bool)), 10,
                          better_than=1) is None
    assert find_consensus(lambda k: np.zeros(0), lambda h: (np.zeros(0), np.zeros((0, 3), bool)), 10) is None
