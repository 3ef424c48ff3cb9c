"""Where numba keeps the compiled kernels: one folder per version of the sources.

numba's own cache (``@njit(cache=True)``) keys a kernel by its own source file only. A kernel
that calls a kernel of another file keeps the callee it was compiled with when only the
callee's file changes: a guidance predictor went on flying an older bank shaper's law, from
its cache, after the shaper had changed, while a fresh checkout of the same commit flew the
new one. So every kernel of the product is cached under one folder named by a digest of the
sources of the packages that hold kernels (common, fsw, sim): any change there compiles them
afresh (a first-call cost), and what runs is always the code in the tree.

The folder is ``<base>/<digest>``, base ``$ELLIPSLED_NUMBA_CACHE`` or else
``$XDG_CACHE_HOME/ellipsled/numba`` (``~/.cache/ellipsled/numba``). It is handed to numba as
``NUMBA_CACHE_DIR``, which child processes inherit. Folders of other digests unused for
``STALE_DAYS`` are removed.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("common", "fsw", "sim")
STALE_DAYS = 7.0


def sources_digest(root: Path = ROOT, packages=PACKAGES) -> str:
    """A digest of every .py file of ``packages`` under ``root`` (relative paths and contents)."""
    h = hashlib.blake2b(digest_size=10)
    for pkg in packages:
        for f in sorted((root / pkg).rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode())
            h.update(b"\0")
            h.update(f.read_bytes())
            h.update(b"\0")
    return h.hexdigest()


def cache_base() -> Path:
    if os.environ.get("ELLIPSLED_NUMBA_CACHE"):
        return Path(os.environ["ELLIPSLED_NUMBA_CACHE"])
    xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(xdg) / "ellipsled" / "numba"


def _prune(base: Path, keep: str, now: float) -> None:
    try:
        for d in base.iterdir():
            if d.name != keep and d.is_dir() and now - d.stat().st_mtime > STALE_DAYS * 86400.0:
                shutil.rmtree(d, ignore_errors=True)
    except OSError:
        pass


def configure() -> str:
    """Point numba's cache at this version's folder (before any kernel is decorated); returns it."""
    digest = sources_digest()
    base = cache_base()
    path = base / digest
    if os.environ.get("NUMBA_CACHE_DIR") == str(path):
        return str(path)                       # this process or its parent did it already
    try:
        path.mkdir(parents=True, exist_ok=True)
        os.utime(path)                         # marks this version as in use for the pruning
    except OSError:
        return os.environ.get("NUMBA_CACHE_DIR", "")   # no writable cache: numba decides
    _prune(base, digest, time.time())
    os.environ["NUMBA_CACHE_DIR"] = str(path)
    # numba imported already: its config follows; not yet: it reads the variable when it is
    # (importing it here would import numpy too, before a real-time process has set numpy's
    # threads: common/rt.py single_threaded_numerics)
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.CACHE_DIR = str(path)
    return str(path)
