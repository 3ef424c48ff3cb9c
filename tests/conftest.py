"""Test-session set-up shared by every test module."""
from __future__ import annotations

import os

import pytest


@pytest.fixture(scope="session", autouse=True)
def _fault_free_twin_cache(tmp_path_factory):
    """Fault-free twins (ellipsled/reference.py) are cached in this session's temp folder,
    never in the user's cache; child processes (the SIL launcher) inherit it."""
    old = os.environ.get("ELLIPSLED_CACHE")
    os.environ["ELLIPSLED_CACHE"] = str(tmp_path_factory.mktemp("ellipsled-cache"))
    yield
    if old is None:
        os.environ.pop("ELLIPSLED_CACHE", None)
    else:
        os.environ["ELLIPSLED_CACHE"] = old
