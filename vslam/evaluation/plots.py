"""PNG plots: a run's trajectories with loop edges and error over time with loops marked (the loop-score matrix:
vslam.evaluation.plots_loops); ROC and precision-recall curves of place recognition. Written atomically."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odometry.shared.atomic_io import atomic_path
from odometry.shared.poses import between


def start_anchored(poses: np.ndarray) -> np.ndarray:
    """Planar poses (N, 3) expressed in the frame of the first valid one: where a run's estimate starts (at the
    origin). Ground truth in its own world frame (render_floor, KITTI, TUM) is then drawn over the estimate instead of
    beside it; rows with NaN stay NaN."""
    p = np.asarray(poses, dtype=float)
    ok = np.flatnonzero(np.all(np.isfinite(p[:, :3]), axis=1)) if len(p) else []
    if len(ok) == 0:
        return p.copy()
    return between(p[ok[0], :3], p[:, :3])


def pyplot():
    """matplotlib.pyplot with the file-only Agg backend."""
    # imported on the first plot: matplotlib takes about 0.4 s, and this module is imported by commands (and by
    # `vslam --help`) that never plot
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


LOOP_STYLES = {"accepted": ("tab:green", "loop kept by the back end"),
               "outlier": ("tab:red", "loop rejected by the back end"),
               "rejected": ("0.6", "verified candidate, below threshold")}


def plot_trajectories(path: str | Path, trajectories: dict[str, np.ndarray], loops=None, loop_positions=None,
                      title: str = "") -> None:
    """Top-down view of planar trajectories {name: (N, 2+)}; loop edges drawn between `loop_positions`
    {'accepted': [(p, q)], 'outlier': [...], 'rejected': [...]}, each with a dot at both ends, since a loop joins
    two visits of one place and its segment is often shorter than the line width."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 7), dpi=110)
    styles = {"ground truth": dict(color="0.3", lw=2.0, ls="--"), "VO": dict(color="tab:orange", lw=1.2),
              "SLAM": dict(color="tab:blue", lw=1.4)}
    for name, p in trajectories.items():
        if p is None or len(p) == 0:
            continue
        ax.plot(p[:, 0], p[:, 1], label=name, **styles.get(name, {}))
        ax.plot(p[0, 0], p[0, 1], "o", color=styles.get(name, {}).get("color", "k"), ms=4)
    for kind, segs in (loop_positions or {}).items():
        if not len(segs):
            continue
        c, lab = LOOP_STYLES.get(kind, ("k", kind))
        for a, b in segs:
            ax.plot([a[0], b[0]], [a[1], b[1]], color=c, lw=1.2, alpha=0.9, zorder=3)
        ends = np.array([[a[0], a[1]] for a, _ in segs] + [[b[0], b[1]] for _, b in segs])
        ax.scatter(ends[:, 0], ends[:, 1], s=28, facecolors=c, edgecolors="black", linewidths=0.6, zorder=4,
                   label=f"{lab} ({len(segs)})")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or "trajectories (top view) and loop closures", fontsize=10)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, bbox_inches="tight")
    plt.close(fig)


def plot_errors(path: str | Path, series: dict[str, tuple[np.ndarray, np.ndarray]], ylabel: str = "APE (m)",
                loop_times: dict[str, np.ndarray] | None = None, title: str = "") -> None:
    """Error over time {name: (t (s), error)}; loop closures {kind: times (s)} (kinds as in LOOP_STYLES) marked as
    vertical lines at the query frame's time."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 3.8), dpi=110)
    colours = {"VO": "tab:orange", "SLAM": "tab:blue"}
    for name, (t, e) in series.items():
        ax.plot(t, e, label=name, lw=1.1, color=colours.get(name))
    for kind, times in (loop_times or {}).items():
        c, lab = LOOP_STYLES.get(kind, ("k", kind))
        for k, t in enumerate(np.asarray(times, float)):
            ax.axvline(t, color=c, lw=1.4, ls="--", label=f"{lab} ({len(times)})" if k == 0 else None)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(ylabel)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(title or "position error over time", fontsize=10)
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
