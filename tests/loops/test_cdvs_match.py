"""Matching: score monotonicity, DISTRAT + RANSAC geometric check, mixed modes."""
import cv2
import numpy as np
import pytest

from loops.cdvs import CdvsParams, GeometryModel, IncompatibleDescriptorsError, MatchParams, extract, match
from loops.cdvs.geometry import distrat_inliers
from loops.geometry import ransac_transform
from tests.loops.test_cdvs_codec import texture

BIG = texture(11, 1400, 1800)


def view(x: int, y: int, angle: float = 0.0, w: int = 640, h: int = 480) -> np.ndarray:
    """A downward-camera-like view of the big texture: window centred at (x, y), rotated by `angle` degrees."""
    M = cv2.getRotationMatrix2D((x, y), angle, 1.0)
    M[:, 2] += [w / 2 - x, h / 2 - y]
    return cv2.warpAffine(BIG, M, (w, h), flags=cv2.INTER_LINEAR)


@pytest.mark.parametrize("mode", [2, 4, 6])
def test_scores_identical_gt_overlapping_gt_disjoint(mode):
    a = extract(view(700, 600), mode)
    same = match(a, extract(view(700, 600), mode))
    overlap = match(a, extract(view(830, 640, angle=25), mode))   # ~60 % of the area in common, rotated
    disjoint = match(a, extract(view(1400, 1100), mode))
    assert same.local_score > overlap.local_score > disjoint.local_score
    assert same.global_score > overlap.global_score > disjoint.global_score
    assert disjoint.n_inliers == 0 and overlap.n_inliers >= 8


def test_inlier_pairs_follow_the_true_motion():
    a, b = extract(view(700, 600), 5), extract(view(760, 620, angle=10), 5)
    r = match(a, b, CdvsParams.floor(5).matching)
    assert r.n_inliers >= 15
    # b shows the window centred at (760, 620) rotated by 10 deg about its centre
    M = cv2.getRotationMatrix2D((760, 620), 10, 1.0)
    M[:, 2] += [320 - 760, 240 - 620]
    M0 = cv2.getRotationMatrix2D((700, 600), 0, 1.0)
    M0[:, 2] += [320 - 700, 240 - 600]
    big_pts = r.inliers_a - M0[:, 2]                       # view a -> big texture
    pred = big_pts @ M[:, :2].T + M[:, 2]
    err = np.linalg.norm(pred - r.inliers_b, axis=1)
    assert np.median(err) < 3.0 and np.mean(err < 6) > 0.9


def _true_matches(n: int, rng: np.random.Generator):
    xa = rng.uniform(0, 640, (n, 2))
    th, s, t = 0.4, 1.1, np.array([30.0, -20.0])
    R = s * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return xa, xa @ R.T + t + rng.normal(0, 0.7, (n, 2))


def test_distrat_finds_inliers_among_outliers():
    rng = np.random.default_rng(0)
    xa, xb = _true_matches(40, rng)
    out_a, out_b = rng.uniform(0, 640, (25, 2)), rng.uniform(0, 640, (25, 2))
    inl = distrat_inliers(np.vstack([xa, out_a]), np.vstack([xb, out_b]), MatchParams().distrat_chi2)
    assert len(inl) >= 30
    assert np.mean(inl < 40) > 0.9  # nearly all selected are true matches


def test_geometric_check_rejects_a_shuffled_match_set():
    rng = np.random.default_rng(1)
    xa, xb = _true_matches(60, rng)
    rejected = 0
    for k in range(10):
        perm = np.random.default_rng(k).permutation(len(xb))
        inl = distrat_inliers(xa, xb[perm], MatchParams().distrat_chi2)
        if len(inl) >= MatchParams().min_inliers:
            ok, _ = ransac_transform(xa[inl], xb[perm][inl], np.ones(len(inl)), GeometryModel.AFFINE, 24, 12.0)
            rejected += ok.sum() < MatchParams().min_inliers
        else:
            rejected += 1
    assert rejected == 10
    # the same points, correctly paired, pass
    assert len(distrat_inliers(xa, xb, MatchParams().distrat_chi2)) >= 50


