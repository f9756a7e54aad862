import pytest

from twin.twin import Twin


@pytest.fixture(scope="session")
def twin_b():
    """Type B in the laboratory mill with the default effects."""
    return Twin("B", mill="lab")


@pytest.fixture(scope="session")
def batch_b():
    """Type B batch mill: breakage only."""
    return Twin("B", mill="lab", effects=["breakage"], n_mixers=1)
