"""Fixtures of the kite tests: one wind-box cache directory per module."""
import pytest


@pytest.fixture(scope="module")
def module_cache(tmp_path_factory):
    """One cache directory for the module: each box is generated once."""
    with pytest.MonkeyPatch.context() as mp:
        path = tmp_path_factory.mktemp("wind_cache")
        mp.setenv("KITE_RTO_CACHE", str(path))
        yield path


@pytest.fixture
def cache(module_cache):
    return module_cache