def test_shuffled_descriptors_give_no_local_score():
    a, b = extract(view(700, 600), 4), extract(view(760, 620), 4)
    assert match(a, b).local_score > 5
    rng = np.random.default_rng(0)
    b_shuffled = type(b)(**{**b.__dict__, "xy": b.xy[rng.permutation(b.n_local)]})
    assert match(a, b_shuffled).n_inliers == 0


def test_ransac_is_deterministic():
    rng = np.random.default_rng(2)
    xa, xb = _true_matches(30, rng)
    w = np.ones(30)
    for model in GeometryModel:
        m1, f1 = ransac_transform(xa, xb, w, model, 12, 3.0)
        assert np.array_equal(m1, ransac_transform(xa, xb, w, model, 12, 3.0)[0]) and m1.sum() >= 25
        assert np.median(np.linalg.norm(f1(xa) - xb, axis=1)) < 2.0


def test_mixed_modes_match_on_the_common_bits():
    a, b = extract(view(700, 600), 2), extract(view(760, 620), 6)
    r = match(a, b)
    assert r.n_inliers >= 5 and r.local_score > 0
    assert abs(r.global_score - match(b, a).global_score) < 1e-6


def test_incompatible_trained_parameters_are_refused():
    a = extract(view(700, 600), 1)
    other = type(a)(**{**a.__dict__, "params_id": (a.params_id + 1) & 0xFFFF})
    with pytest.raises(IncompatibleDescriptorsError):
        match(a, other)


def test_empty_descriptors_match_with_zero_scores():
    blank = extract(np.full((480, 640), 90, np.uint8), 3)
    r = match(blank, extract(view(700, 600), 3))
    assert r.local_score == 0 and r.n_inliers == 0 and r.global_score == 0


def test_ransac_rejects_implausible_transforms():
    rng = np.random.default_rng(3)
    xa, xb = _true_matches(30, rng)
    w = np.ones(30)
    mirrored = xb * [-1.0, 1.0] + [640.0, 0.0]                 # a reflection: no camera motion produces it
    lim = dict(scale_range=MatchParams().scale_range, max_anisotropy=MatchParams().max_anisotropy)
    assert ransac_transform(xa, mirrored, w, GeometryModel.AFFINE, 24, 3.0, **lim)[0].sum() < MatchParams().min_inliers
    assert ransac_transform(xa, xb, w, GeometryModel.AFFINE, 24, 3.0, **lim)[0].sum() >= 25
    # a downward camera at a fixed height sees the floor at scale ~1: a 2x "zoom" is no loop
    zoom = 2.0 * xa + [10.0, 5.0]
    assert ransac_transform(xa, zoom, w, GeometryModel.SIMILARITY, 24, 3.0)[0].sum() == 30
    assert ransac_transform(xa, zoom, w, GeometryModel.SIMILARITY, 24, 3.0, scale_range=(0.8, 1.25))[1] is None


def test_verified_transform_gives_the_image_overlap():
    from loops.geometry import transform_overlap

    def shift(dx):
        return lambda x: x + [dx, 0.0]

    assert transform_overlap(shift(0.0), (640, 480), (640, 480)) == pytest.approx(1.0)
    assert transform_overlap(shift(320.0), (640, 480), (640, 480)) == pytest.approx(1 / 3)
    assert transform_overlap(shift(700.0), (640, 480), (640, 480)) == 0.0
    a = extract(view(700, 600), 4, CdvsParams.floor(4))
    b = extract(view(860, 600), 4, CdvsParams.floor(4))             # 160 px shift of 640: J = 480 / 800 = 0.6
    r = match(a, b, CdvsParams.floor(4).matching)
    assert r.overlap == pytest.approx(0.6, abs=0.03)
    assert match(a, extract(view(1400, 1100), 4, CdvsParams.floor(4)), CdvsParams.floor(4).matching).overlap == 0.0


