"""Test-session set-up shared by every test module."""
from __future__ import annotations

import os

import pytest


def pytest_itemcollected(item):
    """Real-time SIL runs (marker ``realtime``: SCHED_FIFO processes that spin while they wait)
    run one at a time on one xdist worker: two of them at the same FIFO priority on the same
    CPUs take turns at each other's deadlines (measured: the FSW's loop held off 4 s). Other
    tests run beside them, below FIFO. The mark is added as each item is collected, before
    xdist's collection_modifyitems hook turns it into the node id's ``@group`` suffix."""
    if item.get_closest_marker("realtime") is not None:
        item.add_marker(pytest.mark.xdist_group("realtime"))


def pytest_collection_finish(session):
    """Under ``--dist loadgroup`` every grouped item must carry its group in its node id, or
    xdist schedules it like any other test: refused loudly rather than ignored (pytest 9.2
    moved node ids where pytest-xdist 3.8 does not write them; requirements.in pins pytest)."""
    if not getattr(session.config.option, "loadgroup", False):     # set on xdist workers only
        return
    lost = [i.nodeid for i in session.items
            if any(True for _ in i.iter_markers("xdist_group")) and "@" not in i.nodeid]
    if lost:
        raise pytest.UsageError(f"--dist loadgroup: {len(lost)} grouped tests lost their group "
                                f"(e.g. {lost[0]}); this pytest / pytest-xdist pair does not apply "
                                "xdist_group (see requirements.in)")


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
