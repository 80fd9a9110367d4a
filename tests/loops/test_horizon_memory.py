"""Stored horizon landmarks: recognition, the .npz memory format, malformed files."""
from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from loops.horizon import (
    MEMORY_VERSION,
    HorizonLine,
    HorizonParams,
    LandmarkMemory,
    MemoryFormatError,
    extract_features,
    load_memory,
)

from .test_horizon import horizon_image, texture


@pytest.fixture(scope="module")
def memory() -> LandmarkMemory:
    p = HorizonParams()
    mem = LandmarkMemory(p)
    for name, seed in (("north", 21), ("south", 22), ("east", 23)):
        mem.add(name, extract_features(horizon_image(lambda x, s=seed: texture(x, s)), 60, p), f"{name}.png", 60)
    return mem


def test_recognises_the_landmark_seen_again(memory):
    p = memory.params
    # South again, the robot having turned (shift) and come closer (scale).
    view = extract_features(horizon_image(lambda x: texture((x + 50) / 1.1, 22)), 60, p)
    rec = memory.recognise(view)
    assert rec.name == "south" and rec.best == "south"
    assert rec.score >= p.recognition_threshold
    assert rec.result.b_s == pytest.approx(1.1, abs=0.03)
    assert rec.scores["south"] > 2 * max(rec.scores["north"], rec.scores["east"])


def test_unknown_landscape_is_not_recognised(memory):
    view = extract_features(horizon_image(lambda x: texture(x, 99)), 60, memory.params)
    rec = memory.recognise(view)
    assert rec.name is None and rec.best in memory.names
    assert rec.score < memory.params.recognition_threshold
    # The threshold is the caller's to choose.
    assert memory.recognise(view, threshold=0.0).name == rec.best


def test_empty_memory_recognises_nothing():
    rec = LandmarkMemory().recognise(extract_features(horizon_image(lambda x: texture(x, 1)), 60))
    assert rec.name is None and rec.best is None and rec.scores == {}


def test_duplicate_names_and_foreign_descriptors_are_refused(memory):
    f = memory.landmarks[0].features
    with pytest.raises(ValueError, match="already"):
        memory.add("north", f)
    other = LandmarkMemory(HorizonParams(subregions=4))
    with pytest.raises(ValueError, match="do not match"):
        other.add("x", f)


def test_save_load_round_trip(memory, tmp_path):
    path = tmp_path / "mem.npz"
    memory.save(path)
    back = load_memory(path)
    assert back.params == memory.params and back.names == memory.names
    for a, b in zip(memory.landmarks, back.landmarks):
        assert (a.source, a.horizon) == (b.source, b.horizon)
        assert a.features.width == b.features.width
        for field in ("x", "scale", "level", "sign", "response", "descriptor"):
            np.testing.assert_allclose(getattr(a.features, field), getattr(b.features, field), rtol=1e-6)
    view = extract_features(horizon_image(lambda x: texture(x - 30, 21)), 60, memory.params)
    assert back.recognise(view).scores == pytest.approx(memory.recognise(view).scores)
    assert not list(tmp_path.glob(".mem.npz*"))     # no temporary left behind
    empty = tmp_path / "empty.npz"
    LandmarkMemory(HorizonParams.preset("robust")).save(empty)
    assert load_memory(empty).params == HorizonParams.preset("robust") and len(load_memory(empty)) == 0


def test_tilted_horizon_is_stored(tmp_path):
    mem = LandmarkMemory()
    mem.add("a", extract_features(horizon_image(lambda x: texture(x, 2)), 60), "a.png", HorizonLine(58.0, 62.0))
    mem.save(tmp_path / "m.npz")
    assert load_memory(tmp_path / "m.npz").landmarks[0].horizon == HorizonLine(58.0, 62.0)


def _rewrite(src, dst, **changes):
    with np.load(src) as z:
        data = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is None:
            data.pop(k)
        else:
            data[k] = v
    with open(dst, "wb") as fh:
        np.savez(fh, **data)


@pytest.mark.parametrize("change,message", [
    ({"version": np.array(MEMORY_VERSION + 1)}, f"version {MEMORY_VERSION + 1} is not supported"),
    ({"descriptor": None}, "missing field"),
    ({"counts": np.array([1, 2, 3])}, "field x has shape"),
    ({"format": np.array("something.else")}, "format is"),
    ({"params": np.array(json.dumps({"band": 3}))}, "field params"),
    ({"names": np.array(["a", "a", "b"])}, "not unique"),
])
def test_malformed_memory_names_the_file_and_problem(memory, tmp_path, change, message):
    good = tmp_path / "good.npz"
    memory.save(good)
    bad = tmp_path / "bad.npz"
    _rewrite(good, bad, **change)
    with pytest.raises(MemoryFormatError, match=message) as exc:
        load_memory(bad)
    assert str(bad) in str(exc.value) and isinstance(exc.value, ValueError)


def test_truncated_or_foreign_file_is_a_clear_error(memory, tmp_path):
    good = tmp_path / "good.npz"
    memory.save(good)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:200])
    text = tmp_path / "notes.npz"
    text.write_text("hello")
    for path in (cut, text):
        with pytest.raises(MemoryFormatError, match="cannot read it as .npz") as exc:
            load_memory(path)
        assert str(path) in str(exc.value)
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        zf.writestr("other.txt", "x")
    (tmp_path / "zip.npz").write_bytes(buf.getvalue())
    with pytest.raises(MemoryFormatError, match="missing field"):
        load_memory(tmp_path / "zip.npz")
    with pytest.raises(FileNotFoundError):
        load_memory(tmp_path / "absent.npz")
