import numpy as np
import pytest

from loops.vocab import DescriptorKind, VocabFileError, build_tree, load_vocabulary, save_vocabulary
from loops.vocab.kinds import centres, distances
from loops.vocab.kmeans import kmeans, kmeanspp_seeds


def _binary(n, seed=0, n_modes=12):
    """Binary descriptors around a few modes (flip ~8 % of the bits), like real BRIEF clusters."""
    rng = np.random.default_rng(seed)
    modes = rng.integers(0, 256, (n_modes, 32), dtype=np.uint8)
    bits = np.unpackbits(modes[rng.integers(0, n_modes, n)], axis=1)
    flip = rng.random(bits.shape) < 0.08
    return np.packbits(bits ^ flip, axis=1)


def test_hamming_and_l2_distances():
    a = np.array([[0b10110000, 0xFF]], np.uint8)
    b = np.array([[0b00110001, 0x0F], [0b10110000, 0xFF]], np.uint8)
    assert distances(DescriptorKind.BINARY, a, b).tolist() == [[2 + 4, 0]]
    x = np.array([[0.0, 0.0], [3.0, 4.0]], np.float32)
    assert np.allclose(distances(DescriptorKind.FLOAT, x, x[1:]), [[5.0], [0.0]])


def test_majority_bit_and_mean_centres():
    x = np.packbits(np.array([[1, 0, 1, 0, 0, 0, 0, 0], [1, 1, 0, 0, 0, 0, 0, 0], [0, 1, 1, 0, 0, 0, 0, 0],
                              [0, 0, 0, 1, 0, 0, 0, 0]], np.uint8), axis=1)
    c, sizes = centres(DescriptorKind.BINARY, x, np.array([0, 0, 0, 1]), 3)
    assert sizes.tolist() == [3, 1, 0]
    assert np.unpackbits(c[0]).tolist() == [1, 1, 1, 0, 0, 0, 0, 0]   # each of the first 3 bits set in 2 of 3
    assert np.unpackbits(c[1]).tolist() == [0, 0, 0, 1, 0, 0, 0, 0]
    f = np.array([[0, 0], [2, 4], [10, 10]], np.float32)
    m, _ = centres(DescriptorKind.FLOAT, f, np.array([0, 0, 1]), 2)
    assert np.allclose(m, [[1, 2], [10, 10]])


def test_kmeanspp_and_kmeans_are_deterministic_with_a_seed():
    x = _binary(2000)
    s1 = kmeanspp_seeds(DescriptorKind.BINARY, x, 8, np.random.default_rng(5))
    s2 = kmeanspp_seeds(DescriptorKind.BINARY, x, 8, np.random.default_rng(5))
    s3 = kmeanspp_seeds(DescriptorKind.BINARY, x, 8, np.random.default_rng(6))
    assert s1.tolist() == s2.tolist() and s1.tolist() != s3.tolist()
    l1, c1 = kmeans(DescriptorKind.BINARY, x, 8, np.random.default_rng(5))
    l2, c2 = kmeans(DescriptorKind.BINARY, x, 8, np.random.default_rng(5))
    assert np.array_equal(l1, l2) and np.array_equal(c1, c2)
    # labels are the nearest centre (what a query descending the tree will do)
    assert np.array_equal(l1, np.argmin(distances(DescriptorKind.BINARY, x, c1), axis=1))


def test_kmeanspp_spreads_seeds_over_separated_clusters():
    rng = np.random.default_rng(0)
    blobs = np.concatenate([rng.normal(c, 0.1, (200, 2)) for c in ((0, 0), (10, 0), (0, 10), (10, 10))])
    seeds = kmeanspp_seeds(DescriptorKind.FLOAT, blobs.astype(np.float32), 4, np.random.default_rng(1))
    assert sorted(set((blobs[seeds] > 5).dot([1, 2]).tolist())) == [0, 1, 2, 3]


def test_tree_build_is_deterministic_and_seed_dependent():
    x = _binary(3000)
    a, b = build_tree(x, 6, 3, seed=3), build_tree(x, 6, 3, seed=3)
    assert np.array_equal(a.centres, b.centres) and np.array_equal(a.children, b.children)
    c = build_tree(x, 6, 3, seed=4)
    assert not (a.centres.shape == c.centres.shape and np.array_equal(a.centres, c.centres))


def test_tree_shape_and_training_descriptors_find_their_leaf():
    x = _binary(3000)
    t = build_tree(x, 5, 3, seed=0)
    assert t.children.shape[1] == 5 and 0 < t.n_words <= 5 ** 3
    words = t.transform(x)
    assert words.min() >= 0 and words.max() < t.n_words
    # a descriptor identical to a leaf centre lands in that leaf
    leaves = np.nonzero(t.word >= 0)[0][:50]
    assert np.array_equal(t.transform(t.centres[leaves]), t.word[leaves])


