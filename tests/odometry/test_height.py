"""Camera height tracking (odometry.height): the graded estimate (the VO's default) and the significance switch keep
a steady camera at (or very near) its nominal height and follow a bouncing one; the anchor is the window's mean
height."""
from __future__ import annotations

import math

import numpy as np
import pytest

from odometry.height import Height, HeightTracker, WobbleEstimate
from odometry.vo import VOConfig

NOMINAL = 0.5
FPS = 30.0
KEYFRAME_EVERY = 15   # frames
LINK_SIGMA = 3e-4     # per keyframe link, relative (what the refinement reports on the renderers' floors)


def _run(true_log: np.ndarray, rng: np.random.Generator, significance: float = 3.0, window: float = 10.0,
         graded: bool = False, link_sigma: float = LINK_SIGMA, noise_spread: float = 1.0):
    """Chain keyframe-relative height measurements (true ratio + N(0, link_sigma)) through a tracker the way the
    VO does; return the metres given to each keyframe and the true heights there."""
    tr = HeightTracker(NOMINAL, window, significance, graded, noise_spread)
    kf = tr.anchor(Height(NOMINAL))
    kf_true = true_log[0]
    tr.observe(0.0, kf)
    given, truth = [], []
    for i in range(1, len(true_log)):
        s = math.expm1(true_log[i] - kf_true)
        noise = rng.normal(0, link_sigma) if i % KEYFRAME_EVERY == 0 else 0.0
        h = kf.moved(s + noise, link_sigma ** 2 if i % KEYFRAME_EVERY == 0 else 0.0)
        if i % KEYFRAME_EVERY == 0:
            kf, kf_true = tr.anchor(h), true_log[i]
            given.append(kf.metres)
            truth.append(NOMINAL * math.exp(true_log[i]))
            h = kf
        tr.observe(i / FPS, h)
    return np.array(given), np.array(truth), tr


def test_a_steady_camera_stays_at_the_nominal_height():
    rng = np.random.default_rng(0)
    given, _, tr = _run(np.zeros(1800), rng)
    assert tr.nominal_keyframes >= 0.95 * len(given), (tr.tracked, tr.nominal_keyframes)
    assert np.max(np.abs(given / NOMINAL - 1)) < 4 * LINK_SIGMA * math.sqrt(20)


def test_a_slow_bounce_is_followed_once_the_window_has_seen_it():
    rng = np.random.default_rng(1)
    t = np.arange(1800) / FPS
    true_log = np.log1p(0.01 * np.sin(0.7 * t + 1.0))   # 1 % over a 9 s period, not starting at the nominal height
    given, truth, tr = _run(true_log, rng)
    late = np.arange(len(given)) * KEYFRAME_EVERY / FPS > 12.0   # the window (10 s) has been full for a while
    err_tracked = np.abs(given[late] / truth[late] - 1)
    err_nominal = np.abs(NOMINAL / truth[late] - 1)
    assert tr.tracked > 0.5 * len(given)
    assert np.mean(err_tracked) < 0.3 * np.mean(err_nominal), (np.mean(err_tracked), np.mean(err_nominal))


def test_without_significance_every_departure_is_used_and_the_first_keyframe_is_nominal():
    rng = np.random.default_rng(2)
    tr = HeightTracker(NOMINAL, 10.0, 0.0)
    assert tr.anchor(Height(NOMINAL)).metres == NOMINAL          # nothing seen yet: the nominal height
    given, _, tr = _run(np.zeros(600), rng, significance=0.0)
    assert tr.tracked > 0.9 * len(given)


def test_moved_chains_ratios_and_variances_and_never_flips_the_scale():
    h = Height(0.5).moved(0.01, 1e-6).moved(-0.02, 2e-6)
    assert math.isclose(h.metres, 0.5 * 1.01 * 0.98)
    assert math.isclose(h.log_rel, math.log(1.01 * 0.98))
    assert math.isclose(h.variance, 3e-6)
    assert Height(0.5).moved(-3.0, 0.0).metres > 0


def test_before_the_window_is_full_the_anchor_uncertainty_holds_back_a_departure():
    """2 s into a 10 s window, heights seen so far spread by ~0.5 %: a 0.6 % departure could be the first frame's own
    offset (unknown), so it is not used; once the window is full the same departure (the chain being exact) is."""
    def departure_used(seconds: float) -> bool:
        tr = HeightTracker(NOMINAL, 10.0, 3.0)
        t = np.arange(0.0, seconds, 1 / FPS)
        for k, tk in enumerate(t):
            tr.observe(tk, Height(NOMINAL, 0.005 * (-1) ** k, 1e-12 * k))
        before = tr.tracked
        tr.anchor(Height(NOMINAL, 0.006, 1e-12 * len(t)))
        return tr.tracked > before
    assert not departure_used(2.0)
    assert departure_used(12.0)


