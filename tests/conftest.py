import os

import pytest

import mi_dsbrdf  # noqa: F401  (variant + plugins)

DATA = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data"))
REQUIRE_DATA = os.environ.get("MI_DSBRDF_REQUIRE_DATA") == "1"


def data_path(*parts):
    """Path under ../shared/data; skips the test when absent, fails instead in CI."""
    path = os.path.join(DATA, *parts)
    if not os.path.exists(path):
        msg = "test data %s not found" % path
        if REQUIRE_DATA:
            pytest.fail(msg + " (MI_DSBRDF_REQUIRE_DATA=1)")
        pytest.skip(msg)
    return path


@pytest.fixture
def nbrdf_file():
    return data_path("merl", "merl_nbrdf_weights.npz")