def test_small_nodes_get_one_child_per_distinct_descriptor():
    x = np.array([[1] * 32, [2] * 32, [2] * 32, [7] * 32], np.uint8)
    t = build_tree(x, 10, 4)
    assert t.n_words == 3
    assert len(set(t.transform(x).tolist())) == 3
    assert t.transform(x)[1] == t.transform(x)[2]


def test_float_tree():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(1500, 16)).astype(np.float32)
    t = build_tree(x, 4, 3)
    assert t.kind is DescriptorKind.FLOAT and t.transform(x).max() < t.n_words


def test_vocabulary_save_load_roundtrip(tmp_path):
    x = _binary(2000)
    t = build_tree(x, 6, 3, seed=1)
    save_vocabulary(tmp_path / "v.voc", t, {"descriptor": "brief"})
    t2, info = load_vocabulary(tmp_path / "v.voc")
    assert info == {"descriptor": "brief"}
    assert np.array_equal(t.transform(x), t2.transform(x))
    assert (tmp_path / "v.voc").stat().st_size < t.centres.nbytes + t.children.nbytes + t.word.nbytes + 4096


def test_corrupted_vocabulary_files_give_clear_errors(tmp_path):
    t = build_tree(_binary(500), 4, 2)
    p = tmp_path / "v.voc"
    save_vocabulary(p, t)
    raw = bytearray(p.read_bytes())
    raw[-10] ^= 0xFF
    (tmp_path / "bad.voc").write_bytes(bytes(raw))
    with pytest.raises(VocabFileError, match="checksum"):
        load_vocabulary(tmp_path / "bad.voc")
    (tmp_path / "junk.voc").write_bytes(b"hello world, not a vocabulary")
    with pytest.raises(VocabFileError, match="bad magic"):
        load_vocabulary(tmp_path / "junk.voc")
    with pytest.raises(FileNotFoundError, match="missing.voc"):
        load_vocabulary(tmp_path / "missing.voc")


def test_empty_training_set_is_an_error():
    with pytest.raises(ValueError, match="zero descriptors"):
        build_tree(np.zeros((0, 32), np.uint8), 4, 2)


def _plain_lloyd(kind, x, group, n_groups, k, seeds, valid, iters):
    """Reference: textbook Lloyd iterations, group by group, from the given seeds (no bounds, no shortcuts)."""
    labels = np.zeros(len(x), np.int64)
    cents = x[seeds].copy()
    for g in range(n_groups):
        rows = np.nonzero(group == g)[0]
        c = cents[g]
        lab = None
        for it in range(iters + 1):
            d = distances(kind, x[rows], c)
            d[:, ~valid[g]] = np.inf
            new = np.argmin(d, axis=1)
            if lab is not None and np.array_equal(new, lab):
                break
            lab = new
            if it == iters:
                break
            new_c, sizes = centres(kind, x[rows], lab, k)
            new_c[sizes == 0] = c[sizes == 0]
            c = new_c
        labels[rows], cents[g] = lab, c
    return labels, cents


@pytest.mark.parametrize("kind", [DescriptorKind.BINARY, DescriptorKind.FLOAT])
def test_grouped_kmeans_equals_plain_lloyd_per_group(kind):
    """All nodes of a level clustered at once, with active-group, incremental-sum and Hamerly-bound shortcuts,
    give what plain Lloyd gives on each group from the same k-means++ seeds."""
    from loops.vocab.kmeans import grouped_kmeans, grouped_kmeanspp

    rng = np.random.default_rng(3)
    if kind is DescriptorKind.BINARY:
        x = _binary(1500, seed=2, n_modes=20)
    else:
        x = (rng.normal(size=(1500, 8)) + rng.integers(0, 4, (1500, 1))).astype(np.float32)
    sizes = [700, 500, 5, 3, 292]          # big groups, tiny ones (fewer rows than k), one of 3 rows
    group = np.repeat(np.arange(len(sizes)), sizes)
    k, iters = 6, 20
    labels, c, used = grouped_kmeans(kind, x, group, len(sizes), k, np.random.default_rng(11), iters)
    seeds, valid = grouped_kmeanspp(kind, x, group, len(sizes), k, np.random.default_rng(11).random((len(sizes), k)))
    ref_labels, ref_c = _plain_lloyd(kind, x, group, len(sizes), k, seeds, valid, iters)
    assert np.array_equal(labels, ref_labels)
    assert np.allclose(c[used].astype(float), ref_c[used].astype(float), atol=1e-4)
    assert used[3].sum() == 3 and used[2].sum() == 5     # tiny groups: one cluster per distinct row