def _vo_tracker_run(true_log: np.ndarray, seed: int, link_sigma: float):
    """`_run` with the tracker settings of the default VOConfig."""
    c = VOConfig()
    return _run(true_log, np.random.default_rng(seed), c.height_significance, c.height_window, c.height_graded,
                link_sigma, c.height_noise_spread)


def test_the_default_height_estimate_follows_a_bounce_its_links_measure_poorly():
    """A 1 % bounce whose keyframe links err by 0.1 % each (planks, slats and brick in turns on the independent
    renderer): the chain's departure has sigma ~0.3 %, so the 3-sigma switch left nearly every keyframe at the
    nominal height (RMS error ~0.71 %, the bounce itself). The graded estimate (posterior mean) uses what the
    departure says in proportion to its precision."""
    t = np.arange(1800) / FPS
    true_log = np.log1p(0.01 * np.sin(0.7 * t + 1.0))
    for seed in range(3):
        given, truth, _ = _vo_tracker_run(true_log, seed, 1e-3)
        late = np.arange(len(given)) * KEYFRAME_EVERY / FPS > 12.0
        rms = float(np.sqrt(np.mean((given[late] / truth[late] - 1) ** 2)))
        rms_nominal = float(np.sqrt(np.mean((NOMINAL / truth[late] - 1) ** 2)))
        assert rms < 0.6 * rms_nominal, (seed, rms, rms_nominal)


def test_the_default_height_estimate_keeps_a_steady_camera_near_its_nominal_height():
    for seed in range(3):
        given, _, tr = _vo_tracker_run(np.zeros(1800), seed, LINK_SIGMA)
        err = given / NOMINAL - 1
        assert float(np.sqrt(np.mean(err ** 2))) < 2 * LINK_SIGMA, (seed, err)
        assert float(np.max(np.abs(err))) < 4 * LINK_SIGMA * math.sqrt(20)
        assert tr.largest_departure == pytest.approx(float(np.max(np.abs(np.log1p(err)))), abs=1e-12)


def test_graded_shrinks_more_when_the_departure_is_less_certain():
    """The same departure is followed less when its chained variance is larger, and not at all when the window's
    heights show no spread beyond the chain's own noise."""
    def given(chain_variance: float, spread: float) -> float:
        tr = HeightTracker(NOMINAL, 10.0, 3.0, graded=True)
        t = np.arange(0.0, 12.0, 1 / FPS)
        for k, tk in enumerate(t):
            tr.observe(tk, Height(NOMINAL, spread * math.sin(0.7 * tk), chain_variance * tk / 12.0))
        return math.log(tr.anchor(Height(NOMINAL, 0.008, chain_variance)).metres / NOMINAL)
    precise, noisy = given(1e-8, 0.01), given(4e-6, 0.01)
    assert 0.0 < noisy < precise <= 0.0081, (noisy, precise)
    assert given(1e-8, 0.0) == 0.0


def test_the_graded_sigma_is_the_scatter_of_the_departure_of_a_random_walk_chain():
    """A steady camera whose chained heights are a random walk (the links' own errors): the departure d = chain -
    window mean strays from zero by the variance the graded estimate assigns it (a random walk strays from its own
    window mean by a third of its variance over the window; counting all of it, the default, over-shrinks real
    departures 3x when the links' variances are honest)."""
    rng = np.random.default_rng(5)
    link = 3e-4
    ds, variances = [], []
    for _ in range(300):
        tr = HeightTracker(NOMINAL, 10.0, 3.0, graded=True, noise_spread=0.0, random_walk_sigma=True)
        log_rel, var = 0.0, 0.0
        for k in range(int(12 * FPS)):
            if k and k % KEYFRAME_EVERY == 0:
                log_rel += rng.normal(0, link)
                var += link ** 2
            tr.observe(k / FPS, Height(NOMINAL, log_rel, var))
        d, v, _ = tr._graded_terms(Height(NOMINAL, log_rel, var))
        ds.append(d)
        variances.append(v)
    ratio = float(np.mean(np.square(ds)) / np.mean(variances))
    assert 0.7 < ratio < 1.4, ratio


