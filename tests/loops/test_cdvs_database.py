"""Loop database: shortlist + verification, recent-frame exclusion, confirmation, ids."""
import numpy as np
import pytest

from loops.cdvs import extract
from loops.cdvs.database import DatabaseParams, LoopDatabase
from loops.cdvs.detector import detect_loops
from tests.loops.test_cdvs_match import view

# a path over the big texture that comes back to its start: frames 0-3 and 14-17 see the same floor
PATH = [(500 + 70 * k, 500) for k in range(8)] + [(990, 500 + 70 * k) for k in range(1, 5)] + \
       [(990 - 120 * k, 780) for k in range(1, 5)] + [(520, 600), (500, 520), (560, 500)]


@pytest.fixture(scope="module")
def frames():
    return [view(x, y, angle=7 * k) for k, (x, y) in enumerate(PATH)]


@pytest.fixture(scope="module")
def descs(frames):
    return [extract(f, 4) for f in frames]


def test_query_finds_the_revisited_place_and_skips_recent_frames(descs):
    db = LoopDatabase(4, db_params=DatabaseParams(shortlist=3, exclude_recent=5))
    found = {}
    for k, d in enumerate(descs):
        cands = db.query(d, k)
        assert all(c.frame_id <= k - 5 for c in cands)          # the 5 most recent are never candidates
        if cands and cands[0].accepted:
            found[k] = cands[0].frame_id
        db.add(k, d)
    late = {k: m for k, m in found.items() if k >= 16}
    assert late, f"no loop found at the revisit, found {found}"
    for k, m in late.items():
        ax, ay = PATH[k]
        bx, by = PATH[m]
        assert abs(ax - bx) < 320 and abs(ay - by) < 240     # the reported frame really overlaps


def test_candidates_carry_inlier_pixel_pairs(descs):
    db = LoopDatabase(4, db_params=DatabaseParams(shortlist=2, exclude_recent=0))
    db.add(0, descs[0])
    c = db.query(descs[1], 1)[0]
    assert c.frame_id == 0 and c.n_inliers >= 5
    assert c.match.inliers_a.shape == c.match.inliers_b.shape == (c.n_inliers, 2)


def test_confirmation_requires_consecutive_agreement(descs):
    single = LoopDatabase(4, db_params=DatabaseParams(shortlist=2, exclude_recent=0, confirmations=1))
    double = LoopDatabase(4, db_params=DatabaseParams(shortlist=2, exclude_recent=0, confirmations=2))
    for db in (single, double):
        db.add(0, descs[0])
        db.add(1, descs[1])
    first_s, first_d = single.query(descs[2], 2), double.query(descs[2], 2)
    assert any(c.accepted for c in first_s)
    assert not any(c.accepted for c in first_d) and any(c.passes for c in first_d)  # not yet confirmed
    assert any(c.accepted for c in double.query(descs[3], 3))                     # confirmed by the next frame


def test_ids_must_increase_and_params_must_match(descs):
    db = LoopDatabase(4)
    db.add(5, descs[0])
    with pytest.raises(ValueError, match="increase"):
        db.add(5, descs[1])
    other = type(descs[0])(**{**descs[0].__dict__, "params_id": descs[0].params_id ^ 1})
    with pytest.raises(ValueError):
        db.add(9, other)


def test_global_scan_is_chunked_and_consistent(descs):
    db = LoopDatabase(4)
    for k in range(40):
        db.add(k, descs[k % len(descs)])
    g = db.global_scores(descs[0])
    assert g.shape == (40,) and np.argmax(g) % len(descs) == 0
    import loops.cdvs.recognizer as dbm
    old = dbm._CHUNK
    try:
        dbm._CHUNK = 7
        assert np.allclose(db.global_scores(descs[0]), g)
    finally:
        dbm._CHUNK = old


def test_detector_skips_unreadable_frames(frames):
    items = [(0, frames[0]), (1, None), (2, frames[1])]
    rows, st = detect_loops(items, 2, db_params=DatabaseParams(exclude_recent=0))
    assert st.frames == 2 and st.skipped == 1
    assert all(r.query_frame == 2 and r.candidate.frame_id == 0 for r in rows)


def test_min_overlap_rejects_verified_matches_that_overlap_too_little(descs):
    # frames 0 and 1 are 70 px apart on a 640 px wide view: J ~ 0.8
    loose = LoopDatabase(4, db_params=DatabaseParams(shortlist=1, exclude_recent=0), threshold=0.0)
    strict = LoopDatabase(4, db_params=DatabaseParams(shortlist=1, exclude_recent=0, min_overlap=0.95),
                          threshold=0.0)
    for db in (loose, strict):
        db.add(0, descs[0])
    c_loose, c_strict = loose.query(descs[1], 1)[0], strict.query(descs[1], 1)[0]
    assert 0.6 < c_loose.match.overlap < 0.95
    assert c_loose.accepted and not c_strict.passes


def test_min_overlap_comes_from_the_model_unless_given(descs):
    from loops.cdvs.model import LoopModel

    model = LoopModel.default()
    db = LoopDatabase(4, model=model)
    assert db.min_overlap == (model.min_overlap or 0.0)
    assert LoopDatabase(4, db_params=DatabaseParams(min_overlap=0.5), model=model).min_overlap == 0.5
