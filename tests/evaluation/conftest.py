"""Fixtures of the evaluation tests: colour tables cached in a temporary folder, and a small 3-ink table."""

import pytest

from inkopt.evaluation.colour_table import colour_table
from inkopt.model import InkTable

INKS3 = InkTable.from_names(["cyan", "magenta", "white"])


@pytest.fixture(scope="module", autouse=True)
def cache_in_tmp(tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("INKOPT_CACHE_DIR", str(tmp_path_factory.mktemp("cache")))
        yield


@pytest.fixture(scope="module")
def table3():
    """cyan, magenta, white; step 1/2, 1 mm patches."""
    return colour_table(INKS3, patch_mm=1.0, step=2, max_stderr=0.5)
