"""The place-recognition contract (loops.recognition), one suite over the three recognisers: cdvs compact
descriptors, the vocabulary tree (with the shipped floor vocabulary) and 1D SURF horizons (per pair, and packed:
preset fast)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import pytest

from loops.cdvs.recognizer import CdvsRecognizer, CdvsVerifier
from loops.horizon import HorizonParams
from loops.horizon.recognizer import HorizonRecognizer, HorizonVerifier
from loops.recognition import Ranked, Recognizer, Verification, Verifier
from loops.vocab.floor_vocabulary import load_floor_vocabulary
from loops.vocab.recognizer import VocabRecognizer, VocabVerifier

from .test_cdvs_match import view
from .test_horizon import horizon_image
from .test_horizon import texture as skyline


@dataclass
class Case:
    """A recogniser, its verifier, and images: a place, the place seen again, an unrelated place, distractors."""

    make: Callable[[], tuple[Recognizer, Verifier]]
    place: np.ndarray
    again: np.ndarray
    unrelated: np.ndarray
    distractors: list[np.ndarray]


def _cdvs() -> Case:
    return Case(lambda: (CdvsRecognizer(4), CdvsVerifier(4)), view(700, 600), view(760, 630, angle=12),
                view(1450, 1100), [view(300 + 180 * k, 300) for k in range(3)])


def _vocab() -> Case:
    def make():
        tree, params = load_floor_vocabulary()
        return VocabRecognizer(tree, params), VocabVerifier()
    return Case(make, view(700, 600), view(760, 630, angle=12), view(1450, 1100),
                [view(300 + 180 * k, 300) for k in range(3)])


def _horizon() -> Case:
    return Case(lambda: (HorizonRecognizer(60), HorizonVerifier()),
                horizon_image(lambda x: skyline(x, 22)), horizon_image(lambda x: skyline((x + 50) / 1.1, 22)),
                horizon_image(lambda x: skyline(x, 99)),
                [horizon_image(lambda x, s=s: skyline(x, s)) for s in (21, 23, 24)])


def _horizon_fast() -> Case:
    """The packed path (preset fast): the recogniser scores every stored view in one call."""
    params = HorizonParams.preset("fast")
    return Case(lambda: (HorizonRecognizer(60, params), HorizonVerifier(params)),
                horizon_image(lambda x: skyline(x, 22)), horizon_image(lambda x: skyline(x + 50, 22)),
                horizon_image(lambda x: skyline(x, 99)),
                [horizon_image(lambda x, s=s: skyline(x, s)) for s in (21, 23, 24)])


CASES = {"cdvs": _cdvs, "vocab": _vocab, "horizon": _horizon, "horizon-fast": _horizon_fast}


@pytest.fixture(scope="module", params=sorted(CASES))
def case(request) -> Case:
    return CASES[request.param]()


def _filled(case: Case) -> tuple[Recognizer, Verifier, dict]:
    rec, ver = case.make()
    obs = {"place": rec.observe(case.place), "again": rec.observe(case.again),
           "unrelated": rec.observe(case.unrelated)}
    for k, im in enumerate(case.distractors):
        rec.add(f"d{k}", rec.observe(im))
    rec.add("place", obs["place"])
    rec.add("d-last", rec.observe(case.distractors[0][::-1, ::-1].copy()))
    return rec, ver, obs


def test_the_adapters_implement_the_protocols(case):
    rec, ver = case.make()
    for name in ("observe", "add", "query", "__len__"):
        assert callable(getattr(rec, name))
    assert callable(ver.verify)


def test_an_empty_database_returns_nothing(case):
    rec, _ = case.make()
    assert len(rec) == 0
    assert rec.query(rec.observe(case.place)) == []


def test_an_added_key_is_found_at_rank_one_by_the_same_observation(case):
    rec, _, obs = _filled(case)
    assert len(rec) == len(case.distractors) + 2
    ranked = rec.query(obs["place"])
    assert ranked and isinstance(ranked[0], Ranked) and ranked[0].key == "place"
    assert [r.score for r in ranked] == sorted((r.score for r in ranked), reverse=True)


def test_an_unrelated_observation_scores_lower(case):
    rec, _, obs = _filled(case)
    own = rec.query(obs["place"])[0].score
    other = {r.key: r.score for r in rec.query(obs["unrelated"])}
    assert other.get("place", 0.0) < own
    assert max(other.values(), default=0.0) < own


def test_top_and_among_restrict_the_ranking(case):
    rec, _, obs = _filled(case)
    assert len(rec.query(obs["place"], top=1)) <= 1
    n_before = len(case.distractors)
    assert all(r.key != "place" for r in rec.query(obs["place"], among=n_before))
    assert rec.query(obs["place"], among=0) == []


def test_the_verifier_accepts_the_place_seen_again_and_rejects_an_unrelated_one(case):
    _, ver, obs = _filled(case)
    same = ver.verify(obs["again"], obs["place"])
    assert isinstance(same, Verification)
    assert same.accepted and same.n_inliers > 0 and same.transform is not None
    assert len(same.inliers_query) == len(same.inliers_candidate) == same.n_inliers
    other = ver.verify(obs["unrelated"], obs["place"])
    assert not other.accepted and other.score < same.score


def test_recognition_is_deterministic(case):
    (r1, v1, o1), (r2, v2, o2) = _filled(case), _filled(case)
    assert r1.query(o1["again"]) == r2.query(o2["again"])
    assert r1.query(o1["again"]) == r1.query(o1["again"])
    a, b = v1.verify(o1["again"], o1["place"]), v2.verify(o2["again"], o2["place"])
    assert (a.accepted, a.score, a.n_inliers) == (b.accepted, b.score, b.n_inliers)
    np.testing.assert_array_equal(a.inliers_query, b.inliers_query)


# --- the adapters rank exactly as the classes they wrap -------------------------------------------------------

@pytest.mark.parametrize("descriptor", ["orb", "briefrot"])
def test_vocab_recognizer_ranks_as_its_visual_memory(descriptor):
    from loops.vocab import VisualMemory, preset

    from ._vocab_helpers import perturb
    from ._vocab_helpers import texture as scene

    keys = [scene(100 + i) for i in range(6)]
    names = [f"k{i}" for i in range(6)]
    memory = VisualMemory.build(keys, names, preset("fast", descriptor=descriptor))
    grown = VocabRecognizer(memory.trees, memory.params)     # the same vocabularies, keys added one by one
    for name, im in zip(names, keys):
        grown.add(name, grown.observe(im))
    wrapped = VocabRecognizer.from_memory(memory)
    for i, im in enumerate(keys):
        query = perturb(im, i)
        r = memory.query(query)
        expected = [(names[k], float(s)) for k, s in zip(r.keys, r.scores)]
        obs = grown.observe(query)
        assert [(c.key, c.score) for c in grown.query(obs)] == expected
        assert [(c.key, c.score) for c in wrapped.query(obs)] == expected


def test_horizon_recognizer_ranks_as_its_landmark_memory():
    from loops.horizon import LandmarkMemory, extract_features

    memory = LandmarkMemory()
    for name, seed in (("north", 21), ("south", 22), ("east", 23)):
        memory.add(name, extract_features(horizon_image(lambda x, s=seed: skyline(x, s)), 60))
    rec = HorizonRecognizer(60, memory=memory)
    view_ = horizon_image(lambda x: skyline((x + 50) / 1.1, 22))
    expected = memory.recognise(extract_features(view_, 60))
    ranked = rec.query(rec.observe(view_))
    assert ranked[0].key == expected.best == "south"
    assert {r.key: r.score for r in ranked} == expected.scores
