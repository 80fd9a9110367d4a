"""Packed 1D SURF (`loops.horizon.packed`, presets `fast` and `lone`) against full-image ORB + RANSAC, accuracy and
time, on the same frames in the same run; each preset twice, compiled (numba, when installed) and with the numpy
fallback.

How the time is compared (all methods, same images, same pairs, same process, one thread each: OpenCV
single-threaded, BLAS single-threaded by the CLI; thread CPU time, so that time spent waiting for other
processes on a shared machine does not count; the methods take turns every 16 images / 16 test views, each block
starting with the next method, so that a change of load hits all, while each runs its own loop as it would in
use):

- per image: one extraction call (a frame as it arrives), median over the images.
- per pair, matching: median over the pairs. ORB matches one pair per call (its cost does not depend on the
  others). The packed method matches a test view against all its stored candidates of the bank in one call; each
  pair is charged the call's time / candidates.
- per pair, query against every stored view: the packed method matches a test view against all stored views of
  the bank in one call (what a place recogniser does); time / stored views, median over the test views. ORB: the
  same as its pair matching.
- per pair, strict: 2 extractions + 1 matching (each pair pays both its images' extraction).
- per pair, every test view against every stored view: matching against every stored view + (extraction x
  (test views + stored views) + stacking x stored views) / (test views x stored views): each image extracted
  once; stacking = the packed method's building of the stored set (per stored view, once; ORB has none).
"""
from __future__ import annotations

import functools
import time
from collections import defaultdict
from dataclasses import dataclass

import cv2
import numpy as np

from loops.curves import auc
from loops.horizon import HorizonParams
from loops.horizon.packed import compiled_kernels, extract_packed, match_packed, stack_packed
from vslam.bench.horizon_real import OrbRansac
from vslam.evaluation.tables import format_table

ORB = "ORB(1000) + RANSAC, native size"
EXTRACT_CALLS = 33   # array operations in one numpy extract_packed (loops/horizon/packed.py, COLUMN sampling, step > 1)
MATCH_CALLS = 60     # array operations in one numpy match_packed call with `which` (whatever the number of views)
NUMBA, NUMPY = "numba", "numpy"
BLOCK = 16   # images or test views per block: the methods take turns block by block


@dataclass
class PairSet:
    """Images (name -> grey array), their horizon rows, pairs (stored, test) with labels, and a half per pair
    (0 tuning, 1 reporting; one half only for a set nothing was tuned on)."""

    images: dict[str, np.ndarray]
    rows: dict[str, float]
    pairs: list[tuple[str, str]]
    labels: np.ndarray
    half: np.ndarray


@dataclass
class _Measured:
    scores: dict[str, np.ndarray]                  # method -> (P,) score
    ext_us: dict[str, dict[str, float]]            # method -> image -> extraction us
    match_us: dict[str, np.ndarray]                # method -> (P,) matching us charged to each pair
    all_us: dict[str, dict[str, float]]            # packed method -> test image -> us / pair against every view
    stack_us: dict[str, float]                     # packed method -> building the stored set, us per stored view
    call_us: float                                 # one trivial array call (the per-call floor), median
    first_ms: dict[str, float]                     # compiled method -> its first (untimed) call, wall ms


def fast_name(params: HorizonParams, preset: str = "fast", backend: str = NUMPY) -> str:
    return (f"1D SURF packed, preset {preset}, {backend} ({params.bands} bands, {params.max_features} features / "
            f"band, step {params.step}, shift consensus)")


def backends() -> list[str]:
    """The packed backends this machine can run: numba (the compiled kernels) when installed, and numpy."""
    return [NUMBA, NUMPY] if compiled_kernels() is not None else [NUMPY]


def _warm_up(ps: PairSet, packed: dict[str, tuple[HorizonParams, bool]]) -> dict[str, float]:
    """One untimed extraction and matching per compiled method before the measured run (the first call compiles
    the kernel, or loads it from numba's cache); returns that first call's wall time, ms, per method."""
    name = next(iter(ps.images))
    out = {}
    for method, (params, compiled) in packed.items():
        if not compiled:
            continue
        t0 = time.perf_counter()
        f = extract_packed(ps.images[name], ps.rows[name], params, compiled=True)
        match_packed(f, stack_packed([f, f]), params, compiled=True)
        out[method] = (time.perf_counter() - t0) * 1e3
    return out


