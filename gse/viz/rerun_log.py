"""Rerun's own log lines: configured once, before the SDK loads.

The Rerun SDK logs through its Rust logger, whose filter is read from ``RUST_LOG`` once, when
``rerun`` is first imported. The live .rrd is streamed without a footer on purpose (sinks.py
says why; the footer is added when the bridge closes, and the bridge tells the user so), so
the SDK's ``WARN ... FileSink ... write_footer=false`` line is about a choice made here, not a
problem for the user: that one target, ``re_log_encoding::rrd::file_sink``, is filtered to
errors. Everything else keeps the SDK's filter (its default, or the user's ``RUST_LOG``), and
processes started later (the viewer, ``rerun rrd optimize``) see ``RUST_LOG`` unchanged.

The package's ``__init__`` imports this module first, so every ``gse.viz`` module loads Rerun
through it.
"""
from __future__ import annotations

import os
import sys

FILE_SINK_TARGET = "re_log_encoding::rrd::file_sink"
SDK_DEFAULT_FILTER = "warn"    # what the Python SDK logs when RUST_LOG is unset


def rerun_log_filter(current: str | None) -> str:
    """The ``RUST_LOG`` Rerun loads with: ``current`` (the user's, or the SDK's default when
    unset) with the file sink's target at error level, unless ``current`` names it already."""
    base = current.strip() if current and current.strip() else SDK_DEFAULT_FILTER
    if FILE_SINK_TARGET in base:
        return base
    return f"{base},{FILE_SINK_TARGET}=error"


def import_rerun():
    """Import ``rerun`` with ``rerun_log_filter`` in force, then restore ``RUST_LOG``.
    Returns the module (already loaded elsewhere: loaded as it was)."""
    if "rerun" in sys.modules:
        return sys.modules["rerun"]
    old = os.environ.get("RUST_LOG")
    os.environ["RUST_LOG"] = rerun_log_filter(old)
    try:
        import rerun
    finally:
        if old is None:
            os.environ.pop("RUST_LOG", None)
        else:
            os.environ["RUST_LOG"] = old
    return rerun


import_rerun()
