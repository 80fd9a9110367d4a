"""Read and write pose graphs: g2o (2D and 3D) and TORO (.graph), keeping ids, edge order, information and comments.

g2o records
    VERTEX_SE2 id x y theta
    EDGE_SE2 i j dx dy dtheta  I11 I12 I13 I22 I23 I33                  (upper triangle, row by row)
    VERTEX_SE3:QUAT id x y z qx qy qz qw
    EDGE_SE3:QUAT i j dx dy dz qx qy qz qw  I11 .. I16 I22 .. I66       (21 values, order x y z rx ry rz)
    FIX id [id ...]                                                      (vertices held fixed: the anchor)
TORO records
    VERTEX2 id x y theta
    EDGE2 i j dx dy dtheta  Ixx Ixy Iyy Itt Ixt Iyt                      (TORO's own order, NOT g2o's)
    VERTEX3 id x y z roll pitch yaw
    EDGE3 i j dx dy dz roll pitch yaw  I11 .. I16 I22 .. I66             (upper triangle over x y z roll pitch yaw)
    EQUIV i j                                                            (kept verbatim, ignored by the solver)
Lines starting with '#' are comments; they are kept and written back in place. Any other record type, a wrong
field count, a non-numeric or non-finite value, a duplicate vertex, a zero quaternion or an information matrix
that is not symmetric positive definite raises `GraphFormatError` naming file:line.

Numbers are written with Python's shortest round-trip representation, so read -> write -> read is exact.
TORO's roll/pitch/yaw are converted to and from quaternions with R = Rz(yaw) Ry(pitch) Rx(roll); its
information over (roll, pitch, yaw) is used as information over the rotation vector (first order, as gtsam does).
"""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from graph.errors import GraphError
from graph.model import POSE_WIDTH, TANGENT_DIM, PoseGraphData, classify_edges
from odometry.shared.atomic_io import atomic_write_text
from odometry.shared.rotations import quat_to_rotmat


class GraphFormatError(GraphError):
    """A malformed pose-graph file; the message names file:line and the problem."""

    def __init__(self, path: str | os.PathLike, line: int | None, problem: str):
        self.path = Path(path)
        self.line = line
        self.problem = problem
        super().__init__(f"{self.path}{'' if line is None else f':{line}'}: {problem}")


# tag -> (format, dim, kind, number of numeric fields after the tag)
_TAGS = {
    "VERTEX_SE2": ("g2o", 2, "V", 4), "EDGE_SE2": ("g2o", 2, "E", 11),
    "VERTEX_SE3:QUAT": ("g2o", 3, "V", 8), "EDGE_SE3:QUAT": ("g2o", 3, "E", 30),
    "VERTEX2": ("toro", 2, "V", 4), "EDGE2": ("toro", 2, "E", 11),
    "VERTEX3": ("toro", 3, "V", 7), "EDGE3": ("toro", 3, "E", 29),
}
_G2O_INFO_2D = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])      # I11 I12 I13 I22 I23 I33
_TORO_INFO_2D = np.array([[0, 1, 4], [1, 2, 5], [4, 5, 3]])     # Ixx Ixy Iyy Itt Ixt Iyt
_TORO_WRITE_2D = [(0, 0), (0, 1), (1, 1), (2, 2), (0, 2), (1, 2)]


def _sym_from_upper(vals: np.ndarray, d: int) -> np.ndarray:
    """(M, d(d+1)/2) upper-triangle values, row by row -> (M, d, d) symmetric."""
    iu = np.triu_indices(d)
    out = np.zeros((len(vals), d, d))
    out[:, iu[0], iu[1]] = vals
    out[:, iu[1], iu[0]] = vals
    return out


def _fmt(v: float) -> str:
    r = repr(float(v))
    return r[:-2] if r.endswith(".0") else r          # "1.0" -> "1": files stay compact, parsing is unchanged


def _fmt_row(row) -> str:
    return " ".join(_fmt(v) for v in row)


