"""PNG plots: loop probability curves (seed 001 Fig. 5) and score matrices (Fig. 2-3)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odometry.shared.atomic_io import atomic_path


def _plt():
    # matplotlib is imported on first plot only: it is heavy, and plots are optional outputs
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_loop_model(model, path: str | Path) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=90)
    for m, c in sorted(model.curves.items()):
        populated = np.flatnonzero(c.totals > 0)
        if len(populated) == 0:
            continue
        last = min(populated[-1] + 2, len(c.edges))
        x = np.maximum(c.edges[:last], 0.1)
        line, = ax.step(x, c.probability[:last], where="post", label=f"mode {m}")
        if np.isfinite(c.threshold):
            ax.axvline(max(c.threshold, 0.1), color=line.get_color(), ls=":", lw=1)
    ax.set_xscale("log")
    ax.set_xlabel("local score s")
    gate = getattr(model, "min_overlap", None)
    ax.set_ylabel(f"P(J >= {model.overlap_threshold:g} | s" + (f", transform overlap >= {gate:g})" if gate else ")"))
    ax.set_ylim(-0.02, 1.05)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("loop probability per mode (dotted: threshold)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def plot_score_matrices(matrices: dict[str, np.ndarray], path: str | Path, title: str = "") -> None:
    """Lower-triangular score matrices (row i = query, column j < i) side by side, each normalised."""
    plt = _plt()
    n = len(matrices)
    fig, axes = plt.subplots(1, n, figsize=(2.6 * n, 2.9), dpi=90, squeeze=False)
    for ax, (name, mat) in zip(axes[0], matrices.items()):
        m = np.tril(np.asarray(mat, float), -1)
        top = np.percentile(m[m > 0], 99) if np.any(m > 0) else 1.0
        ax.imshow(np.clip(m / max(top, 1e-9), 0, 1), cmap="viridis", interpolation="nearest")
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
