"""Test-session set-up shared by every test module."""
from __future__ import annotations

import os

import pytest


def pytest_collection_modifyitems(config, items):
    """Real-time SIL runs (marker ``realtime``: SCHED_FIFO processes that spin while they wait)
    run one at a time on one xdist worker: two of them at the same FIFO priority on the same
    CPUs would take turns at each other's deadlines. Other tests run beside them, below FIFO."""
    for item in items:
        if item.get_closest_marker("realtime") is not None:
            item.add_marker(pytest.mark.xdist_group("realtime"))


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
