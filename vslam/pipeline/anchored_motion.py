"""Relative motion between two keyframes through the loops already accepted: the motion gate's odometry once the map
has been closed.

Along the VO chain alone, the uncertainty between a candidate of the first lap and a query of the second grows with
the whole lap (drift biases add up), so on a periodic floor a candidate one tile period away from the truth passes
the gate. Once a loop near both ends has been accepted, the path candidate -> (VO) -> that loop's match ->
(loop) -> that loop's query -> (VO) -> query is short: its uncertainty is that of two short VO stretches and one
loop fit, a few centimetres instead of decimetres, and an aliased candidate no longer fits.

This is the closed map's estimate of the relative pose (what the optimised graph says between the two keyframes)
with a conservative covariance: the best single path through one accepted loop, not the graph's marginal (which
would also use every parallel path and be tighter). Loops the back end rejected are never used as anchors.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from odometry.shared.pose_covariance import between_with_covariance, compose_with_covariance
from odometry.shared.poses import wrap_angle

# chain(a, b) for keys a <= b: between(pose a, pose b) along the odometry chain and its covariance
Chain = Callable[[int, int], tuple[np.ndarray, np.ndarray]]


@dataclass(frozen=True)
class Anchor:
    """An accepted loop: `delta` = pose of keyframe `query` in the frame of keyframe `match`, with its covariance."""

    match: int
    query: int
    delta: np.ndarray
    covariance: np.ndarray


def chain_any(chain: Chain, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """between(pose a, pose b) along the chain for keys in either order."""
    if a <= b:
        return chain(a, b)
    rel, cov = chain(b, a)
    return between_with_covariance(rel, cov, np.zeros(3), np.zeros((3, 3)))   # inverse(rel)


def position_variance(cov: np.ndarray) -> float:
    return float(cov[0, 0] + cov[1, 1])


def through(chain: Chain, a: int, b: int, x: Anchor, unscaled: Chain | None = None,
            scale_fraction: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """between(pose a, pose b) along a -> (chain) -> x.match -> (loop x) -> x.query -> (chain) -> b.

    With `unscaled` (the chain without its scale-error term) and `scale_fraction` (that term, m/m): the scale error
    is one bias for both stretches, so it moves b by the fraction of their net displacement; on a revisit the two
    stretches run over the same floor in opposite senses and it largely cancels (treated as independent, it would
    count twice)."""
    if unscaled is None:
        rel, cov = compose_with_covariance(*chain_any(chain, a, x.match), x.delta, x.covariance)
        return compose_with_covariance(rel, cov, *chain_any(chain, x.query, b))
    r1, c1 = chain_any(unscaled, a, x.match)
    m, cm = compose_with_covariance(r1, c1, x.delta, x.covariance)
    r2, c2 = chain_any(unscaled, x.query, b)
    rel, cov = compose_with_covariance(m, cm, r2, c2)
    c, s = np.cos(m[2]), np.sin(m[2])
    net = r1[:2] + np.array([c * r2[0] - s * r2[1], s * r2[0] + c * r2[1]])
    sd = scale_fraction * float(np.hypot(*net))
    return rel, cov + np.diag([sd ** 2, sd ** 2, 0.0])


def agree(chain: Chain, x: Anchor, y: Anchor, chi2: float, unscaled: Chain | None = None,
          scale_fraction: float = 0.0) -> bool:
    """Do loops x and y put the camera at the same place? x's own measurement against the path through y, when
    that path is more certain than the chain between x's two keyframes (else they are too far apart to tell)."""
    if x.match > x.query:
        return False
    rel, cov = through(chain, x.match, x.query, y, unscaled, scale_fraction)
    if position_variance(cov) >= position_variance(chain(x.match, x.query)[1]):
        return False
    r = np.asarray(x.delta, float) - rel
    r[2] = wrap_angle(r[2])
    return float(r @ np.linalg.solve(cov + x.covariance + np.eye(3) * 1e-12, r)) <= chi2


class AnchoredMotion:
    """`relative(a, b)` for the motion gate: the VO chain, or the path through one accepted loop when that is more
    certain (smaller position variance). `anchors()` gives the loops usable now; `keys` the keyframe keys in order
    (to rank anchors by how many keyframes of VO their path needs); `search` how many anchors, nearest first, are
    evaluated in full; `unscaled` and `scale_fraction` as in `through`."""

    def __init__(self, chain: Chain, anchors: Callable[[], Sequence[Anchor]], keys: Callable[[], Sequence[int]],
                 search: int = 4, unscaled: Chain | None = None, scale_fraction: float = 0.0):
        self.chain = chain
        self.unscaled = unscaled
        self.scale_fraction = float(scale_fraction)
        self.anchors = anchors
        self.keys = keys
        self.search = int(search)
        self.used: dict[tuple[int, int], Anchor | None] = {}   # which anchor each relative motion went through

    def __call__(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        best = self.chain(a, b)
        best_anchor = None
        anchors = list(self.anchors())
        if anchors and self.search > 0:
            keys = np.asarray(self.keys())

            def pos(k: int) -> int:   # index of a key among the keyframes
                return int(np.searchsorted(keys, k))
            ia, ib = pos(a), pos(b)
            steps = [abs(ia - pos(x.match)) + abs(ib - pos(x.query)) for x in anchors]
            for j in np.argsort(steps, kind="stable")[:self.search]:
                x = anchors[int(j)]
                if steps[int(j)] >= abs(ib - ia):
                    break   # no shorter than the direct chain
                rel, cov = through(self.chain, a, b, x, self.unscaled, self.scale_fraction)
                if position_variance(cov) < position_variance(best[1]):
                    best, best_anchor = (rel, cov), x
        self.used[(int(a), int(b))] = best_anchor
        return best
