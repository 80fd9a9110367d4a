"""Aperture-aware weighting: LK fixes an edge-like window only across its edge, so the tilt refinement weighs each
residual by the shape of the window's structure tensor (odometry.tracking.aperture_weights)."""
from __future__ import annotations

import math

import numpy as np

from odometry.tilt_refine import refine_planar_tilt
from odometry.tracking import aperture_weights, structure_tensors
from tests.odometry.test_tilt_refine import CAM, _views


def test_an_edge_window_weighs_little_along_the_edge():
    u = np.arange(640)
    stripes = np.tile((128 + 60 * np.sin(2 * np.pi * u / 23.0)).astype(np.uint8), (480, 1))  # edges along v
    w = aperture_weights(structure_tensors(stripes, 15), np.array([[320.0, 240.0], [101.0, 77.0]]))
    assert np.all(w[:, 0, 0] > 1.8) and np.all(w[:, 1, 1] < 0.1)     # floor x = u: across the edges
    rng = np.random.default_rng(0)
    noise = rng.integers(0, 255, (480, 640)).astype(np.uint8)
    w = aperture_weights(structure_tensors(noise, 15), rng.uniform(20, 440, (20, 2)))
    assert np.all(np.linalg.eigvalsh(w)[:, 0] > 0.5)                 # a textured window: both axes count


def test_weighting_removes_the_aperture_error_from_the_height():
    """Half the points are edges whose LK error lies along the edge (as large as the model misfit of a window
    rotated by a turn); with the weights the height ratio and the motion come out as if they were not there."""
    rng = np.random.default_rng(3)
    delta = np.array([0.09, 0.01, 0.15])
    h_cur = 0.5 * 1.004
    xr, xc = _views(delta, (0.0, 0.0), (0.0, 0.0), 0.5, h_cur, n=160, seed=2)
    n = len(xc)
    ang = rng.uniform(0, math.pi, n)
    d = np.column_stack([np.cos(ang), np.sin(ang)])            # edge directions (image and floor alike, up to sign)
    edge = np.arange(n) % 2 == 0
    # the error along each edge, in normalised coordinates: 0.6 px, outwards (a misfit shared by the windows of a
    # view, e.g. rotated ones, projected on each edge: its radial part is a scale change)
    out = np.sign(np.sum(d * xc, axis=1))
    err = np.where(edge, 0.6 / CAM.fx * out, 0.0)[:, None] * d
    xc_bad = xc + err
    w = np.repeat(np.eye(2)[None], n, 0)
    # edge points: information across the edge only (in floor axes y = -v, so the direction's y flips)
    df = d * [1.0, -1.0]
    w[edge] = 2 * np.einsum("ni,nj->nij", np.column_stack([-df[:, 1], df[:, 0]]), np.column_stack([-df[:, 1], df[:, 0]]))[edge] \
        + 0.05 * np.eye(2)
    kw = dict(tilt_sigma=0.003, height_sigma=0.002, sigma_floor=1e-6, iterations=4)
    plain = refine_planar_tilt(CAM, xr, xc_bad, delta, **kw)
    weighted = refine_planar_tilt(CAM, xr, xc_bad, delta, weights=w, **kw)
    s_true = h_cur / 0.5 - 1
    plain_err, weighted_err = abs(plain.params[7] - s_true), abs(weighted.params[7] - s_true)
    assert plain_err > 5e-4                   # the unweighted height is off by more than the bounce it tracks
    assert weighted_err < 0.2 * plain_err
    assert np.hypot(*(weighted.delta[:2] - delta[:2])) < np.hypot(*(plain.delta[:2] - delta[:2]))
