"""The loop-score matrix as an image: how similar every query keyframe is to every earlier one, with the loop
candidates and the loops the back end kept or rejected marked on it. Written atomically."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odometry.shared.atomic_io import atomic_path
from vslam.evaluation.plots import pyplot

# status of a loop -> (marker, face colour, edge colour, size, legend)
MARKS = {
    "candidate": ("o", "white", "black", 18, "verified candidate, below threshold"),
    "kept": ("o", "tab:green", "black", 60, "loop kept by the back end"),
    "rejected": ("X", "tab:red", "black", 70, "loop rejected by the back end"),
    "accepted": ("o", "tab:green", "black", 60, "loop accepted by the detector"),   # no back end (`vslam loops`)
}


def loop_status(accepted: bool, inlier: bool | None, judged: bool = True) -> str:
    """A loop's mark: "kept" / "rejected" (accepted by the detector, then judged by the back end; one the back end
    never saw was not kept), "accepted" when there was no back end (not `judged`), or "candidate" (verified, below
    the detector's threshold)."""
    if not accepted:
        return "candidate"
    if not judged:
        return "accepted"
    return "kept" if inlier else "rejected"


def similarity_matrix(keyframes: np.ndarray, rows: list) -> np.ndarray:
    """(K, K) matrix, NaN where not compared: entry [i, j] is the similarity of keyframe i (as a query) to keyframe
    j; rows are (query frame, stored frames, scores) as the pipeline records them."""
    keyframes = np.asarray(keyframes, int)
    index = {int(f): i for i, f in enumerate(keyframes)}
    m = np.full((len(keyframes), len(keyframes)), np.nan)
    for q, keys, scores in rows:
        if int(q) not in index:
            continue
        cols = [index.get(int(k), -1) for k in keys]
        for j, s in zip(cols, scores):
            if j >= 0:
                m[index[int(q)], j] = s
    return m


def _frame_ticks(ax, keyframes: np.ndarray, n: int = 8) -> None:
    """Axis ticks at keyframe positions, labelled with their frame numbers (cells are keyframes, not frames)."""
    k = len(keyframes)
    pos = np.unique(np.linspace(0, k - 1, min(n, k)).round().astype(int))
    ax.set_xticks(pos, [str(int(keyframes[p])) for p in pos])
    ax.set_yticks(pos, [str(int(keyframes[p])) for p in pos])


def plot_loop_matrix(path: str | Path, keyframes: np.ndarray, matrix: np.ndarray | None, loops: list,
                     score_label: str = "global similarity (score units)", title: str = "") -> None:
    """The matrix as a colour map (grey: pairs never compared) over the query x match keyframe grid, and the loops
    [(query frame, match frame, status in MARKS)] on it. Without a matrix only the loops are drawn (coloured grid)."""
    plt = pyplot()
    keyframes = np.asarray(keyframes, int)
    index = {int(f): i for i, f in enumerate(keyframes)}
    k = max(len(keyframes), 1)
    fig, ax = plt.subplots(figsize=(7.2, 6.2), dpi=110)
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.88")   # pairs never compared: light grey
    if matrix is not None and np.isfinite(matrix).any():
        vals = matrix[np.isfinite(matrix)]
        im = ax.imshow(np.ma.masked_invalid(matrix), cmap=cmap, interpolation="nearest", origin="upper",
                       vmin=float(np.percentile(vals, 1)), vmax=float(np.percentile(vals, 99.5)))
        fig.colorbar(im, ax=ax, label=score_label, shrink=0.85)
    else:
        ax.imshow(np.full((k, k), np.nan), cmap=cmap, origin="upper")
    ax.plot([-0.5, k - 0.5], [-0.5, k - 0.5], color="0.4", lw=0.6, ls=":")   # query = match
    for status, (marker, face, edge, size, label) in MARKS.items():
        pts = [(index[int(q)], index[int(m)]) for q, m, s in loops if s == status and int(q) in index
               and int(m) in index]
        if pts:
            p = np.asarray(pts)
            ax.scatter(p[:, 1], p[:, 0], marker=marker, s=size, facecolors=face, edgecolors=edge, linewidths=0.9,
                       label=f"{label} ({len(pts)})", zorder=3, clip_on=False)
    _frame_ticks(ax, keyframes)
    ax.set_xlabel("match keyframe (frame number)")
    ax.set_ylabel("query keyframe (frame number)")
    ax.set_title(title or "loop scores: each query keyframe against the stored ones", fontsize=10)
    if loops:
        ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, bbox_inches="tight")
    plt.close(fig)