def test_two_way_union_matches_the_reference_definition():
    """The vectorised union equals the CDVS definition written with Python sets."""
    from loops.cdvs.match import _nearest_two, local_matches
    from loops.hamming import hamming_matrix

    a, b = extract(view(700, 600), 3), extract(view(760, 640, angle=20), 3)
    p = MatchParams()
    ia, ib, w = local_matches(a, b, p)
    d = hamming_matrix(np.pad(a.local, ((0, 0), (0, (-a.local.shape[1]) % 8))),
                       np.pad(b.local, ((0, 0), (0, (-b.local.shape[1]) % 8))))
    max_d = p.max_distance_frac * 8 * a.local.shape[1]

    def one_way(dm):
        best = {}
        j, d1, d2 = _nearest_two(dm.copy())
        for i in range(len(j)):
            if d2[i] > 0 and d1[i] <= p.ratio * d2[i] and d1[i] <= max_d:
                wt = np.cos(0.5 * np.pi * np.sqrt(d1[i] / d2[i]))
                if j[i] not in best or wt > best[j[i]][1]:
                    best[j[i]] = (i, wt)
        return {(i, jj): wt for jj, (i, wt) in best.items()}

    m1 = one_way(d)
    m2 = {(i, j): wt for (j, i), wt in one_way(d.T).items()}
    both = set(m1) & set(m2)
    one = [(k, m1[k]) for k in m1 if k not in both] + [(k, m2[k]) for k in m2 if k not in both]
    scale = len(both) / len(one) if len(one) > len(both) else 1.0
    ref = {k: 0.5 * (m1[k] + m2[k]) for k in both} | {k: wt * scale for k, wt in one}
    got = {(int(x), int(y)): float(v) for x, y, v in zip(ia, ib, w)}
    assert got.keys() == ref.keys() and len(got) == len(ia) > 20
    assert all(abs(got[k] - ref[k]) < 1e-9 for k in ref)


def test_database_global_scan_equals_the_pairwise_global_score():
    """The table-lookup scan (absent clusters marked, cv2.LUT) gives the same scores as global_score pair by pair."""
    from loops.cdvs.global_desc import absent_marks, global_score, global_scores_many, weight_lut

    rng = np.random.default_rng(5)
    k = 64
    vis = rng.random((50, k)) < 0.6
    bits = np.where(vis, rng.integers(0, 2 ** 32, size=(50, k), dtype=np.uint64), 0).astype(np.uint32)
    w = rng.standard_normal(33).astype(np.float32)
    vis[3] = False                                   # a keyframe with no visited cluster scores 0
    for q in range(5):
        fast = global_scores_many(vis[q], bits[q], None, bits, vis.sum(axis=1), w, absent_db=absent_marks(vis),
                                  lut=weight_lut(w))
        ref = [global_score(vis[q], bits[q], vis[i], bits[i], w) for i in range(len(bits))]
        assert np.allclose(fast, ref, atol=1e-5)


def test_transform_overlap_equals_the_polygon_intersection():
    """The convex clipping used for the overlap gate agrees with a shapely intersection over union, including
    mirrored maps, disjoint views and a view inside the other."""
    import shapely

    from loops.geometry import transform_overlap

    rng = np.random.default_rng(3)
    for t in range(300):
        A = rng.normal(size=(2, 2)) * 0.5 + np.eye(2) * rng.uniform(0.3, 2.0)
        b = rng.uniform(-700, 700, 2) if t % 3 else rng.uniform(0, 50, 2)
        sa, sb = (int(rng.integers(100, 1300)), int(rng.integers(100, 900))), (640, 480)
        quad = np.array([[0, 0], [sa[0], 0], [sa[0], sa[1]], [0, sa[1]]], float) @ A.T + b
        pa, pb = shapely.Polygon(quad), shapely.box(0, 0, *sb)
        inter = shapely.intersection(pa, pb).area
        expect = inter / (pa.area + pb.area - inter)
        assert transform_overlap(lambda x: x @ A.T + b, sa, sb) == pytest.approx(expect, abs=1e-9)
    assert transform_overlap(lambda x: x + 1000.0, (640, 480), (640, 480)) == 0.0
    assert transform_overlap(lambda x: 0.5 * x + 10.0, (640, 480), (640, 480)) == pytest.approx(0.25)