def _trivial_calls(clock, n: int = 8, per: int = 16) -> list[float]:
    """Thread time of a trivial array call (np.add of two 16-element arrays), us each, from n runs of `per` calls
    (so the clock's own cost is spread): the per-call cost that bounds a method made of a few dozen array
    operations on small arrays."""
    a, b = np.ones(16), np.ones(16)
    out = []
    for _ in range(n):
        t0 = clock()
        for _ in range(per):
            np.add(a, b)
        out.append((clock() - t0) / 1e3 / per)
    return out


def _turns(methods: list, i: int) -> list:
    """The methods in block i's order: each block starts with the next one."""
    k = i % len(methods)
    return methods[k:] + methods[:k]


def _blocks(items: list, size: int = BLOCK) -> list[list]:
    return [items[i:i + size] for i in range(0, len(items), size)]


def _measure(ps: PairSet, packed: dict[str, tuple[HorizonParams, bool]]) -> _Measured:
    """Every packed method (name -> (params, compiled)) and ORB on the same images and pairs, taking turns block by
    block."""
    cv2.setNumThreads(1)
    first_ms = _warm_up(ps, packed)
    clock = time.thread_time_ns
    orb = OrbRansac()
    methods = [*packed, ORB]
    feats: dict[str, dict] = {m: {} for m in methods}
    ext: dict[str, dict[str, float]] = {m: {} for m in methods}
    extractors = {ORB: lambda im, row: orb.extract(im)}
    for name, (params, compiled) in packed.items():
        extractors[name] = functools.partial(lambda im, row, p, c: extract_packed(im, row, p, compiled=c),
                                             p=params, c=compiled)
    calls: list[float] = []
    for i, block in enumerate(_blocks(list(ps.images))):
        calls += _trivial_calls(clock)
        for method in _turns(methods, i):
            for name in block:
                t0 = clock()
                feats[method][name] = extractors[method](ps.images[name], ps.rows[name])
                ext[method][name] = (clock() - t0) / 1e3
    stored_names = sorted({a for a, _ in ps.pairs})
    col = {n: i for i, n in enumerate(stored_names)}
    dbs, stack_us = {}, {}
    for name in packed:
        t0 = clock()
        dbs[name] = stack_packed([feats[name][n] for n in stored_names])
        stack_us[name] = (clock() - t0) / 1e3 / len(stored_names)
    groups: dict[str, list[int]] = defaultdict(list)
    for p, (_, b) in enumerate(ps.pairs):
        groups[b].append(p)
    n = len(ps.pairs)
    scores = {m: np.zeros(n) for m in methods}
    match_us = {m: np.zeros(n) for m in methods}
    all_us: dict[str, dict[str, float]] = {m: {} for m in packed}

    def packed_block(method: str, block: list[str]) -> None:
        (params, compiled), db = packed[method], dbs[method]
        for b in block:
            idx = groups[b]
            which = np.array([col[ps.pairs[p][0]] for p in idx])
            t0 = clock()
            r = match_packed(feats[method][b], db, params, which, compiled=compiled)
            t = (clock() - t0) / 1e3
            scores[method][idx] = r.score_ransac
            match_us[method][idx] = t / len(idx)
            t0 = clock()
            match_packed(feats[method][b], db, params, compiled=compiled)
            all_us[method][b] = (clock() - t0) / 1e3 / len(stored_names)

    def orb_block(block: list[str]) -> None:
        for b in block:
            for p in groups[b]:
                t0 = clock()
                scores[ORB][p] = orb.match(feats[ORB][b], feats[ORB][ps.pairs[p][0]])
                match_us[ORB][p] = (clock() - t0) / 1e3

    for i, block in enumerate(_blocks(list(groups))):
        for method in _turns(methods, i):
            orb_block(block) if method == ORB else packed_block(method, block)
    return _Measured(scores, ext, match_us, all_us, stack_us, float(np.median(calls)), first_ms)


