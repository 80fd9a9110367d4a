"""Stored landmarks: memorise a few horizons, recognise which of them (if any) a new horizon shows (paper §3.1, §4.2).

On disk a memory is one .npz (written atomically, loaded without pickle) holding a format version, the
HorizonParams the features were extracted with (a query must be extracted with the same ones), and every
landmark's features concatenated, with per-landmark counts.
"""
from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from loops.errors import LoopsError
from loops.horizon.matching import MatchResult, match
from loops.horizon.params import HorizonParams
from loops.horizon.signal import HorizonLine
from loops.horizon.surf1d import HorizonFeatures
from odometry.shared.atomic_io import atomic_path

MEMORY_VERSION = 1
_FORMAT = "vslam.horizon.memory"


class MemoryFormatError(LoopsError):
    """A landmark memory file that cannot be read; the message names the file and the problem."""


@dataclass(frozen=True)
class Landmark:
    name: str
    features: HorizonFeatures
    source: str = ""                     # where the features came from (an image path), for the user
    horizon: HorizonLine = HorizonLine(float("nan"), float("nan"))


@dataclass(frozen=True)
class Recognition:
    """Which stored landmark a horizon shows.

    name: the best landmark when its NN+RANSAC score reaches the threshold, else None.
    best: the best-scoring landmark whatever the threshold (None for an empty memory); result: its MatchResult.
    scores: NN+RANSAC score against every landmark, in memory order.
    """

    name: str | None
    best: str | None
    result: MatchResult | None
    scores: dict[str, float]
    threshold: float

    @property
    def score(self) -> float:
        return self.result.score_ransac if self.result is not None else 0.0


@dataclass
class LandmarkMemory:
    params: HorizonParams = field(default_factory=HorizonParams)
    landmarks: list[Landmark] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.landmarks)

    @property
    def names(self) -> list[str]:
        return [lm.name for lm in self.landmarks]

    def add(self, name: str, features: HorizonFeatures, source: str = "",
            horizon: HorizonLine | float | None = None) -> Landmark:
        """Memorise `features` under `name` (names are unique)."""
        if name in self.names:
            raise LoopsError(f"landmark {name!r} is already in the memory")
        dim = 2 * self.params.subregions
        if features.descriptor.ndim != 2 or features.descriptor.shape[1] != dim:
            raise LoopsError(f"landmark {name!r}: descriptors of size {features.descriptor.shape[1:]} do not match "
                             f"the memory's parameters (size {dim})")
        if horizon is None:
            horizon = HorizonLine(float("nan"), float("nan"))
        elif not isinstance(horizon, HorizonLine):
            horizon = HorizonLine.level(float(horizon))
        lm = Landmark(str(name), features, str(source), horizon)
        self.landmarks.append(lm)
        return lm

    def match_all(self, features: HorizonFeatures) -> list[MatchResult]:
        return [match(features, lm.features, self.params) for lm in self.landmarks]

    def recognise(self, features: HorizonFeatures, threshold: float | None = None) -> Recognition:
        """Match `features` against every landmark; recognised when the best NN+RANSAC score >= threshold
        (default params.recognition_threshold)."""
        thr = self.params.recognition_threshold if threshold is None else float(threshold)
        results = self.match_all(features)
        scores = {lm.name: r.score_ransac for lm, r in zip(self.landmarks, results)}
        if not results:
            return Recognition(None, None, None, scores, thr)
        k = int(np.argmax([r.score_ransac for r in results]))
        best = self.landmarks[k].name
        name = best if results[k].score_ransac >= thr else None
        return Recognition(name, best, results[k], scores, thr)

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
        "counts": np.array([len(lm.features) for lm in lms], dtype=np.int64),
    }
    for name, dtype in _FEATURE_FIELDS.items():
        parts = [np.asarray(getattr(lm.features, name), dtype=dtype) for lm in lms]
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
    if version != MEMORY_VERSION:
        raise bad(f"version {version} is not supported (this code reads version {MEMORY_VERSION})")
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
    ends = np.cumsum(counts)
    starts = ends - counts
    for i in range(n_lm):
        sl = slice(int(starts[i]), int(ends[i]))
        feats = HorizonFeatures(**{k: data[k][sl].astype(t) for k, t in _RUNTIME_DTYPES.items()},
                                width=int(data["widths"][i]))
        h = data["horizons"][i]
        memory.add(str(names[i]), feats, str(data["sources"][i]), HorizonLine(float(h[0]), float(h[1])))
    return memory
