"""The figure of `vslam bench paper`, in the layout of the paper's Figs. 7-8: one panel per mode with its VO and
VSLAM trajectories over the ground truth, then the naive ORB chain, then a close-up of where every estimate ends
(the start-to-end error of Table IV)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odometry.shared.poses import between, compose
from vslam.evaluation.plots import pyplot

STRIDE = 4          # frames between plotted points: a 7154-frame path stays smooth and the PNG small
END_FRAMES = 400    # frames before the end drawn in the close-up


def anchored(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Estimated poses started at the first ground-truth pose (as the paper draws its paths on the blueprint)."""
    return compose(gt[0], between(est[0], est))


def paper_figure(path: Path, renderer: str, gt: np.ndarray, runs: list, chain: np.ndarray) -> None:
    """Write the PNG: `runs` are the per-mode results (poses_vo, poses_slam, mode), `chain` the ORB chain poses."""
    plt = pyplot()

    n = min(len(gt), *(len(r.poses_vo) for r in runs), len(chain))
    gt = gt[:n]
    ok = ~np.isnan(gt[:, 0])
    g = gt[ok]
    panels = len(runs) + 2
    cols = 4
    rows = -(-panels // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.6 * rows), constrained_layout=True)
    axes = np.atleast_1d(axes).ravel()

    def draw(ax, curves, title):
        ax.plot(g[::STRIDE, 0], g[::STRIDE, 1], color="black", lw=2.5, alpha=0.3, label="ground truth")
        for p, kw in curves:
            p = anchored(p[:n], gt)[ok]
            ax.plot(p[::STRIDE, 0], p[::STRIDE, 1], lw=0.9, **kw)
        ax.set_title(title, fontsize=10)
        ax.set_aspect("equal", adjustable="datalim")
        ax.tick_params(labelsize=7)

    for ax, r in zip(axes, runs):
        draw(ax, [(r.poses_vo, dict(color="tab:blue", label="VO")), (r.poses_slam, dict(color="tab:red", label="VSLAM"))],
             f"mode {r.mode}" + (" (no VO in the paper)" if r.mode == 1 else ""))
    axes[0].legend(fontsize=7, loc="best")
    draw(axes[len(runs)], [(chain, dict(color="tab:grey", label="ORB + affine chain")),
                           (runs[0].poses_vo, dict(color="tab:blue", label="our VO"))], "naive ORB chain")
    axes[len(runs)].legend(fontsize=7, loc="best")
    _close_up(axes[len(runs) + 1], gt[ok], [(anchored(r.poses_slam[:n], gt)[ok], f"VSLAM mode {r.mode}") for r in runs],
              anchored(runs[0].poses_vo[:n], gt)[ok])
    for ax in axes[panels:]:
        ax.axis("off")
    fig.suptitle(f"{renderer} renderer: per mode, VO (blue) and VSLAM (red) over the ground truth (grey), metres",
                 fontsize=11)
    fig.savefig(path, dpi=72)
    plt.close(fig)


def _close_up(ax, gt: np.ndarray, slam: list[tuple[np.ndarray, str]], vo: np.ndarray) -> None:
    """The last END_FRAMES frames around the true end: the start-to-end errors at a scale where they show."""
    end = gt[-1, :2]
    tail = slice(max(0, len(gt) - END_FRAMES), len(gt))
    ax.plot(gt[tail, 0], gt[tail, 1], color="black", lw=2.5, alpha=0.3, label="ground truth")
    ax.plot(vo[tail, 0], vo[tail, 1], color="tab:blue", lw=0.9, label="VO")
    colours = pyplot().get_cmap("autumn")(np.linspace(0.0, 0.85, max(1, len(slam))))   # reds to yellows: not VO's blue
    for (p, label), c in zip(slam, colours):
        ax.plot(p[tail, 0], p[tail, 1], lw=0.9, color=c, label=label)
    reach = max([np.hypot(*(p[-1, :2] - end)) for p, _ in slam] + [np.hypot(*(vo[-1, :2] - end))])
    half = max(0.05, 1.4 * reach)
    ax.set_xlim(end[0] - half, end[0] + half)
    ax.set_ylim(end[1] - half, end[1] + half)
    ax.plot(*end, "k+", ms=10)
    ax.set_aspect("equal")
    ax.set_title("end of the run (close-up)", fontsize=10)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=6, loc="best")