def _half_figures(ps: PairSet, m: _Measured, method: str, sel: np.ndarray) -> dict:
    pairs = [ps.pairs[p] for p in np.flatnonzero(sel)]
    stored, tests = sorted({a for a, _ in pairs}), sorted({b for _, b in pairs})
    ext = float(np.median([m.ext_us[method][k] for k in sorted(set(stored) | set(tests))]))
    match = float(np.median(m.match_us[method][sel]))
    every = match if method == ORB else float(np.median([m.all_us[method][b] for b in tests]))
    stack = 0.0 if method == ORB else m.stack_us[method]
    y = ps.labels[sel]
    return {"auc": auc(m.scores[method][sel], y), "pairs": int(sel.sum()), "test_views": len(tests),
            "stored_views": len(stored), "extraction_us": ext, "matching_us": match, "matching_every_us": every,
            "strict_us": 2 * ext + match,
            "stacking_us": stack,
            "every_pair_us": every + (ext * (len(tests) + len(stored)) + stack * len(stored)) / (len(tests) * len(stored))}


def compare(ps: PairSet, packed: dict[str, HorizonParams], halves: dict[str, int | None]) -> tuple[str, dict]:
    """Table of AUC and per-image / per-pair times of every packed preset (preset name -> params), on each backend
    (numba and numpy, or numpy alone without numba), and ORB on each half (name -> half id, None = all), and each
    preset's time ratios to ORB's (keys "preset, backend")."""
    named, label = {}, {}
    for preset, p in packed.items():
        for backend in backends():
            named[fast_name(p, preset, backend)] = (p, backend == NUMBA)
            label[fast_name(p, preset, backend)] = f"{preset}, {backend}"
    m = _measure(ps, named)
    res: dict[str, dict] = {}
    rows, ratio_rows = [], []
    cols = ("extraction_us", "matching_us", "matching_every_us", "strict_us", "every_pair_us")
    for half_name, h in halves.items():
        sel = np.ones(len(ps.pairs), bool) if h is None else ps.half == h
        res[half_name] = {meth: _half_figures(ps, m, meth, sel) for meth in (*named, ORB)}
        o = res[half_name][ORB]
        for meth in (*named, ORB):
            r = res[half_name][meth]
            rows.append([half_name, meth, r["pairs"], r["auc"], *(r[c] for c in cols)])
        res[half_name]["orb_over_packed"] = {}
        for meth in named:
            f = res[half_name][meth]
            ratio_rows.append([half_name, label[meth], f["auc"] - o["auc"], *(o[c] / f[c] for c in cols)])
            res[half_name]["orb_over_packed"][label[meth]] = {c: o[c] / f[c] for c in cols}
    names = ["extraction / image", "matching / pair (its candidates)", "matching / pair (against every stored view)",
             "per pair, strict (2 extractions + matching)", "per pair, every test x every stored view"]
    table = format_table(["half", "method", "pairs", "AUC", *(f"{n}, us" for n in names)], rows, floatfmt=".3g")
    ratios = format_table(["half", "preset", "AUC, packed - ORB", *(f"ORB / packed, {n}" for n in names)],
                          ratio_rows, floatfmt=".3g")
    res["trivial_call_us"] = m.call_us
    res["first_call_ms"] = {label[k]: v for k, v in m.first_ms.items()}
    floor = (f"One trivial array call (np.add of two 16-element arrays, timed between the blocks of this run): "
             f"{m.call_us:.2g} us median. A numpy packed extraction is {EXTRACT_CALLS} array operations, a numpy "
             f"packed matching call {MATCH_CALLS} (shared by its candidates): at that cost alone a strict pair with "
             f"about 9 candidates per test view is >= {m.call_us * (2 * EXTRACT_CALLS + MATCH_CALLS / 9):.2g} us. "
             "The numba rows are one compiled call each.")
    if m.first_ms:
        floor += (" First compiled call of each preset (extraction + matching, untimed in the table; compiles, or "
                  "loads numba's cache): " + ", ".join(f"{label[k]} {v:.0f} ms" for k, v in m.first_ms.items())
                  + ".")
    return f"{table}\n\n{ratios}\n\n{floor}", res
