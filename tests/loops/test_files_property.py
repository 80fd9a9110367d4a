"""Property tests: damaged visual-memory, vocabulary and loop-model files load or raise a LoopsError naming the file;
nothing else escapes (issue 15). Cases are seeded mutations of valid files (`vslam.bench.fuzz_cases`); the long run
is `vslam bench fuzz`."""
import json
import random

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from loops.cdvs.model import LoopModel
from loops.errors import LoopsError
from loops.vocab import VisualMemory, preset
from loops.vocab.tree import load_vocabulary, save_vocabulary
from vslam.bench.fuzz_cases import join_array_file, mutate_bytes, mutate_json, split_array_file, texture

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def memory_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("files")
    m = VisualMemory.build([texture(i) for i in range(3)], ["a", "b", "c"], preset("fast", descriptor="briefrot"))
    m.save(d / "m.vmem")
    save_vocabulary(d / "v.voc", m.trees[0], {"note": "test"})
    return d


def _expect_only_loops_errors(fn, path):
    try:
        fn()
    except LoopsError as exc:
        assert str(path) in str(exc), f"error does not name the file: {exc}"


@FAST
@given(seed=st.integers(0, 2**32 - 1))
def test_memory_file_with_a_damaged_header(memory_file, tmp_path, seed):
    header, data = split_array_file((memory_file / "m.vmem").read_bytes())
    p = tmp_path / f"h{seed}.vmem"
    p.write_bytes(join_array_file(mutate_json(random.Random(seed), header), data))

    def use():
        m = VisualMemory.load(p)
        m.query(texture(1))
        m.key_similarity(0)
    _expect_only_loops_errors(use, p)


@FAST
@given(seed=st.integers(0, 2**32 - 1))
def test_memory_file_with_damaged_bytes(memory_file, tmp_path, seed):
    p = tmp_path / f"b{seed}.vmem"
    p.write_bytes(mutate_bytes(random.Random(seed), (memory_file / "m.vmem").read_bytes()))
    _expect_only_loops_errors(lambda: VisualMemory.load(p).query(texture(2)), p)


@FAST
@given(seed=st.integers(0, 2**32 - 1))
@example(seed=842)     # sets the centres' width to 0: once an IndexError in the Hamming kernel, not a LoopsError
def test_vocabulary_file_with_a_damaged_header(memory_file, tmp_path, seed):
    header, data = split_array_file((memory_file / "v.voc").read_bytes())
    p = tmp_path / f"v{seed}.voc"
    p.write_bytes(join_array_file(mutate_json(random.Random(seed), header), data))

    def use():
        tree, _ = load_vocabulary(p)
        tree.transform(np.zeros((3, tree.centres.shape[1]), np.uint8))
    _expect_only_loops_errors(use, p)


@FAST
@given(seed=st.integers(0, 2**32 - 1))
def test_loop_model_with_damaged_fields(tmp_path, seed):
    doc = LoopModel.default().to_dict()
    p = tmp_path / f"m{seed}.json"
    p.write_text(json.dumps(mutate_json(random.Random(seed), doc)))

    def use():
        m = LoopModel.load(p)
        for mode in m.curves:
            m.probability(mode, np.array([0.0, 5.0, 50.0]))
            m.threshold(mode)
    _expect_only_loops_errors(use, p)


@settings(max_examples=40, deadline=None)
@given(text=st.text(max_size=200))
def test_loop_model_from_any_text(tmp_path_factory, text):
    p = tmp_path_factory.mktemp("lm") / "m.json"
    p.write_text(text, encoding="utf-8", errors="surrogatepass")
    _expect_only_loops_errors(lambda: LoopModel.load(p), p)


def test_a_zero_descriptor_width_in_the_header_is_a_loops_error_naming_the_file_and_array(memory_file, tmp_path):
    """The array table is outside the checksum: a width of 0 fits inside the data, so only the layout check (the
    table must account for every data byte) stops it before the distance kernels see rows of no bytes."""
    header, data = split_array_file((memory_file / "v.voc").read_bytes())
    centres = next(e for e in header["arrays"] if e["name"] == "centres")
    centres["shape"][1] = 0
    p = tmp_path / "zero-width.voc"
    p.write_bytes(join_array_file(header, data))
    with pytest.raises(LoopsError) as err:
        load_vocabulary(p)
    msg = str(err.value)
    assert str(p) in msg and "'centres'" in msg and f"shape {centres['shape']}" in msg
