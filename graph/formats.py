"""Read and write pose graphs: g2o (2D and 3D) and TORO (.graph), keeping ids, edge order, information and comments.

g2o records
    VERTEX_SE2 id x y theta
    EDGE_SE2 i j dx dy dtheta  I11 I12 I13 I22 I23 I33                  (upper triangle, row by row)
    VERTEX_SE3:QUAT id x y z qx qy qz qw
    EDGE_SE3:QUAT i j dx dy dz qx qy qz qw  I11 .. I16 I22 .. I66       (21 values, order x y z rx ry rz)
    FIX id [id ...]                                                      (vertices held fixed: the anchor)
    PARAMS_* / other VERTEX_* / EDGE_* (PARAMS_SE3OFFSET, VERTEX_TRACKXYZ, EDGE_SE3_PRIOR, VERTEX_XY, ...: what g2o
    and RTAB-Map write besides poses) are not optimised: kept verbatim for g2o output, one `GraphFormatWarning`
    counts them per type. A UTF-8 byte-order mark is ignored.
TORO records
    VERTEX2 id x y theta
    EDGE2 i j dx dy dtheta  Ixx Ixy Iyy Itt Ixt Iyt                      (TORO's own order, NOT g2o's)
    VERTEX3 id x y z roll pitch yaw
    EDGE3 i j dx dy dz roll pitch yaw  I11 .. I16 I22 .. I66             (upper triangle over x y z roll pitch yaw)
    EQUIV i j                                                            (kept verbatim, ignored by the solver)
Vertex ids are integers of any size, kept exact (never through float64; see graph.ids); ids, order, information
and comments survive a read -> write. An id that appears only on edges gets a node without a guess (placed from its
neighbours; a `GraphFormatWarning` names the first such line when the file has VERTEX lines at all).
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
import warnings
from pathlib import Path

import numpy as np

from graph.errors import GraphError
from graph.ids import common_ids, id_array
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


class GraphFormatWarning(UserWarning):
    """A pose-graph file read with records skipped or vertices implied: the message names the file and counts."""


# g2o record families read past (not optimised): parameter blocks, and vertex / edge types other than the poses
_OTHER_G2O_PREFIXES = ("PARAMS_", "VERTEX_", "EDGE_")

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
def _is_other_g2o(tag: str) -> bool:
    """A g2o record we read past: parameter blocks, and vertex / edge types that are not SE2 / SE3:QUAT poses."""
    return tag.startswith(_OTHER_G2O_PREFIXES) and tag not in _TAGS


def sniff_format(path: str | os.PathLike) -> str:
    """'g2o' or 'toro', from the first record tag in the file."""
    path = Path(path)
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        for lineno, line in enumerate(f, 1):
            s = line.strip()
            if not s or s.startswith("#"):
                continue
            tag = s.split()[0]
            if tag in _TAGS:
                return _TAGS[tag][0]
            if tag == "FIX" or _is_other_g2o(tag):
                return "g2o"
            if tag == "EQUIV":
                return "toro"
            raise GraphFormatError(path, lineno, f"unknown record type {_shown(tag)}; expected one of "
                                                 f"{', '.join(sorted(_TAGS))}, FIX, EQUIV or another g2o "
                                                 "VERTEX_* / EDGE_* / PARAMS_* record")
    raise GraphFormatError(path, None, "no vertex or edge records (empty pose-graph file)")


def _shown(tag: str) -> str:
    return repr(tag if len(tag) <= 40 else tag[:40] + "...")


def read_graph(path: str | os.PathLike, toro_info_order: str = "auto") -> PoseGraphData:
    """Read a g2o or TORO file (format detected from the first record)."""
    fmt = sniff_format(path)
    return read_g2o(path) if fmt == "g2o" else read_toro(path, info_order=toro_info_order)


def read_g2o(path: str | os.PathLike) -> PoseGraphData:
    """Read a g2o file: VERTEX_SE2 / EDGE_SE2 or VERTEX_SE3:QUAT / EDGE_SE3:QUAT, FIX, comments; other VERTEX_* /
    EDGE_* / PARAMS_* records are kept verbatim but not optimised (one `GraphFormatWarning` counts them)."""
    return _read(Path(path), "g2o")


def read_toro(path: str | os.PathLike, info_order: str = "auto") -> PoseGraphData:
    """Read a TORO file: VERTEX2 / EDGE2 (or VERTEX3 / EDGE3), EQUIV, comments.

    `info_order` for EDGE2: 'toro' (Ixx Ixy Iyy Itt Ixt Iyt), 'g2o' (I11 I12 I13 I22 I23 I33, used by iSAM's
    EDGE2 files) or 'auto' (TORO unless some matrix is not positive definite in TORO order but all are in g2o order).
    """
    if info_order not in ("auto", "toro", "g2o"):
        raise ValueError(f"info_order must be auto, toro or g2o, got {info_order!r}")
    return _read(Path(path), "toro", info_order)


def _parse_ids(path: Path, lineno: int, tag: str, fields: list[str]) -> list[int]:
    # ids stay Python ints from here on (graph.ids): never float64, never a wrapping cast
    try:
        return [int(p) for p in fields]
    except ValueError:
        raise GraphFormatError(path, lineno, f"{tag}: vertex ids must be integers, got "
                                             f"{_shown(' '.join(fields))}") from None


def _read(path: Path, fmt: str, info_order: str = "toro") -> PoseGraphData:
    dim = None
    v_ids, v_vals, v_lines = [], [], []
    e_ids, e_vals, e_lines = [], [], []
    fixed, fix_lines, comments, extras, layout = [], [], [], [], []
    other: dict[str, list[int]] = {}          # skipped g2o record type -> its line numbers
    other_vertices: dict[int, str] = {}       # id -> type of a skipped (non-pose) vertex
    # utf-8-sig: a UTF-8 byte-order mark (Windows editors, some exporters) is not part of the first tag
    with open(path, encoding="utf-8-sig", errors="replace") as f:
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
                ids = _parse_ids(path, lineno, "FIX", parts[1:])
                if not ids:
                    raise GraphFormatError(path, lineno, "FIX without a vertex id")
                layout.append(("X", len(extras)))
                extras.append(s)
                fixed.extend(ids)
                fix_lines.extend([lineno] * len(ids))
                continue
            if tag == "EQUIV" and fmt == "toro":
                layout.append(("X", len(extras)))
                extras.append(s)
                continue
            if fmt == "g2o" and _is_other_g2o(tag):
                # g2o and RTAB-Map write parameter blocks (PARAMS_SE3OFFSET), landmarks (VERTEX_TRACKXYZ, VERTEX_XY)
                # and their edges: not poses, so not optimised; kept verbatim so the output keeps them
                other.setdefault(tag, []).append(lineno)
                if tag.startswith("VERTEX_") and len(parts) > 1:
                    try:
                        other_vertices.setdefault(int(parts[1]), tag)
                    except ValueError:
                        pass
                layout.append(("X", len(extras)))
                extras.append(s)
                continue
            spec = _TAGS.get(tag)
            if spec is None or spec[0] != fmt:
                allowed = sorted(t for t, v in _TAGS.items() if v[0] == fmt) + (
                    ["FIX", "other VERTEX_* / EDGE_* / PARAMS_*"] if fmt == "g2o" else ["EQUIV"])
                raise GraphFormatError(path, lineno, f"unknown record type {_shown(tag)} in a {fmt} file; expected "
                                                     f"one of {', '.join(allowed)}")
            _, tdim, kind, nfields = spec
            if dim is None:
                dim = tdim
            elif tdim != dim:
                raise GraphFormatError(path, lineno, f"{tag} is a {tdim}D record in a {dim}D graph (2D and 3D mixed)")
            if len(parts) - 1 != nfields:
                raise GraphFormatError(path, lineno, f"{tag} needs {nfields} fields after the tag, got {len(parts) - 1}")
            nid = 1 if kind == "V" else 2
            ids = _parse_ids(path, lineno, tag, parts[1:1 + nid])
            try:
                vals = [float(p) for p in parts[1 + nid:]]
            except ValueError:
                bad = next(p for p in parts[1 + nid:] if not _is_float(p))
                raise GraphFormatError(path, lineno, f"{tag}: non-numeric value {_shown(bad)}") from None
            if not all(math.isfinite(v) for v in vals):
                raise GraphFormatError(path, lineno, f"{tag}: NaN or infinite value")
            if kind == "V":
                layout.append(("V", len(v_ids)))
                v_ids.append(ids[0])
                v_vals.append(vals)
                v_lines.append(lineno)
            else:
                layout.append(("E", len(e_vals)))
                e_ids.append(ids)
                e_vals.append(vals)
                e_lines.append(lineno)
    if dim is None:
        what = f" (only {', '.join(sorted(other))} records, which are not poses)" if other else ""
        raise GraphFormatError(path, None, f"no pose vertex or edge records{what} (empty pose-graph file)")
    if other:
        counts = ", ".join(f"{len(v)} {t}" for t, v in sorted(other.items()))
        warnings.warn(GraphFormatWarning(f"{path}: skipped records that are not pose vertices or pose edges "
                                         f"(kept in g2o output, not optimised): {counts}"), stacklevel=3)
    return _assemble(path, fmt, dim, info_order, v_ids, v_vals, v_lines, e_ids, e_vals, e_lines, fixed, fix_lines,
                     comments, extras, layout, other_vertices)


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def _check_ids(path, v_ids, v_lines, e_ids, e_lines, fixed, fix_lines, other_vertices) -> tuple[list[int], list[int]]:
    """Duplicates, self-edges, edges to non-pose vertices, FIX on unknown ids. Returns (node ids in order: vertex
    lines first, then ids seen only on edges, ascending; the FIX ids that name pose nodes, sorted)."""
    seen: dict[int, int] = {}
    for k, i in enumerate(v_ids):
        if i in seen:
            raise GraphFormatError(path, v_lines[k], f"duplicate vertex id {i} (first defined on line "
                                                     f"{v_lines[seen[i]]})")
        if i in other_vertices:
            raise GraphFormatError(path, v_lines[k], f"vertex id {i} is also a {other_vertices[i]} vertex")
        seen[i] = k
    edge_only: dict[int, int] = {}
    for (i, j), ln in zip(e_ids, e_lines):
        if i == j:
            raise GraphFormatError(path, ln, f"edge from vertex {i} to itself")
        for n in (i, j):
            if n in other_vertices:
                raise GraphFormatError(path, ln, f"pose edge names vertex {n}, which is a {other_vertices[n]} "
                                                 "vertex, not a pose")
            if n not in seen and n not in edge_only:
                edge_only[n] = ln
    if v_ids and edge_only:
        first = min(edge_only, key=edge_only.get)
        warnings.warn(GraphFormatWarning(
            f"{path}:{edge_only[first]}: {len(edge_only)} vertex id(s) appear only on edges, with no VERTEX line "
            f"(first: {first}); they are placed by composing edges from their neighbours"), stacklevel=4)
    node_ids = list(v_ids) + sorted(edge_only)
    known = set(node_ids)
    fixed_ids = []
    for i, ln in zip(fixed, fix_lines):
        if i in known:
            fixed_ids.append(i)
        elif i not in other_vertices:     # FIX on a landmark (not optimised here) is harmless
            raise GraphFormatError(path, ln, f"FIX names vertex {i}, which no record defines")
    return node_ids, sorted(set(fixed_ids))


def _assemble(path, fmt, dim, info_order, v_ids, v_vals, v_lines, e_ids, e_vals, e_lines, fixed, fix_lines, comments,
              extras, layout, other_vertices):
    w = POSE_WIDTH[dim]
    node_list, fixed_list = _check_ids(path, v_ids, v_lines, e_ids, e_lines, fixed, fix_lines, other_vertices)
    vv = np.asarray(v_vals, float).reshape(len(v_ids), 3 if dim == 2 else (6 if fmt == "toro" else 7))
    if dim == 2:
        poses = vv.reshape(-1, 3)
    elif fmt == "toro":
        poses = np.column_stack([vv[:, :3], rpy_to_quat(vv[:, 3:6])]) if len(vv) else np.zeros((0, 7))
    else:
        poses = _normalised_quats(path, vv.reshape(-1, 7), v_lines, "vertex")
    ev = np.asarray(e_vals, float).reshape(len(e_vals), 9 if dim == 2 else (27 if fmt == "toro" else 28))
    e_lines = np.asarray(e_lines)
    if dim == 2:
        meas = ev[:, 0:3]
        raw = ev[:, 3:9]
        if fmt == "g2o":
            info = raw[:, _G2O_INFO_2D]
        else:
            info = raw[:, _TORO_INFO_2D]
            if info_order == "g2o" or (info_order == "auto" and not _all_pd(info) and _all_pd(raw[:, _G2O_INFO_2D])):
                info = raw[:, _G2O_INFO_2D]
    else:
        if fmt == "g2o":
            meas = _normalised_quats(path, ev[:, 0:7], e_lines, "edge") if len(ev) else np.zeros((0, 7))
            info = _sym_from_upper(ev[:, 7:28], 6) if len(ev) else np.zeros((0, 6, 6))
        else:
            meas = np.column_stack([ev[:, 0:3], rpy_to_quat(ev[:, 3:6])]) if len(ev) else np.zeros((0, 7))
            info = _sym_from_upper(ev[:, 6:27], 6) if len(ev) else np.zeros((0, 6, 6))
    _check_information(path, info, e_lines)
    node_ids = id_array(node_list)
    all_poses = np.vstack([poses.reshape(-1, w), np.full((len(node_list) - len(v_ids), w), np.nan)])
    ei = id_array([e[0] for e in e_ids])
    ej = id_array([e[1] for e in e_ids])
    node_ids, ei, ej = common_ids(node_ids, ei, ej)
    return PoseGraphData(dim, node_ids, all_poses, ei, ej, meas, info, classify_edges(node_ids, ei, ej),
                         np.ones(len(ei)), id_array(fixed_list), comments, extras, layout)


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
    # verbatim extra lines are format-specific: FIX and the skipped g2o records exist only in g2o, EQUIV only in TORO
    xlines = [x if (x.split()[0] == "EQUIV") == (fmt == "toro") else None for x in data.extras]
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
