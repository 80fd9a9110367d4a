"""Stored landmarks: memorise a few horizons, recognise which of them (if any) a new horizon shows (paper §3.1, §4.2).

On disk a memory is one .npz (written atomically, loaded without pickle) holding a format version, the
HorizonParams the features were extracted with (a query must be extracted with the same ones), and every
landmark's features concatenated, with per-landmark counts. With parameters of the packed path (preset `fast`,
loops.horizon.packed) each landmark is its packed bands instead (format version 2: arrays packed_x, packed_keys,
packed_valid, one row per landmark), and recognition scores a view against every landmark in one call.
"""
from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loops.errors import LoopsError
from loops.horizon.packed import PackedBands, PackedSet, uses_packed
from loops.horizon.params import HorizonParams
from loops.horizon.signal import HorizonLine
from loops.horizon.surf1d import HorizonFeatures
from loops.horizon.views import HorizonMatch, HorizonView, check_view, match_views, score_views, stack_views
from odometry.shared.atomic_io import atomic_path

MEMORY_VERSION = 2      # 2: packed landmarks (preset fast); version 1 files (per-pair features) are still read
_FORMAT = "vslam.horizon.memory"


class MemoryFormatError(LoopsError):
    """A landmark memory file that cannot be read; the message names the file and the problem."""


@dataclass(frozen=True)
class Landmark:
    name: str
    features: HorizonView                # HorizonFeatures, or PackedBands on the packed path
    source: str = ""                     # where the features came from (an image path), for the user
    horizon: HorizonLine = HorizonLine(float("nan"), float("nan"))


@dataclass(frozen=True)
class Recognition:
    """Which stored landmark a horizon shows.

    name: the best landmark when its NN+RANSAC score reaches the threshold, else None.
    best: the best-scoring landmark whatever the threshold (None for an empty memory); result: its match
        (MatchResult, or PackedMatch on the packed path).
    scores: NN+RANSAC (packed: NN+shift) score against every landmark, in memory order.
    """

    name: str | None
    best: str | None
    result: HorizonMatch | None
    scores: dict[str, float]
    threshold: float

    @property
    def score(self) -> float:
        return self.result.score_ransac if self.result is not None else 0.0


@dataclass
class LandmarkMemory:
    params: HorizonParams = field(default_factory=HorizonParams)
    landmarks: list[Landmark] = field(default_factory=list)
    _stacked: tuple[int, PackedSet | None] | None = field(default=None, init=False, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.landmarks)

    @property
    def names(self) -> list[str]:
        return [lm.name for lm in self.landmarks]

    @property
    def packed(self) -> bool:
        """Whether the memory scores on the packed path (its parameters allow it: preset fast)."""
        return uses_packed(self.params)

    def add(self, name: str, features: HorizonView, source: str = "",
            horizon: HorizonLine | float | None = None) -> Landmark:
        """Memorise `features` (loops.horizon.views.extract_view with the memory's parameters) under `name` (names
        are unique)."""
        if name in self.names:
            raise LoopsError(f"landmark {name!r} is already in the memory")
        check_view(features, self.params, f"landmark {name!r}")
        if horizon is None:
            horizon = HorizonLine(float("nan"), float("nan"))
        elif not isinstance(horizon, HorizonLine):
            horizon = HorizonLine.level(float(horizon))
        lm = Landmark(str(name), features, str(source), horizon)
        self.landmarks.append(lm)
        return lm

    def match_all(self, features: HorizonView) -> list[HorizonMatch]:
        return match_views(features, [lm.features for lm in self.landmarks], self.params)

    def scores(self, features: HorizonView, among: int | None = None) -> np.ndarray:
        """NN+consensus score against the first `among` landmarks (default all), in memory order; on the packed
        path one call over the landmarks stacked once (restacked only after an add)."""
        check_view(features, self.params, "query view")
        views = [lm.features for lm in self.landmarks]
        if self._stacked is None or self._stacked[0] != len(views):
            self._stacked = (len(views), stack_views(views, self.params))
        return score_views(features, views, self.params, self._stacked[1], among)

    def recognise(self, features: HorizonView, threshold: float | None = None) -> Recognition:
        """Match `features` against every landmark; recognised when the best NN+RANSAC score >= threshold
        (default params.recognition_threshold)."""
        thr = self.params.recognition_threshold if threshold is None else float(threshold)
        s = self.scores(features)
        scores = {lm.name: float(v) for lm, v in zip(self.landmarks, s)}
        if not len(s):
            return Recognition(None, None, None, scores, thr)
        k = int(np.argmax(s))
        best = self.landmarks[k].name
        result = match_views(features, [self.landmarks[k].features], self.params)[0]
        name = best if result.score_ransac >= thr else None
        return Recognition(name, best, result, scores, thr)

    def save(self, path: str | os.PathLike) -> None:
        save_memory(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "LandmarkMemory":
        return load_memory(path)


# Storage dtypes on disk, and the dtypes features have in memory.
_FEATURE_FIELDS = {"x": np.float64, "scale": np.float64, "level": np.int16, "sign": np.int8,
                   "response": np.float32, "descriptor": np.float32}
_RUNTIME_DTYPES = {"x": np.float64, "scale": np.float64, "level": np.intp, "sign": np.int8,
                   "response": np.float64, "descriptor": np.float32}


def save_memory(memory: LandmarkMemory, path: str | os.PathLike) -> None:
    """Write `memory` to `path` (.npz) atomically."""
    lms = memory.landmarks
    dim = 2 * memory.params.subregions
    arrays: dict[str, np.ndarray] = {
        "format": np.array(_FORMAT),
        "version": np.array(MEMORY_VERSION, dtype=np.int64),
        "params": np.array(json.dumps(memory.params.to_dict(), sort_keys=True)),
        "names": np.array([lm.name for lm in lms], dtype=np.str_).reshape(len(lms)),
        "sources": np.array([lm.source for lm in lms], dtype=np.str_).reshape(len(lms)),
        "horizons": np.array([[lm.horizon.row_left, lm.horizon.row_right] for lm in lms],
                             dtype=np.float64).reshape(len(lms), 2),
        "widths": np.array([lm.features.width for lm in lms], dtype=np.int64),
        "counts": np.array([0 if memory.packed else len(lm.features) for lm in lms], dtype=np.int64),
    }
    if memory.packed:
        p = memory.params
        shape = (len(lms), p.bands, p.max_features)
        arrays["packed_x"] = np.array([lm.features.x for lm in lms], np.float64).reshape(shape)
        arrays["packed_keys"] = np.array([lm.features.keys for lm in lms], np.float32).reshape(*shape, dim + 1)
        arrays["packed_valid"] = np.array([lm.features.valid for lm in lms], bool).reshape(shape)
    for name, dtype in _FEATURE_FIELDS.items():
        parts = [] if memory.packed else [np.asarray(getattr(lm.features, name), dtype=dtype) for lm in lms]
        empty = np.zeros((0, dim) if name == "descriptor" else 0, dtype)
        arrays[name] = np.concatenate(parts) if parts else empty
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())


