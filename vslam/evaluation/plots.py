"""PNG plots: a run's trajectories with loop edges, error over time and loop score matrix; ROC and
precision-recall curves of place recognition. Every plot is written atomically."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odometry.shared.atomic_io import atomic_path


def pyplot():
    """matplotlib.pyplot with the file-only Agg backend."""
    # imported on the first plot: matplotlib takes about 0.4 s, and this module is imported by commands (and by
    # `vslam --help`) that never plot
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_trajectories(path: str | Path, trajectories: dict[str, np.ndarray], loops=None, loop_positions=None,
                      title: str = "") -> None:
    """Top-down view of planar trajectories {name: (N, 2+)}; loop edges drawn between `loop_positions`
    {'accepted': [(p, q)], 'rejected': [...], 'outlier': [...]}."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    styles = {"ground truth": dict(color="0.3", lw=2.0, ls="--"), "VO": dict(color="tab:orange", lw=1.2),
              "SLAM": dict(color="tab:blue", lw=1.4)}
    for name, p in trajectories.items():
        if p is None or len(p) == 0:
            continue
        ax.plot(p[:, 0], p[:, 1], label=name, **styles.get(name, {}))
        ax.plot(p[0, 0], p[0, 1], "o", color=styles.get(name, {}).get("color", "k"), ms=4)
    colours = {"accepted": ("tab:green", "loop (kept)"), "outlier": ("tab:red", "loop (rejected by back end)"),
               "rejected": ("0.7", "candidate below threshold")}
    for kind, segs in (loop_positions or {}).items():
        c, lab = colours.get(kind, ("k", kind))
        for k, (a, b) in enumerate(segs):
            ax.plot([a[0], b[0]], [a[1], b[1]], color=c, lw=0.8, alpha=0.8, label=lab if k == 0 else None)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, bbox_inches="tight")
    plt.close(fig)


def plot_errors(path: str | Path, series: dict[str, tuple[np.ndarray, np.ndarray]], ylabel: str = "APE (m)") -> None:
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.5), dpi=110)
    for name, (t, e) in series.items():
        ax.plot(t, e, label=name, lw=1.0)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, bbox_inches="tight")
    plt.close(fig)


def plot_score_matrix(path: str | Path, query: np.ndarray, match: np.ndarray, score: np.ndarray, n: int,
                      title: str = "local score", max_size: int = 600) -> None:
    """Score of query i against match j as an image (like seed 001 Fig. 2), frames binned to at most max_size."""
    plt = pyplot()
    n = max(int(n), 1)
    b = max(1, int(np.ceil(n / max_size)))
    m = np.full((n // b + 1, n // b + 1), np.nan)
    for qi, mj, s in zip(query, match, score):
        i, j = int(qi) // b, int(mj) // b
        if np.isnan(m[i, j]) or s > m[i, j]:
            m[i, j] = s
    fig, ax = plt.subplots(figsize=(6, 5.2), dpi=110)
    im = ax.imshow(m, origin="upper", cmap="viridis", interpolation="nearest")
    fig.colorbar(im, ax=ax, label=title)
    ax.set_xlabel(f"match frame (/{b})" if b > 1 else "match frame")
    ax.set_ylabel(f"query frame (/{b})" if b > 1 else "query frame")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, bbox_inches="tight")
    plt.close(fig)


def plot_roc_curves(path: str | Path, curves: dict[str, tuple], title: str) -> None:
    """ROC curves {name: (fpr, tpr, auc)} as a PNG."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(4.8, 4.2), dpi=100)
    for name, (fpr, tpr, a) in curves.items():
        ax.plot(fpr, tpr, label=f"{name} (AUC {a:.3f})", lw=1.5)
    ax.plot([0, 1], [0, 1], ":", color="grey", lw=0.8)
    ax.set_xlabel("false positive rate (1 - specificity)")
    ax.set_ylabel("true positive rate (sensitivity)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="lower right", fontsize=8)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.01)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def plot_pr_curves(path: str | Path, curves: dict, title: str) -> None:
    """Precision-recall curves {label: PRCurve (recall, precision, average_precision)} as a PNG."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 4), dpi=100)
    for label, pr in curves.items():
        ax.plot(pr.recall, pr.precision, label=f"{label} (AP {pr.average_precision:.2f})")
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1.02)
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
