"""The motion gate anchored on the closed map (issue 13, printed floors periodic at the keyframe spacing).

After a lap, the VO chain's drift-aware uncertainty spans more than one tile period, so a candidate one period
away from the truth passes the gate on the chain alone. Through an accepted loop near both keyframes, the path is a
few keyframes long on each side and the same candidate fails, while the true one still passes.
"""
from __future__ import annotations

import numpy as np

from odometry.shared.poses import between
from vslam.pipeline.anchored_motion import Anchor, AnchoredMotion, agree, position_variance, through
from vslam.pipeline.loop_pose import LoopPose
from vslam.pipeline.motion_gate import ChainMotion, DriftModel, MotionGate

PERIOD = 0.256   # the printed floor's tile period (m), equal to the keyframe spacing


def two_laps(radius: float = 2.0, spacing: float = 0.256):
    """Keyframe poses (exact) on a circle driven twice: key k and key k + n are the same place."""
    n = int(round(2 * np.pi * radius / spacing))
    a = np.arange(2 * n) * 2 * np.pi / n
    poses = np.column_stack([radius * np.sin(a), radius * (1 - np.cos(a)), a])
    return poses, n


def chains(poses):
    drift = DriftModel()
    full = ChainMotion(poses, drift, height=0.5)
    unscaled = ChainMotion(poses, drift.replace(trans_fraction=0.0), height=0.5)
    return full, unscaled, drift


def fit_of(delta) -> LoopPose:
    return LoopPose(np.asarray(delta, float), np.diag([1e-5, 1e-5, 1e-6]), 40, 0.002)


def test_an_alias_one_period_off_passes_the_vo_chain_but_not_the_closed_map():
    poses, n = two_laps()
    full, unscaled, drift = chains(poses)
    c, q = 10, n + 10                                          # a revisit of key 10 on the second lap
    truth = between(poses[c], poses[q])
    alias = truth + np.array([PERIOD, 0.0, 0.0])               # one tile along the candidate's x axis
    chain_gate = MotionGate(lambda v: v, full)
    assert chain_gate.check(c, q, fit_of(truth)).consistent
    assert chain_gate.check(c, q, fit_of(alias)).consistent    # the problem: the lap-long chain cannot tell
    anchor = Anchor(7, n + 7, between(poses[7], poses[n + 7]), np.diag([1e-5, 1e-5, 1e-6]))
    motion = AnchoredMotion(full, lambda: [anchor], lambda: np.arange(len(poses)), 4, unscaled,
                            drift.trans_fraction)
    gate = MotionGate(lambda v: v, motion)
    assert gate.check(c, q, fit_of(truth)).consistent
    assert not gate.check(c, q, fit_of(alias)).consistent
    assert motion.used[(c, q)] == anchor


def test_the_scale_error_of_a_revisit_counts_once():
    poses, n = two_laps()
    full, unscaled, drift = chains(poses)
    anchor = Anchor(5, n + 5, between(poses[5], poses[n + 5]), np.diag([1e-5, 1e-5, 1e-6]))
    _, independent = through(full, 12, n + 12, anchor)
    _, joint = through(full, 12, n + 12, anchor, unscaled, drift.trans_fraction)
    # the two stretches (key 12 -> 5 on lap 1, n+5 -> n+12 on lap 2) cover the same floor in opposite senses
    assert position_variance(joint) < 0.5 * position_variance(independent)


def test_no_anchor_nearer_than_the_chain_leaves_the_chain():
    poses, n = two_laps()
    full, unscaled, drift = chains(poses)
    far = Anchor(0, n + 30, between(poses[0], poses[n + 30]), np.diag([1e-5, 1e-5, 1e-6]))
    motion = AnchoredMotion(full, lambda: [far], lambda: np.arange(len(poses)), 4, unscaled, drift.trans_fraction)
    rel, cov = motion(20, 24)
    ref, ref_cov = full(20, 24)
    assert np.allclose(rel, ref) and np.allclose(cov, ref_cov)
    assert motion.used[(20, 24)] is None


def test_two_loops_agree_only_when_they_put_the_camera_at_one_place():
    poses, n = two_laps()
    full, unscaled, drift = chains(poses)
    cov = np.diag([1e-5, 1e-5, 1e-6])
    a = Anchor(10, n + 10, between(poses[10], poses[n + 10]), cov)
    b = Anchor(11, n + 11, between(poses[11], poses[n + 11]), cov)
    shifted = Anchor(11, n + 11, between(poses[11], poses[n + 11]) + np.array([PERIOD, 0, 0]), cov)
    assert agree(full, b, a, 16.27, unscaled, drift.trans_fraction)
    assert not agree(full, shifted, a, 16.27, unscaled, drift.trans_fraction)