def load_memory(path: str | os.PathLike) -> LandmarkMemory:
    """Read a memory written by save_memory; MemoryFormatError (a ValueError) names the file and the problem."""
    path = Path(path)

    def bad(problem: str) -> MemoryFormatError:
        return MemoryFormatError(f"{path}: not a valid horizon landmark memory: {problem}")

    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, EOFError, ValueError) as exc:
        raise bad(f"cannot read it as .npz ({exc})") from None
    if not isinstance(data, dict):
        raise bad("expected an .npz archive")
    required = ["format", "version", "params", "names", "sources", "horizons", "widths", "counts",
                *_FEATURE_FIELDS]
    missing = [k for k in required if k not in data]
    if missing:
        raise bad(f"missing field(s) {', '.join(missing)}")
    if str(data["format"]) != _FORMAT:
        raise bad(f"format is {str(data['format'])!r}, expected {_FORMAT!r}")
    version = int(data["version"])
    if version not in (1, MEMORY_VERSION):
        raise bad(f"version {version} is not supported (this code reads versions 1 to {MEMORY_VERSION})")
    try:
        params = HorizonParams.from_dict(json.loads(str(data["params"])))
    except (ValueError, TypeError) as exc:
        raise bad(f"field params: {exc}") from None
    names, counts = data["names"], data["counts"]
    n_lm = names.shape[0] if names.ndim == 1 else -1
    for k, shape in (("sources", (n_lm,)), ("horizons", (n_lm, 2)), ("widths", (n_lm,)), ("counts", (n_lm,))):
        if n_lm < 0 or data[k].shape != shape:
            raise bad(f"field {k} has shape {data[k].shape}, expected {shape} for {max(n_lm, 0)} landmarks")
    if np.any(counts < 0):
        raise bad("field counts has negative entries")
    total = int(counts.sum())
    dim = 2 * params.subregions
    for k in _FEATURE_FIELDS:
        expect = (total, dim) if k == "descriptor" else (total,)
        if data[k].shape != expect:
            raise bad(f"field {k} has shape {data[k].shape}, expected {expect} (counts sum to {total})")
    if len(set(names.tolist())) != n_lm:
        raise bad("landmark names are not unique")
    memory = LandmarkMemory(params)
    views = _packed_views(data, params, n_lm, bad) if memory.packed else None
    ends = np.cumsum(counts)
    starts = ends - counts
    for i in range(n_lm):
        if views is not None:
            feats = views[i]
        else:
            sl = slice(int(starts[i]), int(ends[i]))
            feats = HorizonFeatures(**{k: data[k][sl].astype(t) for k, t in _RUNTIME_DTYPES.items()},
                                    width=int(data["widths"][i]))
        h = data["horizons"][i]
        memory.add(str(names[i]), feats, str(data["sources"][i]), HorizonLine(float(h[0]), float(h[1])))
    return memory


def _packed_views(data: dict, params: HorizonParams, n_lm: int, bad) -> list[PackedBands]:
    """The landmarks of a memory on the packed path, every array checked against the parameters first."""
    shape = (n_lm, params.bands, params.max_features)
    expect = {"packed_x": (shape, "f"), "packed_keys": ((*shape, 2 * params.subregions + 1), "f"),
              "packed_valid": (shape, "b")}
    for k, (want, kind) in expect.items():
        if k not in data:
            raise bad(f"field {k} is missing: its parameters (preset fast) need packed landmarks; a memory written "
                      "before version 2 with these parameters must be memorised again")
        if data[k].shape != want or data[k].dtype.kind != kind:
            raise bad(f"field {k} has shape {data[k].shape} ({data[k].dtype}), expected {want} for {n_lm} landmarks "
                      f"of {params.bands} bands x {params.max_features} features")
    if not (np.all(np.isfinite(data["packed_x"])) and np.all(np.isfinite(data["packed_keys"]))):
        raise bad("fields packed_x / packed_keys hold non-finite values")
    return [PackedBands(data["packed_x"][i].astype(np.float64), data["packed_keys"][i].astype(np.float32),
                        data["packed_valid"][i].astype(bool), int(data["widths"][i])) for i in range(n_lm)]
