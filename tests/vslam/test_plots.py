"""The run's plots exist, are not blank and show what they are for: the loop-score matrix fills the keyframe grid
(not single-pixel dots) with its diagonal band and the loops marked; loops are marked on the trajectory and
error plots."""
import cv2
import numpy as np
import pytest

from vslam.evaluation import plots
from vslam.evaluation.plots_loops import loop_status, plot_loop_matrix, similarity_matrix


def _png(path):
    img = cv2.imread(str(path))
    assert img is not None, path
    return img


def _share(img, bgr, tol=40):
    """Fraction of the pixels within `tol` (sum of channel differences) of a colour."""
    return float((np.abs(img.astype(int) - np.array(bgr)).sum(axis=2) < tol).mean())


def test_loop_matrix_fills_the_grid_with_a_diagonal_band(tmp_path):
    k = 60
    frames = np.arange(k) * 7
    # similarity falls off with the keyframe distance (the diagonal band), plus a revisit of 0..9 by 50..59
    rows = [(frames[i], frames[:i + 1], np.exp(-np.abs(i - np.arange(i + 1)) / 3.0) + 0.6 * (
        (i >= 50) & (np.abs(np.arange(i + 1) - (i - 50)) < 2))) for i in range(k)]
    m = similarity_matrix(frames, rows)
    assert np.isfinite(np.tril(m)).all() and np.isnan(m[0, 1])      # queries compare with stored keyframes only
    loops = [(frames[55], frames[5], loop_status(True, True)), (frames[40], frames[3], loop_status(True, False)),
             (frames[30], frames[10], loop_status(False, None))]
    plot_loop_matrix(tmp_path / "m.png", frames, m, loops)
    img = _png(tmp_path / "m.png")
    assert img.shape[0] >= 500 and img.std() > 30                      # readable size, not blank
    assert _share(img, (255, 255, 255)) < 0.45                          # a filled grid, not dots on white
    assert _share(img, (44, 160, 44)) > 1e-4                            # the kept loop (tab:green)
    assert _share(img, (40, 39, 214)) > 1e-4                            # the rejected loop (tab:red)


def test_trajectory_and_error_plots_mark_the_loops(tmp_path):
    t = np.linspace(0, 2 * np.pi, 200)
    gt = np.column_stack([np.cos(t), np.sin(t), t])
    slam = gt + 0.01
    plots.plot_trajectories(tmp_path / "t.png", {"ground truth": gt, "SLAM": slam},
                            loop_positions={"accepted": [(slam[199], slam[0])], "outlier": [(slam[150], slam[20])]})
    plots.plot_errors(tmp_path / "e.png", {"SLAM": (t, np.abs(np.sin(t)) * 0.01)},
                      loop_times={"accepted": [5.0], "outlier": [2.0]})
    for name in ("t.png", "e.png"):
        img = _png(tmp_path / name)
        assert img.std() > 20
        assert _share(img, (44, 160, 44)) > 1e-5 and _share(img, (40, 39, 214)) > 1e-5, name


@pytest.mark.parametrize("name", ["trajectories.png", "error_over_time.png", "loop_scores.png"])
def test_a_runs_plots_exist_and_are_not_blank(name, run_plots):
    img = _png(run_plots / name)
    assert img.shape[0] > 300 and img.std() > 20


@pytest.fixture(scope="module")
def run_plots(tmp_path_factory):
    from vslam.cli.main import main
    from vslam.sim import SimConfig, simulate

    root = tmp_path_factory.mktemp("plots")
    simulate(SimConfig(width=320, height=240, focal=250.0, length=4.0, laps=2, turn_radius=0.6, fps=10.0, seed=4),
             root / "seq")
    assert main(["run", str(root / "seq"), "--out", str(root / "out"), "--no-recording", "--quiet"]) == 0
    img = _png(root / "out" / "plots" / "loop_scores.png")
    assert _share(img, (255, 255, 255)) < 0.5       # the whole query x match grid is coloured
    return root / "out" / "plots"


def test_ground_truth_is_drawn_from_where_the_estimate_starts():
    """Ground truth in its own world frame (render_floor, KITTI) is expressed in the frame of its first pose: the
    estimate starts at the origin, so an unaligned comparison measures drift, not the choice of world frame."""
    from odometry.shared.poses import compose

    est = np.column_stack([np.linspace(0, 2, 50), 0.1 * np.sin(np.linspace(0, 3, 50)), np.linspace(0, 0.5, 50)])
    start = np.array([5.0, -2.0, 1.2])
    gt = compose(start, est)
    gt[3] = np.nan
    anchored = plots.start_anchored(np.vstack([np.full((1, 3), np.nan), gt]))
    assert np.isnan(anchored[0]).all() and np.isnan(anchored[4]).all()
    np.testing.assert_allclose(np.delete(anchored[1:], 3, axis=0), np.delete(est, 3, axis=0), atol=1e-12)
