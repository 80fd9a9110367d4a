"""Loop exclusion by time and footprint (not a count of keyframes), and the motion gate of standalone loops."""
from __future__ import annotations

import numpy as np
import pytest

from loops.loop_detector import DatabaseParams, LoopDetector
from loops.recognition import Verification
from odometry.shared.camera import CameraModel
from odometry.shared.footprint import overlap_pairs
from odometry.shared.poses import between
from tests._tools import render_floor_tool, render_printed_floor
from tests.loops._fakes import SamePlace
from vslam.pipeline.motion_gate import ChainMotion, MotionGate


class AcceptAll:
    def verify(self, query, candidate):
        return Verification(True, 10.0, 10)


def camera() -> CameraModel:
    return CameraModel(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5, camera_height=0.5)


def keys_found(det: LoopDetector, n: int, poses=None, stamps=None) -> dict[int, list[int]]:
    out = {}
    for k in range(n):
        c = det.query(None, key=k, stamp=None if stamps is None else stamps[k])
        out[k] = sorted(x.key for x in c if x.accepted)
        det.add(k, None, None if stamps is None else stamps[k], None if poses is None else poses[k])
    return out


def test_a_keyframe_is_a_candidate_only_after_the_camera_left_its_footprint():
    # low-rate regime: 0.2 m per frame along x with a 0.64 m footprint, no count or time exclusion
    poses = np.column_stack([0.2 * np.arange(8), np.zeros(8), np.zeros(8)])
    det = LoopDetector(SamePlace(), AcceptAll(), DatabaseParams(exclude_recent=0, shortlist=10), camera=camera())
    found = keys_found(det, 8, poses)
    cam = camera()
    for q, ks in found.items():
        for k in ks:   # some keyframe between k and q no longer overlapped k
            between_ = poses[k + 1:q]
            assert len(between_) and np.any(overlap_pairs(cam, np.repeat(poses[k][None], len(between_), 0),
                                                          between_) <= 0)
    # frame 4 (0.8 m along a 0.64 m footprint) is the first that does not overlap frame 0: from frame 5 on, frame 0
    # is another visit; frames 1..4 never are for frame 5
    assert found[5] == [0]
    assert found[4] == [] and found[7] == [0, 1, 2]


def test_without_poses_the_count_alone_would_accept_neighbours():
    det = LoopDetector(SamePlace(), AcceptAll(), DatabaseParams(exclude_recent=0, shortlist=10))
    assert keys_found(det, 4)[3] == [0, 1, 2]


def test_time_exclusion_holds_back_keyframes_younger_than_exclude_seconds():
    stamps = np.arange(10) * 0.5
    det = LoopDetector(SamePlace(), AcceptAll(), DatabaseParams(exclude_recent=0, exclude_seconds=2.0, shortlist=20))
    found = keys_found(det, 10, stamps=stamps)
    assert found[9] == [0, 1, 2, 3, 4, 5]    # 4.5 s - 2 s: frames up to t = 2.5 s
    assert found[3] == []


def test_a_reverse_direction_revisit_is_a_candidate():
    # out along x, turn around, come back: frame 9 (heading pi) is over frame 1
    xs = [0.2 * i for i in range(6)] + [1.0, 0.8, 0.6, 0.2]
    th = [0.0] * 6 + [np.pi] * 4
    poses = np.column_stack([xs, np.zeros(10), th])
    det = LoopDetector(SamePlace(), AcceptAll(), DatabaseParams(exclude_recent=0, shortlist=20), camera=camera())
    found = keys_found(det, 10, poses)
    assert 1 in found[9] and 0 in found[9]


class FixedLoop(AcceptAll):
    """Verifies every pair with floor points that imply the candidate's pose = query's pose + `offset` (metres)."""

    def __init__(self, cam: CameraModel, offset: np.ndarray):
        self.cam, self.offset = cam, offset

    def verify(self, query, candidate):
        px = np.array([[100, 100], [500, 120], [320, 400], [200, 300], [450, 350], [150, 420], [600, 60]], float)
        floor = self.cam.pixel_to_floor(px)
        moved = self.cam.floor_to_pixel(floor - self.offset)
        return Verification(True, 10.0, len(px), inliers_query=px, inliers_candidate=moved)


def test_the_motion_gate_rejects_a_loop_that_contradicts_the_odometry():
    cam = camera()
    odo = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.0, 0.0]])   # out 0.3 m and back
    gate = MotionGate.for_camera(cam, ChainMotion(odo))
    v_true = FixedLoop(cam, np.zeros(2)).verify(None, None)          # the same place: agrees with odometry
    v_false = FixedLoop(cam, np.array([0.4, 0.0])).verify(None, None)  # a look-alike 0.4 m away
    assert gate(0, 2, v_true)
    assert not gate(0, 2, v_false)
    assert np.allclose(between(odo[0], odo[2]), 0.0)


@pytest.mark.skipif(render_floor_tool() is None, reason="needs VSLAM_SHARED_DATA and ../tools/render_floor.py")
def test_standalone_loops_on_a_printed_floor_join_no_non_overlapping_places(tmp_path):
    from vslam.app.loops import detect_sequence_loops
    from vslam.evaluation.loops import read_loops_csv
    from vslam.io import open_sequence

    seq_dir = render_printed_floor(tmp_path / "printed", seed=1)
    seq = open_sequence(seq_dir)
    gt = seq.groundtruth_planar()

    def no_overlap(out):
        t = read_loops_csv(out / "loops.csv")
        q, m = t.query[t.accepted], t.match[t.accepted]
        return int((overlap_pairs(seq.camera, gt[q], gt[m]) <= 0).sum()), len(q)

    detect_sequence_loops(seq_dir, tmp_path / "gated")
    detect_sequence_loops(seq_dir, tmp_path / "appearance", appearance_only=True)
    bad_gated, n_gated = no_overlap(tmp_path / "gated")
    bad_app, _ = no_overlap(tmp_path / "appearance")
    assert bad_app > 0          # the floor does fool appearance alone
    assert bad_gated == 0 and n_gated > 0


def test_across_an_unmeasured_step_the_gate_leaves_the_decision_to_appearance():
    cam = camera()
    odo = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.0, 0.0]])
    v_false = FixedLoop(cam, np.array([0.4, 0.0])).verify(None, None)
    assert not MotionGate.for_camera(cam, ChainMotion(odo))(0, 2, v_false)
    lost = np.array([False, True, False])     # VO lost frame 1: the motion 0 -> 2 is unknown
    assert MotionGate.for_camera(cam, ChainMotion(odo, unknown=lost))(0, 2, v_false)
