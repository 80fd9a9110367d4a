"""Real graphs of ../shared/data the graph tests read."""
import pytest

from graph import read_graph


def se_sync_graph(shared_data, name: str):
    """A graph of the SE-Sync set in ../shared/data (intel, CSAIL, parking-garage, ...), skipped where absent."""
    p = shared_data / "posegraphs" / "se-sync" / f"{name}.g2o"
    if not p.exists():
        pytest.skip(f"{p} not present")
    return read_graph(p)
