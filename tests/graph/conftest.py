"""Fixtures shared by the graph tests."""
import numpy as np
import pytest

from graph import read_graph


@pytest.fixture(scope="module")
def manhattan(shared_data):
    """M3500 (Olson) from the Vertigo set and its ground-truth poses (x, y, theta per node)."""
    root = shared_data / "posegraphs" / "vertigo_from_pyslam" / "manhattan"
    g, t = root / "originalDataset" / "g2o" / "manhattanOlson3500.g2o", \
        root / "groundTruth" / "manhattanOlson3500_nodes_groundTruth.dat"
    if not (g.exists() and t.exists()):
        pytest.skip(f"{g} or its ground truth not present")
    return read_graph(g), np.loadtxt(t, ndmin=2)[:, -3:]
