import cv2
import numpy as np
import pytest

from loops.vocab import EmptyMemoryError, NoFeaturesError, Scores, VisualMemory, evaluate, merge_max, preset

from ._vocab_helpers import perturb, texture

N_KEYS = 8


@pytest.fixture(scope="module")
def keys():
    return [texture(100 + i) for i in range(N_KEYS)]


def _rotate(img, angle):
    h, w = img.shape[:2]
    return cv2.warpAffine(img, cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), angle, 1.0), (w, h),
                          borderMode=cv2.BORDER_REFLECT)


@pytest.mark.parametrize("name", ["brief", "orb", "surf", "color-whole"])
def test_memory_finds_the_place_of_each_query(keys, name):
    memory = VisualMemory.build(keys, [f"k{i}" for i in range(N_KEYS)], preset("fast", descriptor=name))
    for i, img in enumerate(keys):
        r = memory.query(perturb(img, i))
        assert r.keys[0] == i and 0 < r.scores[0] <= 1
        assert np.all(np.diff(r.scores) <= 0)


def test_merge_max_is_eq2():
    s0 = Scores(np.array([2, 0]), np.array([0.5, 0.2]), np.array([9, 9]))
    s1 = Scores(np.array([0, 1]), np.array([0.6, 0.1]), np.array([9, 9]))
    s2 = Scores(np.array([1]), np.array([0.3]), np.array([9]))
    r = merge_max([s0, s1, s2])
    assert r.keys.tolist() == [0, 2, 1]
    assert r.scores.tolist() == [0.6, 0.5, 0.3]
    assert r.vocab.tolist() == [1, 0, 2]


def test_briefrot_score_is_the_max_over_its_three_vocabularies(keys):
    params = preset("fast", descriptor="briefrot", rot_theta_deg=15)
    memory = VisualMemory.build(keys, [f"k{i}" for i in range(N_KEYS)], params)
    assert memory.angles == (0.0, 15.0, -15.0) and len(memory.trees) == 3
    query = _rotate(keys[3], 15.0)
    from loops.vocab import extract

    d = extract(query, params)[0]
    per_vocab = [db.score(t.transform(d), params.min_shared_words).scores.max(initial=0)
                 for t, db in zip(memory.trees, memory.databases)]
    r = memory.query(query)
    assert r.keys[0] == 3
    assert r.scores[0] == pytest.approx(max(per_vocab))
    # an image turned by +15 deg is explained by the key descriptors whose pattern turned by -15 deg
    assert r.vocab[0] == 2 and per_vocab[2] > per_vocab[0]


def test_memory_save_load_gives_identical_rankings(keys, tmp_path):
    params = preset("fast", descriptor="briefrot")
    memory = VisualMemory.build(keys, [f"k{i}" for i in range(N_KEYS)], params)
    memory.save(tmp_path / "m.vmem")
    loaded = VisualMemory.load(tmp_path / "m.vmem")
    assert loaded.key_names == memory.key_names and loaded.params == params
    q = perturb(keys[5], 1)
    a, b = memory.query(q), loaded.query(q)
    assert np.array_equal(a.keys, b.keys) and np.allclose(a.scores, b.scores)


def test_same_seed_same_memory_file(keys, tmp_path):
    params = preset("fast", descriptor="orb", seed=11)
    for name in ("a", "b"):
        VisualMemory.build(keys, [f"k{i}" for i in range(N_KEYS)], params).save(tmp_path / f"{name}.vmem")
    assert (tmp_path / "a.vmem").read_bytes() == (tmp_path / "b.vmem").read_bytes()


def test_empty_memory_and_featureless_images_are_clear_errors(keys):
    with pytest.raises(EmptyMemoryError, match="no key images"):
        VisualMemory.build([], [], preset("fast"))
    blank = np.full((120, 160, 3), 90, np.uint8)
    # a key image without features (issue 15: a blank wall) is kept as a key that never matches
    m = VisualMemory.build([keys[0], blank], ["k0", "wall.png"], preset("fast"))
    assert m.featureless == (1,) and list(m.query(keys[0]).keys) == [0]
    memory = VisualMemory.build(keys[:3], ["a", "b", "c"], preset("fast"))
    with pytest.raises(NoFeaturesError, match="q.png"):
        memory.query(blank, name="q.png")


def test_evaluate_reports_mu1_mu2_and_featureless_queries(keys):
    memory = VisualMemory.build(keys, [f"k{i}" for i in range(N_KEYS)], preset("fast"))
    queries = [(f"q{i}", perturb(keys[i], i), None) for i in range(N_KEYS)]
    queries.append(("blank", np.zeros((120, 160, 3), np.uint8), None))
    truth = {f"q{i}": [i] for i in range(N_KEYS)} | {"blank": [0]}
    ev = evaluate(memory, queries, truth)
    s = ev.summary()
    assert s.n_tests == N_KEYS + 1 and s.correct_mu1 == N_KEYS and s.recall1 == pytest.approx(N_KEYS / (N_KEYS + 1))
    blank = ev.results[-1]
    assert "no brief features" in blank.error and blank.mu1 == (1 + N_KEYS) / 2
    assert all(r.mu2 >= 1 for r in ev.results)
    rows = ev.ranking_rows(memory.key_names)
    assert rows[0][:3] == ("q0", 1, "k0")


def test_key_similarity_compares_key_images_as_stored(keys):
    """mu2's z_l(I*_k): key images compared in the same representation in each vocabulary (max over BRIEFROT's
    three, eq. 2). Unrelated key images get 0, a near-duplicate a positive similarity, the key itself 1."""
    params = preset("default", descriptor="briefrot", rot_theta_deg=8)
    images = [keys[0], perturb(keys[0], 1)] + keys[1:6]
    memory = VisualMemory.build(images, [f"k{i}" for i in range(len(images))], params)
    z = memory.key_similarity(0)
    assert z[0] == 1.0 and z[1] > 0 and np.all(z[2:] == 0)
    per_vocab = [merge_max([db.score_image(0, params.min_shared_words)]).dense_scores(len(images))
                 for db in memory.databases]
    assert np.allclose(z, np.maximum.reduce(per_vocab))
    # the plain-pattern descriptors of key 0 queried against the rotated vocabularies would not do: plain
    # descriptors in a vocabulary trained on rotated ones share words with unrelated key images by chance
    from loops.vocab import extract

    cross = memory.query_descriptors(extract(images[0], params)[0]).dense_scores(len(images))
    assert np.count_nonzero(cross[2:]) > 0
