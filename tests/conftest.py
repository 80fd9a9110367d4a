import pytest

from vslam.paths import shared_data_dir


@pytest.fixture(scope="session")
def shared_data():
    """The real data sets in ../shared/data; tests that need them skip with a reason where they are absent."""
    d = shared_data_dir()
    if d is None:
        pytest.skip("../shared/data is not present on this machine (set VSLAM_SHARED_DATA)")
    return d
