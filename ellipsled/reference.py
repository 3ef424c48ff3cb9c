"""The fault-free twin of a run: the same scenario, seed, reference schedule, parameters and
identification mode flown without faults. The fault-attributable bank error
(metrics.fault_attributable_max_deg) is a run's bank error minus its twin's.

Twins are cached as small .npz files keyed by a hash of everything that decides the
flight (the scenario's content except its name and faults, the seed, the FSW default
parameters and the source of the code that flies it), so a report, a batch re-run or a
Monte Carlo campaign flies each twin once. Cache folder: the caller's (e.g. under the
run's output) or ``ELLIPSLED_CACHE``, else ``$XDG_CACHE_HOME/ellipsled``, else
``~/.cache/ellipsled``, with a ``fault-free`` sub-folder.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from functools import lru_cache
from pathlib import Path

import numpy as np

from common.model import Scenario
from fsw.params import DEFAULT_FILE

from . import lockstep
from .sil import fsw_report, history
from .sil.history import History

# What a twin keeps: enough for the bank error, aligned on k (a full entry ~0.5 MB compressed).
TWIN_FIELDS = ("k", "t_s", "bank_rad", "bank_ref_rad")
# Source trees whose code decides a flight (a change there invalidates every twin), and the
# harness modules that fly a twin.
_CODE_DIRS = ("fsw", "sim", "common", "interfaces")
_CODE_MODULES = (lockstep, history, fsw_report)
_ROOT = Path(__file__).resolve().parent.parent
_IGNORED = {"name", "description", "file", "faults"}


def default_cache_dir() -> Path:
    base = os.environ.get("ELLIPSLED_CACHE") or (Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
                                                  / "ellipsled")
    return Path(base) / "fault-free"


def fault_free(scn: Scenario) -> Scenario:
    return scn.with_(faults=(), name=f"{scn.name}-fault-free")


def _canon(x):
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return {f.name: _canon(getattr(x, f.name)) for f in dataclasses.fields(x) if f.name not in _IGNORED}
    if isinstance(x, dict):
        return {str(k): _canon(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_canon(v) for v in x]
    if isinstance(x, np.ndarray):
        return [_canon(v) for v in x.tolist()]
    if isinstance(x, (float, np.floating)):
        return repr(float(x))          # exact: a different bit pattern is a different flight
    if isinstance(x, (np.integer, np.bool_)):
        return x.item()
    return x


@lru_cache(maxsize=1)
def code_digest() -> str:
    """Hash of the flight code and the FSW default parameters, read once per process."""
    h = hashlib.sha256()
    files = sorted(p for d in _CODE_DIRS for p in (_ROOT / d).rglob("*.py"))
    files += [Path(m.__file__).resolve() for m in _CODE_MODULES] + [Path(DEFAULT_FILE)]
    for p in files:
        h.update(str(p.relative_to(_ROOT)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def twin_key(scn: Scenario, seed: int) -> str:
    """Cache key of the fault-free twin of (scenario, seed)."""
    content = json.dumps({"scenario": _canon(scn), "seed": int(seed), "code": code_digest()}, sort_keys=True)
    return hashlib.sha256(content.encode()).hexdigest()[:32]


def fly_twin(scn: Scenario, seed: int) -> History:
    return lockstep.fly(fault_free(scn), seed, verify_every=0).history


def fault_free_history(scn: Scenario, seed: int, cache_dir: str | Path | None = None) -> History:
    """The twin's history (TWIN_FIELDS only), from the cache or flown now and cached.
    ``scn`` is the prepared scenario of the run (duration and command-line changes applied)."""
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = folder / f"{twin_key(scn, seed)}.npz"
    if path.exists():
        try:
            return History.load(path)
        except (OSError, ValueError, KeyError, EOFError):
            pass                       # a damaged entry is flown again and replaced
    h = fly_twin(scn, seed)
    store_twin(scn, seed, h, folder)
    return h


def store_twin(scn: Scenario, seed: int, h: History, cache_dir: str | Path | None = None) -> None:
    """Cache ``h`` as the fault-free twin of (scn, seed): a run flown without any fault is
    its own twin (a report stores its nominal run so the faulted cases need not fly it)."""
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    path = folder / f"{twin_key(scn, seed)}.npz"
    folder.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".npz.tmp")
    os.close(fd)
    try:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **{k: h[k] for k in TWIN_FIELDS})
        os.replace(tmp, path)          # atomic: parallel workers may write the same twin
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def fault_free_reference(h: History, scn: Scenario, seed: int, faults_applied: list,
                         cache_dir: str | Path | None = None) -> History:
    """The fault-free twin of a run whose history is ``h``: the run itself when no fault was
    applied, else fault_free_history()."""
    if not faults_applied:
        return h
    return fault_free_history(scn, seed, cache_dir)
