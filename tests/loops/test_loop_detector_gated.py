"""Acceptance below the verifier's threshold when the motion gate confirms the loop (issue 13, slow revisits: the
demo's closing keyframes verify with P(loop|score) 0.85-0.985, below the P = 1 threshold, and were refused)."""
from __future__ import annotations

from loops.loop_detector import DatabaseParams, LoopDetector
from loops.recognition import Verification
from tests.loops._fakes import SamePlace


class ByObservation:
    """The verification of a pair is the observation of the candidate (a Verification)."""

    def verify(self, query, candidate):
        return candidate


def below(p: float = 0.9, overlap: float = 0.5) -> Verification:
    return Verification(False, 15.0, 40, overlap=overlap, probability=p)


def above() -> Verification:
    return Verification(True, 30.0, 80, overlap=0.6, probability=1.0)


def run(observations, gate, p=0.5, query_key=10):
    det = LoopDetector(SamePlace(), ByObservation(), DatabaseParams(exclude_recent=0, gated_min_probability=p), gate=gate)
    for k, obs in enumerate(observations):
        det.add(k, obs)
    return det, det.query(None, key=query_key)


def test_a_likely_loop_below_threshold_is_accepted_when_the_gate_confirms_it():
    _, out = run([below()], gate=lambda c, q, v: True)
    assert [c.accepted for c in out] == [True]
    assert out[0].motion_consistent is True


def test_below_threshold_needs_the_gate_the_probability_and_the_overlap():
    assert not run([below()], gate=lambda c, q, v: False)[1][0].accepted      # gate refuses
    assert not run([below()], gate=None)[1][0].accepted                       # no gate: the threshold decides
    assert not run([below(p=0.4)], gate=lambda c, q, v: True)[1][0].accepted  # less likely than not
    assert not run([below(overlap=0.25)], gate=lambda c, q, v: True)[1][0].accepted   # not a loop's overlap
    assert not run([below()], gate=lambda c, q, v: True, p=None)[1][0].accepted       # option off


def test_after_a_look_alike_only_the_threshold_admits_loops():
    # key 0 passes the verifier but the gate puts it elsewhere: the floor repeats
    det = LoopDetector(SamePlace(), ByObservation(), DatabaseParams(exclude_recent=0, gated_min_probability=0.5),
                       gate=lambda c, q, v: c != 0)
    det.add(0, above())
    det.add(1, below())
    first = {c.key: c.accepted for c in det.query(None, key=10)}
    assert det.lookalikes == 1 and first[0] is False
    # the same likely candidate that would pass on a floor without look-alikes is no longer admitted below threshold
    second = {c.key: c.accepted for c in det.query(None, key=11)}
    assert second[1] is False
    fresh = LoopDetector(SamePlace(), ByObservation(), DatabaseParams(exclude_recent=0, gated_min_probability=0.5),
                         gate=lambda c, q, v: c != 0)
    fresh.add(1, below())
    assert [c.accepted for c in fresh.query(None, key=11)] == [True]
