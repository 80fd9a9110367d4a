"""graph.trial: a loop's squared Mahalanobis distance with the map's own uncertainty between its ends added
(graph.core_start judges the loops outside the core by it).

Under drift the map between a lone loop's ends is loose and the loop fits once that uncertainty is counted; between
two nodes of a densely looped stretch the map is tight and a wrong loop misses either way.
"""
import numpy as np
from scipy.stats import chi2

from graph import GraphParams, optimize
from graph.batch import build
from graph.factors import values_from_array
from graph.trial import MapUncertainty
from tests.graph.synth import noisy_graph, square_laps


def _drift_map(bias: float = 0.0005):
    """Three laps of a square, a heading bias of `bias` rad per odometry step (a quarter of its noise); lap 2's loops kept, lap 3 loop-free. The
    map solved on odometry + lap 2's loops, with the lone loop (lap 3 back to the start) and one wrong loop (two
    nodes of lap 2 three steps apart claimed at one place) as factors judged against it."""
    truth = square_laps(laps=3, side=8)
    data, truth = noisy_graph(truth, np.random.default_rng(3), sigma_xy=0.01, sigma_th=0.002)
    data.measurements[~data.is_loop, 2] += bias
    loops = np.flatnonzero(data.is_loop)
    a, b = data.edge_index_pairs()
    lap3 = loops[np.maximum(a[loops], b[loops]) >= 64]
    keep = np.ones(data.num_edges, bool)
    keep[lap3] = False
    lone = lap3[-1]
    solved = data.with_edges(keep)
    res = optimize(solved, GraphParams.preset("least_squares"))
    wrong = data.append_edges(data.node_ids[[40]], data.node_ids[[43]], np.zeros((1, 3)), data.information[lone][None],
                              np.ones(1, bool))
    judged = wrong.with_edges(np.r_[np.flatnonzero(keep), lone, wrong.num_edges - 1])
    built = build(judged, GraphParams.preset("least_squares"))
    values = values_from_array(2, res.poses)
    kept = np.r_[np.ones(built.loop_idx.size - 2, bool), False, False]
    return built, values, kept


def test_lone_loop_under_drift_fits_the_map_uncertainty_and_a_wrong_loop_in_a_looped_stretch_does_not():
    built, values, kept = _drift_map()
    c2 = chi2.ppf(0.99, 3)
    plain = built.r2(values)[-2:]
    m = MapUncertainty(built.graph(kept), values)
    with_map = np.array([m.r2(f) for f in built.loops[-2:]])
    lone, wrong = 0, 1
    assert plain[lone] > 10 * c2                      # the drift is its residual at the map without it
    assert with_map[lone] <= c2                       # ... and within the map's own uncertainty
    assert with_map[wrong] > 10 * c2                  # a tight stretch: the wrong loop misses either way
    assert np.all(with_map <= plain + 1e-9)


def test_bound_from_the_end_poses_own_marginals_never_exceeds_the_joint_distance():
    built, values, kept = _drift_map()
    m = MapUncertainty(built.graph(kept), values)
    exact = np.array([m.r2(f) for f in built.loops[-2:]])
    lower = np.array([m.lower(f) for f in built.loops[-2:]])
    assert np.all(lower <= exact + 1e-9)
    assert lower[1] > 10 * chi2.ppf(0.99, 3)          # the wrong loop in a looped stretch misses even the bound
