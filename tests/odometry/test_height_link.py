"""The redundant height link (odometry.height_link): fusing each keyframe's chained height with its height measured
against the keyframe before the last one lowers the chain's error, an outlying link is gated out, and on a
rendered sequence whose camera height wobbles the VO's trajectory scale error drops with it."""
from __future__ import annotations

import math

import numpy as np
import pytest

from odometry.height import Height
from odometry.height_link import HeightLinks
from odometry.vo import VisualOdometry, VOConfig
from tests.odometry._floor import texture
from tests.odometry.test_vo import _bouncing, _segment_error

SIGMA = 1e-3   # per link, relative


def _chain(rng: np.random.Generator, n: int, redundant: bool, true_log: np.ndarray,
           outliers: frozenset[int] = frozenset()) -> tuple[np.ndarray, HeightLinks]:
    """Keyframe heights chained from links a_k (k-1 -> k) and, with `redundant`, fused with links b (k-2 -> k);
    every link is the true log ratio + N(0, SIGMA) (b + 0.05 at the keyframes in `outliers`)."""
    links = HeightLinks(prior_triangles=5, gate=3.0)
    kfs = [Height(0.5)]
    for k in range(1, n):
        a = true_log[k] - true_log[k - 1] + rng.normal(0, SIGMA)
        via_k1 = kfs[k - 1].moved(math.expm1(a), SIGMA ** 2)
        via_k2 = None
        if redundant and k >= 2:
            b = true_log[k] - true_log[k - 2] + rng.normal(0, SIGMA) + (0.05 if k in outliers else 0.0)
            via_k2 = kfs[k - 2].moved(math.expm1(b), SIGMA ** 2)
        kfs.append(links.fuse(kfs[k - 2] if k >= 2 else kfs[0], kfs[k - 1], via_k1, via_k2))
    return np.array([h.log_rel for h in kfs]) - true_log, links


def test_the_fused_chain_strays_less_than_the_single_chain():
    true_log = np.log1p(0.01 * np.sin(np.arange(200) / 10.0))
    single, fused = [], []
    for seed in range(40):
        single.append(_chain(np.random.default_rng(seed), 200, False, true_log)[0][-1])
        err, links = _chain(np.random.default_rng(seed), 200, True, true_log)
        fused.append(err[-1])
        assert links.rejected <= 10 and links.used + links.rejected == 198   # a 3-sigma gate: a few honest ones
    rms_single, rms_fused = math.sqrt(np.mean(np.square(single))), math.sqrt(np.mean(np.square(fused)))
    assert rms_fused < 0.8 * rms_single, (rms_fused, rms_single)
    # honest links: the triangles' normalised disagreement is about 1
    _, links = _chain(np.random.default_rng(0), 200, True, true_log)
    assert 0.7 < links.nees < 1.4, links.nees


def test_an_outlying_k2_link_is_gated_out():
    true_log = np.zeros(60)
    err, links = _chain(np.random.default_rng(1), 60, True, true_log, outliers=frozenset({20, 40}))
    assert 2 <= links.rejected <= 4 and links.used + links.rejected == 58
    assert np.max(np.abs(err)) < 0.01    # a 5 % outlier fused in would have moved the chain by ~2 %


def test_without_a_second_link_the_chain_is_unchanged():
    links = HeightLinks()
    via = Height(0.5).moved(0.01, 1e-6)
    assert links.fuse(Height(0.5), Height(0.5), via, None) == via


@pytest.fixture(scope="module")
def carpet(shared_data):
    return texture(shared_data)


def test_vo_with_the_redundant_link_has_a_smaller_scale_error_on_a_bouncing_camera(carpet):
    """A camera height that wobbles by 1 % over 6 s: with height_redundant the keyframes' heights are measured
    through two paths, and the segment (scale) error after the height window has filled falls below the single
    chain's. A carpet photograph: its keyframes renew while keyframe k-2 still overlaps (on a synthetic texture
    that tracks every corner they renew only at 40 % overlap, and k-2 is out of view on a straight path)."""
    tex = carpet
    cam, poses, imgs = _bouncing(tex, 0.01, n=440)
    errors, vos = {}, {}
    # the redundant link fuses per-frame link variances; it was built on (and is off by default against) the
    # chain without the tilt coupling of the link variances
    for name, cfg in (("chain", VOConfig(height_tilt_coupling=False)),
                      ("redundant", VOConfig(height_redundant=True, height_tilt_coupling=False))):
        vo = VisualOdometry(cam, cfg)
        for i, img in enumerate(imgs):
            vo.process(img, i / 20.0)
        errors[name], vos[name] = _segment_error(vo.poses, poses, start=240), vo
    assert vos["redundant"].height_links.used >= 5, vos["redundant"].height_links.used
    assert vos["chain"].height_links.used == 0
    assert errors["redundant"] < 0.95 * errors["chain"], errors