# ------------------------------------------------------------------------------------------------------- rpy
def rpy_to_quat(rpy: np.ndarray) -> np.ndarray:
    """(N, 3) roll, pitch, yaw -> (N, 4) qx qy qz qw for R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (np.asarray(rpy, float).reshape(-1, 3)[:, k] / 2 for k in range(3))
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    q = np.stack([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy,
                  cr * cp * cy + sr * sp * sy], -1)
    return q * np.where(q[:, 3:4] < 0, -1.0, 1.0)


def quat_to_rpy(q: np.ndarray) -> np.ndarray:
    """(N, 4) qx qy qz qw -> (N, 3) roll, pitch, yaw (inverse of `rpy_to_quat`)."""
    m = quat_to_rotmat(np.asarray(q, float).reshape(-1, 4))
    pitch = np.arcsin(np.clip(-m[:, 2, 0], -1.0, 1.0))
    return np.stack([np.arctan2(m[:, 2, 1], m[:, 2, 2]), pitch, np.arctan2(m[:, 1, 0], m[:, 0, 0])], -1)


# ------------------------------------------------------------------------------------------------------ read
def sniff_format(path: str | os.PathLike) -> str:
    """'g2o' or 'toro', from the first record tag in the file."""
    path = Path(path)
    with open(path, encoding="utf-8", errors="replace") as f:
        for lineno, line in enumerate(f, 1):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            tag = s.split()[0]
            if tag in _TAGS:
                return _TAGS[tag][0]
            if tag in ("FIX",):
                return "g2o"
            if tag == "EQUIV":
                return "toro"
            raise GraphFormatError(path, lineno, f"unknown record type {tag!r}; expected one of "
                                                 f"{', '.join(sorted(_TAGS))}, FIX or EQUIV")
    raise GraphFormatError(path, None, "no vertex or edge records (empty pose-graph file)")


def read_graph(path: str | os.PathLike, toro_info_order: str = "auto") -> PoseGraphData:
    """Read a g2o or TORO file (format detected from the first record)."""
    fmt = sniff_format(path)
    return read_g2o(path) if fmt == "g2o" else read_toro(path, info_order=toro_info_order)


def read_g2o(path: str | os.PathLike) -> PoseGraphData:
    """Read a g2o file: VERTEX_SE2 / EDGE_SE2 or VERTEX_SE3:QUAT / EDGE_SE3:QUAT, FIX, comments."""
    return _read(Path(path), "g2o")


def read_toro(path: str | os.PathLike, info_order: str = "auto") -> PoseGraphData:
    """Read a TORO file: VERTEX2 / EDGE2 (or VERTEX3 / EDGE3), EQUIV, comments.

    `info_order` for EDGE2: 'toro' (Ixx Ixy Iyy Itt Ixt Iyt), 'g2o' (I11 I12 I13 I22 I23 I33, used by iSAM's
    EDGE2 files) or 'auto' (TORO unless some matrix is not positive definite in TORO order but all are in g2o order).
    """
    if info_order not in ("auto", "toro", "g2o"):
        raise ValueError(f"info_order must be auto, toro or g2o, got {info_order!r}")
    return _read(Path(path), "toro", info_order)


def _read(path: Path, fmt: str, info_order: str = "toro") -> PoseGraphData:
    dim = None
    v_ids, v_vals, v_lines = [], [], []
    e_vals, e_lines = [], []
    fixed, comments, extras, layout = [], [], [], []
    with open(path, encoding="utf-8", errors="replace") as f:
        for lineno, line in enumerate(f, 1):
            s = line.strip()
            if not s:
                continue
            if s.startswith("#"):
                layout.append(("#", len(comments)))
                comments.append(line.rstrip("\r\n"))
                continue
            parts = s.split("#", 1)[0].split()
            tag = parts[0]
            if tag == "FIX" and fmt == "g2o":
                try:
                    ids = [int(p) for p in parts[1:]]
                except ValueError:
                    raise GraphFormatError(path, lineno, f"FIX: vertex ids must be integers, got {s!r}") from None
                if not ids:
                    raise GraphFormatError(path, lineno, "FIX without a vertex id")
                layout.append(("X", len(extras)))
                extras.append(s)
                fixed.extend(ids)
                continue
            if tag == "EQUIV" and fmt == "toro":
                layout.append(("X", len(extras)))
                extras.append(s)
                continue
            spec = _TAGS.get(tag)
            if spec is None or spec[0] != fmt:
                allowed = sorted(t for t, v in _TAGS.items() if v[0] == fmt) + (["FIX"] if fmt == "g2o" else ["EQUIV"])
                raise GraphFormatError(path, lineno, f"unknown record type {tag!r} in a {fmt} file; expected one of "
                                                     f"{', '.join(allowed)}")
            _, tdim, kind, nfields = spec
            if dim is None:
                dim = tdim
            elif tdim != dim:
                raise GraphFormatError(path, lineno, f"{tag} is a {tdim}D record in a {dim}D graph (2D and 3D mixed)")
            if len(parts) - 1 != nfields:
                raise GraphFormatError(path, lineno, f"{tag} needs {nfields} fields after the tag, got {len(parts) - 1}")
            nid = 1 if kind == "V" else 2
            try:
                ids = [int(p) for p in parts[1:1 + nid]]
            except ValueError:
                raise GraphFormatError(path, lineno, f"{tag}: vertex ids must be integers, got "
                                                     f"{' '.join(parts[1:1 + nid])!r}") from None
            try:
                vals = [float(p) for p in parts[1 + nid:]]
            except ValueError:
                bad = next(p for p in parts[1 + nid:] if not _is_float(p))
                raise GraphFormatError(path, lineno, f"{tag}: non-numeric value {bad!r}") from None
            if not all(math.isfinite(v) for v in vals):
                raise GraphFormatError(path, lineno, f"{tag}: NaN or infinite value")
            if kind == "V":
                layout.append(("V", len(v_ids)))
                v_ids.append(ids[0])
                v_vals.append(vals)
                v_lines.append(lineno)
            else:
                layout.append(("E", len(e_vals)))
                e_vals.append(ids + vals)
                e_lines.append(lineno)
    if dim is None:
        raise GraphFormatError(path, None, "no vertex or edge records (empty pose-graph file)")
    return _assemble(path, fmt, dim, info_order, v_ids, v_vals, v_lines, e_vals, e_lines, fixed, comments, extras,
                     layout)


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _assemble(path, fmt, dim, info_order, v_ids, v_vals, v_lines, e_vals, e_lines, fixed, comments, extras, layout):
    w = POSE_WIDTH[dim]
    v_ids = np.asarray(v_ids, np.int64)
    uniq, first = np.unique(v_ids, return_index=True)
    if len(uniq) != len(v_ids):
        dup_pos = np.setdiff1d(np.arange(len(v_ids)), first)[0]
        raise GraphFormatError(path, v_lines[dup_pos], f"duplicate vertex id {int(v_ids[dup_pos])}")
    vv = np.asarray(v_vals, float).reshape(len(v_ids), 3 if dim == 2 else (6 if fmt == "toro" else 7))
    if dim == 2:
        poses = vv.reshape(-1, 3)
    elif fmt == "toro":
        poses = np.column_stack([vv[:, :3], rpy_to_quat(vv[:, 3:6])]) if len(vv) else np.zeros((0, 7))
    else:
        poses = _normalised_quats(path, vv.reshape(-1, 7), v_lines, "vertex")
    ev = np.asarray(e_vals, float).reshape(len(e_vals), 11 if dim == 2 else (29 if fmt == "toro" else 30))
    e_lines = np.asarray(e_lines)
    ei = ev[:, 0].astype(np.int64) if len(ev) else np.zeros(0, np.int64)
    ej = ev[:, 1].astype(np.int64) if len(ev) else np.zeros(0, np.int64)
    if dim == 2:
        meas = ev[:, 2:5] if len(ev) else np.zeros((0, 3))
        raw = ev[:, 5:11] if len(ev) else np.zeros((0, 6))
        if fmt == "g2o":
            info = raw[:, _G2O_INFO_2D]
        else:
            info = raw[:, _TORO_INFO_2D]
            if info_order == "g2o" or (info_order == "auto" and not _all_pd(info) and _all_pd(raw[:, _G2O_INFO_2D])):
                info = raw[:, _G2O_INFO_2D]
    else:
        if fmt == "g2o":
            meas = _normalised_quats(path, ev[:, 2:9], e_lines, "edge") if len(ev) else np.zeros((0, 7))
            info = _sym_from_upper(ev[:, 9:30], 6) if len(ev) else np.zeros((0, 6, 6))
        else:
            meas = np.column_stack([ev[:, 2:5], rpy_to_quat(ev[:, 5:8])]) if len(ev) else np.zeros((0, 7))
            info = _sym_from_upper(ev[:, 8:29], 6) if len(ev) else np.zeros((0, 6, 6))
    _check_information(path, info, e_lines)
    # node order: vertex lines first, then ids seen only on edges (ascending)
    extra_ids = np.setdiff1d(np.concatenate([ei, ej]), v_ids)
    node_ids = np.concatenate([v_ids, extra_ids])
    all_poses = np.vstack([poses.reshape(-1, w), np.full((len(extra_ids), w), np.nan)])
    fixed_ids = np.unique(np.asarray(fixed, np.int64))
    unknown_fix = np.setdiff1d(fixed_ids, node_ids)
    if len(unknown_fix):
        k = next(n for n, x in enumerate(extras) if x.split()[0] == "FIX" and str(int(unknown_fix[0])) in x.split()[1:])
        fix_line = _line_of(path, layout, ("X", k))
        raise GraphFormatError(path, fix_line, f"FIX names vertex {int(unknown_fix[0])}, which no record defines")
    self_loops = np.flatnonzero(ei == ej)
    if len(self_loops):
        raise GraphFormatError(path, int(e_lines[self_loops[0]]), f"edge from vertex {int(ei[self_loops[0]])} to itself")
    return PoseGraphData(dim, node_ids, all_poses, ei, ej, meas, info, classify_edges(node_ids, ei, ej),
                         np.ones(len(ei)), fixed_ids, comments, extras, layout)


def _line_of(path: Path, layout, rec) -> int | None:
    # only used on the error path: re-read the file to find the record's line
    k = layout.index(rec)
    n = -1
    with open(path, encoding="utf-8", errors="replace") as f:
        for lineno, line in enumerate(f, 1):
            if line.strip():
                n += 1
                if n == k:
                    return lineno
    return None


def _normalised_quats(path, arr, lines, what) -> np.ndarray:
    arr = np.asarray(arr, float).copy()
    norms = np.linalg.norm(arr[:, 3:7], axis=1)
    bad = np.flatnonzero(norms < 1e-12)
    if len(bad):
        raise GraphFormatError(path, int(lines[bad[0]]), f"{what} has a zero quaternion")
    # keep values exactly as written when already unit length (round trips stay bit-exact)
    off = np.abs(norms - 1.0) > 1e-9
    arr[off, 3:7] /= norms[off, None]
    return arr


def _all_pd(info: np.ndarray) -> bool:
    if len(info) == 0:
        return True
    return bool(np.all(np.linalg.eigvalsh(info)[:, 0] > 0))


def _check_information(path: Path, info: np.ndarray, lines: np.ndarray) -> None:
    if len(info) == 0:
        return
    scale = np.maximum(np.abs(info).max(axis=(1, 2)), 1e-300)
    asym = np.abs(info - np.swapaxes(info, 1, 2)).max(axis=(1, 2)) > 1e-9 * scale
    ev = np.linalg.eigvalsh(info)
    bad = np.flatnonzero(asym | (ev[:, 0] <= 0))
    if len(bad):
        k = bad[0]
        raise GraphFormatError(path, int(lines[k]), f"information matrix is not positive definite "
                                                    f"(smallest eigenvalue {ev[k, 0]:.3g})")


# ----------------------------------------------------------------------------------------------------- write
def format_g2o(data: PoseGraphData, poses: np.ndarray | None = None) -> str:
    """g2o text for `data`; `poses` (N, 3|7), in node order, replaces the vertex guesses (e.g. a solution)."""
    return _format(data, "g2o", poses)


def format_toro(data: PoseGraphData, poses: np.ndarray | None = None) -> str:
    """TORO text for `data` (see module docstring for the record layout)."""
    return _format(data, "toro", poses)


def write_g2o(path: str | os.PathLike, data: PoseGraphData, poses: np.ndarray | None = None) -> None:
    """Write a g2o file atomically (vertices get `poses` if given, else the graph's guesses)."""
    atomic_write_text(path, format_g2o(data, poses))


def write_toro(path: str | os.PathLike, data: PoseGraphData, poses: np.ndarray | None = None) -> None:
    atomic_write_text(path, format_toro(data, poses))


def write_graph(path: str | os.PathLike, data: PoseGraphData, poses: np.ndarray | None = None,
                fmt: str | None = None) -> None:
    """Write g2o, or TORO when `fmt` is 'toro' or the file name ends in .graph."""
    fmt = fmt or ("toro" if str(path).endswith(".graph") else "g2o")
    if fmt not in ("g2o", "toro"):
        raise ValueError(f"unknown pose-graph format {fmt!r} (g2o or toro)")
    atomic_write_text(path, _format(data, fmt, poses))


def _vertex_lines(data: PoseGraphData, fmt: str, poses: np.ndarray) -> list[str | None]:
    out: list[str | None] = []
    for nid, p in zip(data.node_ids.tolist(), poses):
        if np.isnan(p).any():
            out.append(None)
            continue
        if data.dim == 2:
            out.append(f"{'VERTEX_SE2' if fmt == 'g2o' else 'VERTEX2'} {nid} {_fmt_row(p)}")
        elif fmt == "g2o":
            out.append(f"VERTEX_SE3:QUAT {nid} {_fmt_row(p)}")
        else:
            out.append(f"VERTEX3 {nid} {_fmt_row(np.concatenate([p[:3], quat_to_rpy(p[3:7])[0]]))}")
    return out


def _edge_lines(data: PoseGraphData, fmt: str) -> list[str]:
    d = TANGENT_DIM[data.dim]
    info = data.information
    if data.dim == 2 and fmt == "toro":
        tri = np.stack([info[:, a, b] for a, b in _TORO_WRITE_2D], -1)
    else:
        iu = np.triu_indices(d)
        tri = info[:, iu[0], iu[1]]
    meas = data.measurements
    if data.dim == 3 and fmt == "toro":
        meas = np.column_stack([meas[:, :3], quat_to_rpy(meas[:, 3:7])]) if len(meas) else np.zeros((0, 6))
    tag = {("g2o", 2): "EDGE_SE2", ("g2o", 3): "EDGE_SE3:QUAT", ("toro", 2): "EDGE2", ("toro", 3): "EDGE3"}[(fmt, data.dim)]
    return [f"{tag} {i} {j} {_fmt_row(m)} {_fmt_row(t)}"
            for i, j, m, t in zip(data.edge_from.tolist(), data.edge_to.tolist(), meas, tri)]


def _format(data: PoseGraphData, fmt: str, poses: np.ndarray | None) -> str:
    w = POSE_WIDTH[data.dim]
    poses = data.poses if poses is None else np.asarray(poses, float).reshape(-1, w)
    if len(poses) != data.num_nodes:
        raise ValueError(f"{len(poses)} poses for {data.num_nodes} nodes")
    vlines = _vertex_lines(data, fmt, poses)
    elines = _edge_lines(data, fmt)
    # verbatim extra lines are format-specific: FIX exists only in g2o, EQUIV only in TORO
    keep_tag = "FIX" if fmt == "g2o" else "EQUIV"
    xlines = [x if x.split()[0] == keep_tag else None for x in data.extras]
    has_fix_line = any(x is not None and x.startswith("FIX") for x in xlines)
    flines = [f"FIX {' '.join(str(i) for i in data.fixed.tolist())}"] if (
        fmt == "g2o" and len(data.fixed) and not has_fix_line) else []
    n_file_vertices = sum(1 for kind, _ in data.layout if kind == "V")
    use_layout = (data.layout and n_file_vertices <= data.num_nodes
                  and sum(1 for kind, _ in data.layout if kind == "E") == data.num_edges)
    out: list[str] = []
    if use_layout:
        # vertices the file did not define (edge-only files) go right before the first edge
        pending = [ln for ln in vlines[n_file_vertices:] if ln is not None]
        for kind, k in data.layout:
            if kind == "E" and pending:
                out += pending
                pending = []
            if kind == "V":
                if vlines[k] is not None:
                    out.append(vlines[k])
            elif kind == "E":
                out.append(elines[k])
            elif kind == "#":
                out.append(data.comments[k])
            elif kind == "X" and k < len(xlines) and xlines[k] is not None:
                out.append(xlines[k])
        out += pending
        out += flines
    else:
        out += data.comments
        out += [ln for ln in vlines if ln is not None]
        out += flines
        out += [x for x in xlines if x is not None and x.startswith("FIX")]
        out += elines
        out += [x for x in xlines if x is not None and not x.startswith("FIX")]
    return "\n".join(out) + "\n"
