"""graph.calibration: separate variance factors for the translation and rotation noise of 3D graphs, read from the
agreeing cycles (graph.support), and the robust solve on the calibrated information (robust.calibration_split)."""
import numpy as np
import pytest
from scipy.stats import chi2

from graph import GraphParams, optimize
from graph.calibration import VarianceFactors, refined_factor, scalar_factor, scale_information, split_factors
from graph.support import CycleSupport, cycle_support
from tests.graph.synth import noisy_graph, square_laps
from tests.graph.synth3d import mis_stated_graph, position_rmse


def _cycles(data):
    return cycle_support(data, 10, float(chi2.ppf(0.99, 6)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_split_recovers_both_factors(seed):
    # translation stated 10x too loose (variance factor 1/100), rotation 2x (1/4)
    data, _, _ = mis_stated_graph(np.random.default_rng(seed), stated_t=10.0, stated_r=2.0)
    f = split_factors(_cycles(data))
    assert f is not None
    assert 1 / 1.5 < f.translation / 0.01 < 1.5
    assert 1 / 1.5 < f.rotation / 0.25 < 1.5
    # one factor for both lies between them, far from either
    assert f.translation < f.scalar < f.rotation


@pytest.mark.parametrize("seed", [0, 1])
def test_propagated_split_attributes_the_lever_arm_to_the_rotation_noise(seed):
    # rotation noise 0.02 rad per step: over a cycle of ~10 steps of 0.5 m it moves the translation by more than
    # the translation noise itself; the summed blocks would charge that to the translation factor
    data, _, _ = mis_stated_graph(np.random.default_rng(seed), sigma_r=0.02, stated_t=10.0, stated_r=2.0)
    f = split_factors(cycle_support(data, 10, float(chi2.ppf(0.99, 6)), decompose=5000))
    assert 1 / 1.5 < f.translation / 0.01 < 1.5
    assert 1 / 1.5 < f.rotation / 0.25 < 1.5
    summed = split_factors(_cycles(data))
    assert summed.translation > 1.5 * f.translation


def test_equally_mis_stated_noise_gives_equal_factors():
    data, _, _ = mis_stated_graph(np.random.default_rng(3), stated_t=3.0, stated_r=3.0)
    f = split_factors(_cycles(data))
    assert 1 / 1.5 < f.translation / (1 / 9) < 1.5
    assert 1 / 1.5 < f.rotation / (1 / 9) < 1.5


def test_scale_information_scales_the_covariance_blocks():
    data, _, _ = mis_stated_graph(np.random.default_rng(0))
    data.information[:] = np.linalg.inv(np.full((6, 6), 0.1) + np.eye(6))      # with cross terms
    out = scale_information(data, VarianceFactors(4.0, 0.25, 1.0))
    cov, scaled = np.linalg.inv(data.information[0]), np.linalg.inv(out.information[0])
    d = np.sqrt(np.r_[np.full(3, 4.0), np.full(3, 0.25)])
    np.testing.assert_allclose(scaled, d[:, None] * cov * d[None, :], rtol=1e-10)
    np.testing.assert_array_equal(out.measurements, data.measurements)
    assert data.information[0, 0, 0] != out.information[0, 0, 0]         # the input is left as it was


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_split_calibration_keeps_true_and_rejects_near_miss_false_loops(seed):
    # 20 false loops claiming a pose 1 m from the truth next to true revisits: they agree with their neighbours
    # over short cycles under the loose stated noise; one variance factor for both blocks lets them fit
    # (translation thresholds ~10x too loose in variance), two factors do not
    data, truth, false = mis_stated_graph(np.random.default_rng(seed), num_false=20, local_offset=1.0)
    res = optimize(data, GraphParams())
    assert res.loop_inlier[~false].all()
    assert not res.loop_inlier[false].any()
    clean, _, _ = mis_stated_graph(np.random.default_rng(seed))
    ref = optimize(clean, GraphParams().replace(robust="none"))
    # the final map is the least-squares optimum of the true loops on the stated information
    assert abs(position_rmse(truth, res.poses) - position_rmse(truth, ref.poses)) < 1e-3
    assert np.abs(res.poses[:, :3] - ref.poses[:, :3]).max() < 1e-3


def test_planar_graphs_ignore_the_split_setting():
    data, _ = noisy_graph(square_laps(3, 6), np.random.default_rng(0), sigma_xy=0.05, sigma_th=0.002)
    on = optimize(data, GraphParams().replace(robust={"calibration_split": True}))
    off = optimize(data, GraphParams().replace(robust={"calibration_split": False}))
    np.testing.assert_array_equal(on.poses, off.poses)
    np.testing.assert_array_equal(on.loop_inlier, off.loop_inlier)


def test_rotation_stated_far_too_loose_keeps_every_true_loop():
    # parking-garage states its rotation noise ~500x looser (in variance, relative to translation) than its cycles
    # show; the calibrated information is then too ill-conditioned for a chordal start, which uses the stated one
    data, _, false = mis_stated_graph(np.random.default_rng(0), stated_t=2.0, stated_r=300.0, num_false=20)
    res = optimize(data, GraphParams())
    assert res.loop_inlier[~false].all()
    assert not res.loop_inlier[false].any()


def _cycle_set(r2: np.ndarray) -> CycleSupport:
    n = len(r2)
    return CycleSupport(np.arange(n), np.arange(n) + 1, r2, np.zeros((n, 3)), np.zeros((n, 3, 3)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refined_factor_sheds_the_cycles_that_agree_only_on_loosely_stated_noise(seed):
    # a graph stating its noise 500x too loose (factor 0.002): 55 % of the agreeing cycles are true ones, 45 % close
    # through false loops, still within the stated chi-square bound but 30-400x the true noise
    rng = np.random.default_rng(seed)
    s = 0.002
    true = s * rng.chisquare(3, 5500)
    false = s * rng.chisquare(3, 4500) * rng.uniform(30, 400, 4500)
    cycles = _cycle_set(rng.permutation(np.r_[true, false]))
    bound = float(chi2.ppf(0.99, 3)) * 10
    plain = scalar_factor(cycles, 3)
    refined = refined_factor(cycles, 3, bound, 5)
    assert plain > 2 * s                        # the median is carried off by the false cycles
    assert 1 / 1.3 < refined / s < 1.3
    assert refined_factor(cycles, 3, bound, 0) == plain


def test_refined_factor_leaves_a_clean_set_alone():
    rng = np.random.default_rng(4)
    cycles = _cycle_set(0.05 * rng.chisquare(3, 3000))
    bound = float(chi2.ppf(0.99, 3)) * 10
    assert abs(refined_factor(cycles, 3, bound, 5) / scalar_factor(cycles, 3) - 1) < 0.01
