"""Node ids as exact integers at any size.

Ids are int64 arrays when every id fits (the common case, fast), else object arrays of Python ints: nanosecond
timestamps (~1.7e18) fit int64 but not float64's 53-bit mantissa, and unsigned 64-bit keys (>= 2^63) fit neither,
so ids never pass through float64 or a wrapping cast. gtsam never sees them: solvers key nodes by position.
"""
from __future__ import annotations

import numpy as np

INT64_MIN = -(2 ** 63)
INT64_MAX = 2 ** 63 - 1


def id_array(ids) -> np.ndarray:
    """(N,) ids: int64 when all fit, else dtype=object holding Python ints. Never rounds or wraps."""
    if isinstance(ids, np.ndarray) and ids.dtype != object:
        a = ids.reshape(-1)
        if a.dtype.kind == "u" and a.size and int(a.max()) > INT64_MAX:
            return _to_object(a)
        return a.astype(np.int64, copy=False)     # int arrays, and float arrays such as np.asarray([])
    # anything else goes through Python ints: np.asarray([2**63, -1]) would silently be float64
    values = [int(v) for v in _flatten(ids)]
    if all(INT64_MIN <= v <= INT64_MAX for v in values):
        return np.asarray(values, dtype=np.int64)
    out = np.empty(len(values), dtype=object)
    out[:] = values
    return out


def _flatten(seq) -> list:
    if isinstance(seq, np.ndarray):
        seq = seq.reshape(-1).tolist()
    if not isinstance(seq, (list, tuple)):
        return [seq]
    out = []
    for v in seq:
        out.extend(_flatten(v) if isinstance(v, (list, tuple, np.ndarray)) else [v])
    return out


def common_ids(*arrays: np.ndarray) -> list[np.ndarray]:
    """The arrays with one dtype: object for all when any needs it (comparisons and searches stay exact)."""
    if any(a.dtype == object for a in arrays):
        return [a if a.dtype == object else _to_object(a) for a in arrays]
    return list(arrays)


def _to_object(a: np.ndarray) -> np.ndarray:
    out = np.empty(len(a), dtype=object)
    out[:] = [int(v) for v in a.tolist()]
    return out
