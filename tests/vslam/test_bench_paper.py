"""The pieces of `vslam bench paper` that can fail quietly: the naive ORB chain baseline and the paper's tables."""
from __future__ import annotations

import pickle
from dataclasses import replace

import matplotlib.image
import numpy as np
import pytest

from vslam.bench.baseline_orb_chain import naive_orb_chain
from vslam.bench.paper_figure import paper_figure
from vslam.bench.paper_pool import TaskPool
from vslam.bench.paper_runs import kept_overlap, vo_pass
from vslam.bench.paper_tables import PAPER_TABLE_IV, table_iv, table_v
from vslam.io import open_sequence
from vslam.sim import SimConfig, simulate


def test_orb_chain_follows_a_simulated_floor(tmp_path):
    simulate(SimConfig(floor="carpet", length=1.5, max_frames=60, width=320, height=240, focal=250.0), tmp_path / "s")
    seq = open_sequence(tmp_path / "s")
    est, _, _ = naive_orb_chain(seq, seq.require_camera())
    gt = seq.groundtruth_planar()[: len(est)]
    assert est.shape == (len(seq), 3) and np.isfinite(est).all()
    true_len = np.sum(np.hypot(*np.diff(gt[:, :2], axis=0).T))
    est_len = np.sum(np.hypot(*np.diff(est[:, :2], axis=0).T))
    assert true_len > 0.5
    assert abs(est_len - true_len) < 0.1 * true_len


class _Run:
    def __init__(self, mode):
        s2e = {"error_dx": 0.01, "error_dy": -0.02, "error_dtheta": 0.003}
        self.mode, self.vo, self.slam, self.vo_ate_m, self.slam_ate_m = mode, s2e, s2e, 0.5, 0.05
        self.accepted, self.kept, self.false_kept, self.kept_below_r, self.fps = 10, 8, 1, 2, 30.0


def test_tables_put_the_papers_figures_beside_ours():
    chain = {"start_to_end": {"error_dx": 1.0, "error_dy": 2.0, "error_dtheta": 0.1}, "ate_m": 3.0}
    iv = table_iv([_Run(1), _Run(4)], chain)
    assert "no VO in the paper" in iv.splitlines()[4]          # mode 1: the paper had no VO
    assert f"{PAPER_TABLE_IV[4][0][0]:+.4g}" in iv and "ORB chain" in iv
    v = table_v({4: {"storage_mb": 28.0, "linear_s": 5.0, "indexed_s": 0.02}}, {"storage_mb": 900.0, "linear_s": 40.0})
    assert "28.59" in v and "1213.84" in v and "SIFT" in v
    header = [c.strip() for c in iv.splitlines()[2].split("|")]
    row = [c.strip() for c in iv.splitlines()[4].split("|")]
    assert row[header.index("false kept (J = 0)")] == "1" and row[header.index("kept, 0 < J < 0.33")] == "2"


class _Loop:
    def __init__(self, q, m):
        self.query_frame, self.match_frame = q, m


def test_a_kept_loop_is_false_only_when_the_footprints_do_not_overlap(tmp_path):
    """The paper's table calls a kept loop false at J = 0 (no shared floor), not below the loop threshold 0.33:
    a loop between footprints half overlapping is a correct constraint."""
    simulate(SimConfig(floor="carpet", length=2.0, max_frames=80, width=320, height=240, focal=250.0), tmp_path / "s")
    seq = open_sequence(tmp_path / "s")
    gt = seq.groundtruth_planar()
    cam = seq.require_camera()
    long_side = float(np.ptp(cam.footprint(), axis=0).max())
    along = np.cumsum(np.r_[0.0, np.hypot(*np.diff(gt[:, :2], axis=0).T)])
    half = int(np.searchsorted(along, 0.5 * long_side))      # about half the footprint along the path
    far = int(np.searchsorted(along, 1.5 * long_side))       # beyond the footprint: no shared floor
    assert far < len(seq)
    J = kept_overlap(seq, [_Loop(0, 0), _Loop(half, 0), _Loop(far, 0)])
    assert J[0] == pytest.approx(1.0) and 0 < J[1] < 0.5 and J[2] == 0


class _Traj:
    def __init__(self, mode, vo, slam):
        self.mode, self.poses_vo, self.poses_slam = mode, vo, slam


def test_figure_has_a_panel_per_mode_and_stays_small(tmp_path):
    t = np.linspace(0, 4 * np.pi, 7000)
    gt = np.column_stack([10 * np.cos(t), 6 * np.sin(t), t + np.pi / 2])
    rng = np.random.default_rng(0)
    runs = [_Traj(m, gt + np.cumsum(rng.normal(0, 1e-3, gt.shape), 0), gt + rng.normal(0, 1e-3, gt.shape))
            for m in range(1, 7)]
    paper_figure(tmp_path / "p.png", "ours", gt, runs, gt * 1.02)
    size = (tmp_path / "p.png").stat().st_size
    img = matplotlib.image.imread(tmp_path / "p.png")
    assert size < 300_000                                   # docs/img budget
    assert img.shape[1] > 1.5 * img.shape[0]                # two rows of four panels: 6 modes, chain, close-up


def test_vo_cache_reuses_a_pass_only_when_it_checks_out(tmp_path):
    simulate(SimConfig(floor="carpet", length=1.0, max_frames=40, width=320, height=240, focal=250.0), tmp_path / "s")
    first = vo_pass(tmp_path / "s", tmp_path / "cache")
    stored = list((tmp_path / "cache").glob("*.pkl"))
    again = vo_pass(tmp_path / "s", tmp_path / "cache")
    assert not first.reused and again.reused and len(stored) == 1
    assert all(np.array_equal(a.pose, b.pose) for a, b in zip(first.estimates, again.estimates))
    # a stale pass under the same key (say, from code the key missed) is recomputed, not reused
    bad = replace(first, estimates=[replace(e, pose=e.pose + 1.0) for e in first.estimates])
    stored[0].write_bytes(pickle.dumps(bad))
    fresh = vo_pass(tmp_path / "s", tmp_path / "cache")
    assert not fresh.reused and np.array_equal(fresh.estimates[-1].pose, first.estimates[-1].pose)


def test_task_pool_hands_back_values_failures_and_times():
    with TaskPool(1) as pool:
        ok = pool.submit("sum", sum, [1, 2, 3], describe=lambda v: f"got {v}")
        bad = pool.submit("div", divmod, 1, 0)
        times = pool.report()
    assert ok.result() == 6 and set(times) == {"sum"} and times["sum"]["wall_s"] >= 0
    with pytest.raises(ZeroDivisionError):
        bad.result()