def test_a_bounce_is_followed_before_the_window_is_full():
    """2 s into the run, a 1 % bounce that started at the nominal height (precise links): the heights so far sit
    far from the nominal level and the first frame is known to 0.2 % (`start_sigma`), so most of the departure is
    used (the default, the spread about the short window's own mean as the anchor's uncertainty, keeps only ~half:
    0.5 % off)."""
    t = np.arange(int(2.0 * FPS)) / FPS
    true_log = np.log1p(0.01 * np.sin(0.7 * t))
    tr = HeightTracker(NOMINAL, 10.0, 3.0, graded=True, start_sigma=0.002)
    for tk, x in zip(t, true_log):
        tr.observe(tk, Height(NOMINAL * math.exp(x), x, 1e-9 * tk))
    given = math.log(tr.anchor(Height(NOMINAL, true_log[-1] + 1e-4, 2e-9)).metres / NOMINAL)
    assert abs(given - true_log[-1]) < 0.2 * abs(true_log[-1]), (given, true_log[-1])


def test_the_graded_options_off_are_the_default_estimate():
    """Without the options the graded estimate is the default one (same departure, sigma and prior)."""
    rng = np.random.default_rng(9)
    a = HeightTracker(NOMINAL, 10.0, 3.0, graded=True)
    b = HeightTracker(NOMINAL, 10.0, 3.0, graded=True, random_walk_sigma=False, start_sigma=None)
    log_rel, var = 0.0, 0.0
    for k in range(400):
        log_rel += rng.normal(0, 1e-3)
        var += 1e-6
        h = Height(NOMINAL, log_rel, var)
        if k % 15 == 0 and k:
            assert a.graded_departure(h) == b.graded_departure(h)
            d, sigma, signal = a._departure(h)
            d2, v2, s2 = a._graded_terms(h)
            assert (d, sigma * sigma, signal) == pytest.approx((d2, v2, s2), rel=1e-12, abs=1e-18)
        a.observe(k / FPS, h)
        b.observe(k / FPS, h)


def _chain_error_spread(coupled: bool, wobble: float, seed: int, links: int = 30) -> tuple[float, float]:
    """(RMS chained error, RMS of its stated standard deviation) over many chains of links whose only error is
    -gain . tilt with a slow tilt wobble of standard deviation `wobble` (correlation exp(-dt / 2 s), a link every
    0.25 s), each link's refinement having stated sum(gain^2) tilt_sigma^2 (tilts independent)."""
    rng = np.random.default_rng(seed)
    gain = np.array([0.02, -0.07, 0.03, -0.12])
    tilt_sigma, dt, tau = 0.003, 0.25, 2.0
    rho = math.exp(-dt / tau)
    errs, sds = [], []
    for _ in range(300):
        tilt = rng.normal(0, wobble, 2)
        h = Height(0.5, t=0.0)
        err = 0.0
        for k in range(links):
            new = rho * tilt + math.sqrt(1 - rho * rho) * rng.normal(0, wobble, 2)
            err += -float(gain @ np.concatenate([tilt, new]))
            stated = tilt_sigma ** 2 * float(gain @ gain)
            if coupled:
                h = h.moved_coupled(0.0, 0.0, gain, (k + 1) * dt, wobble, tau)
            else:
                h = h.moved(0.0, stated)
            tilt = new
        errs.append(err)
        sds.append(h.variance)
    return math.sqrt(np.mean(np.square(errs))), math.sqrt(np.mean(sds))


def test_a_chain_of_links_sharing_a_slow_wobble_states_its_error_only_when_coupled():
    err, stated = _chain_error_spread(False, 0.003, seed=1)
    assert err > 2.0 * stated                        # independent tilts: the chain is far too confident
    err, stated = _chain_error_spread(True, 0.003, seed=1)
    assert 0.8 < err / stated < 1.25                 # the correlated wobble counted: an honest chain
    # no wobble: nothing of the tilt prior's part is left in the chain
    h = Height(0.5, t=0.0).moved_coupled(0.001, 2e-8, (0.02, -0.07, 0.03, -0.12), 0.25, 0.0, 2.0)
    assert h.variance == pytest.approx(2e-8)
    assert h.log_rel == pytest.approx(math.log1p(0.001))


@pytest.mark.parametrize("wobble", [0.0, 0.0025])
def test_the_wobble_estimate_finds_the_tilt_really_there(wobble):
    # posterior means under a zero-mean prior of 0.003 rad with posterior sd 0.0005: the wobble's sd is recovered,
    # ~0 for a camera that does not tilt
    rng = np.random.default_rng(3)
    prior, post = 0.003, 0.0005
    k = 1 - post ** 2 / prior ** 2
    est = WobbleEstimate(prior, prior_weight=20)
    for _ in range(500):
        true = rng.normal(0, wobble, 4)
        noise = rng.normal(0, math.sqrt(post ** 2 / k), 4)
        est.add(k * (true + noise), [post ** 2] * 4)
    assert est.sigma == pytest.approx(wobble, abs=4e-4)
    assert WobbleEstimate(prior, prior_weight=20).sigma == pytest.approx(prior)
