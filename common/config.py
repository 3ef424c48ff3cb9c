"""Loading and validating the project's data files (TOML).

Every value is checked once at load; a bad file raises ConfigError whose message names
the file, the field (dotted path) and the reason, e.g.
``data/vehicles/x.toml: vehicle.mass_kg: must be > 0, got -3``.
"""
from __future__ import annotations

import difflib
import math
import tomllib
from pathlib import Path
from typing import Any, Iterable

import numpy as np

DATA_DIR = Path(__file__).resolve().parent.parent / "data"
# the flight-software parameters' defaults: every parameter a scenario's [fsw] may override
FSW_DEFAULTS_FILE = DATA_DIR / "fsw" / "default.toml"

_MISSING = object()


class ConfigError(ValueError):
    """A data file or parameter that fails validation."""

    def __init__(self, file: str | Path, field: str, reason: str):
        self.file, self.field, self.reason = str(file), field, reason
        super().__init__(f"{file}: {field}: {reason}")


def load_toml(path: str | Path) -> dict:
    path = Path(path)
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(path, "<file>", "file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(path, "<file>", f"not valid TOML: {e}") from None


def resolve(kind: str, name_or_path: str | Path) -> Path:
    """A data file by name (``data/<kind>/<name>.toml``) or by explicit path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or (len(p.parts) > 1 and not (DATA_DIR / kind / f"{name_or_path}.toml").exists()):
        return p
    cand = DATA_DIR / kind / f"{name_or_path}.toml"
    if not cand.exists():
        known = sorted(x.stem for x in (DATA_DIR / kind).glob("*.toml"))
        raise ConfigError(cand, "<file>", f"no {kind[:-1]} named {name_or_path!r}; known: {', '.join(known)}")
    return cand


class Table:
    """A TOML table with typed, bounds-checked accessors that report file and field."""

    def __init__(self, data: dict, file: str | Path, prefix: str = ""):
        if not isinstance(data, dict):
            raise ConfigError(file, prefix or "<root>", f"must be a table, got {type(data).__name__}")
        self.data, self.file, self.prefix = data, str(file), prefix
        self._used: set[str] = set()

    def _name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, reason: str) -> ConfigError:
        return ConfigError(self.file, self._name(key), reason)

    def has(self, key: str) -> bool:
        self._used.add(key)         # a name the reader knows, present or not
        return key in self.data

    def _get(self, key: str, default: Any) -> Any:
        self._used.add(key)
        if key not in self.data:
            if default is _MISSING:
                raise self.error(key, "missing (required)")
            return default
        return self.data[key]

    def num(self, key: str, default: Any = _MISSING, lo: float | None = None, hi: float | None = None,
            lo_open: bool = False, hi_open: bool = False, integer: bool = False) -> float:
        v = self._get(key, default)
        if v is None:
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.error(key, f"must be a number, got {v!r}")
        if integer and not (isinstance(v, int) or float(v).is_integer()):
            raise self.error(key, f"must be an integer, got {v!r}")
        if not math.isfinite(v):
            raise self.error(key, f"must be finite, got {v!r}")
        check_bounds(self, key, v, lo, hi, lo_open, hi_open)
        return int(v) if integer else float(v)

    def vec(self, key: str, n: int | None = None, default: Any = _MISSING, lo: float | None = None,
            hi: float | None = None, lo_open: bool = False, hi_open: bool = False) -> np.ndarray:
        v = self._get(key, default)
        if not isinstance(v, (list, tuple)) or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            raise self.error(key, f"must be a list of numbers, got {v!r}")
        if n is not None and len(v) != n:
            raise self.error(key, f"must have {n} elements, got {len(v)}")
        a = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(a)):
            raise self.error(key, "must be finite")
        for x in a:
            check_bounds(self, key, x, lo, hi, lo_open, hi_open)
        return a

    def matrix(self, key: str, rows: int, cols: int) -> np.ndarray:
        v = self._get(key, _MISSING)
        if not isinstance(v, list) or len(v) != rows:
            raise self.error(key, f"must be a list of {rows} rows")
        out = np.empty((rows, cols))
        for i, row in enumerate(v):
            if not isinstance(row, list) or len(row) != cols or not all(
                    isinstance(x, (int, float)) and not isinstance(x, bool) for x in row):
                raise self.error(key, f"row {i + 1} must be a list of {cols} numbers")
            out[i] = row
        if not np.all(np.isfinite(out)):
            raise self.error(key, "must be finite")
        return out

    def str(self, key: str, default: Any = _MISSING, choices: Iterable[str] | None = None) -> str:
        v = self._get(key, default)
        if not isinstance(v, str):
            raise self.error(key, f"must be a string, got {v!r}")
        if choices is not None and v not in choices:
            raise self.error(key, f"must be one of {', '.join(choices)}; got {v!r}")
        return v

    def bool(self, key: str, default: Any = _MISSING) -> bool:
        v = self._get(key, default)
        if not isinstance(v, bool):
            raise self.error(key, f"must be true or false, got {v!r}")
        return v

    def table(self, key: str, default: Any = _MISSING) -> "Table":
        v = self._get(key, default)
        return Table(v, self.file, self._name(key))

    def tables(self, key: str) -> list["Table"]:
        v = self._get(key, [])
        if not isinstance(v, list):
            raise self.error(key, "must be an array of tables ([[...]])")
        return [Table(x, self.file, f"{self._name(key)}[{i}]") for i, x in enumerate(v)]

    def raw(self, key: str, default: Any = _MISSING) -> Any:
        return self._get(key, default)

    def reject_unknown(self) -> None:
        """Fail on keys nobody read: catches typos such as ``mass_kgg`` (the nearest valid
        name is suggested)."""
        unknown = sorted(set(self.data) - self._used)
        if unknown:
            raise self.error(unknown[0], unknown_key(unknown[0], self._used))


def unknown_key(key: str, valid) -> str:
    """The reason for refusing ``key``: unknown, with the nearest of the ``valid`` names."""
    near = difflib.get_close_matches(key, sorted(valid), n=1, cutoff=0.6)
    if near:
        return f"unknown key (did you mean {near[0]}?)"
    return f"unknown key (valid: {', '.join(sorted(valid))})" if valid else "unknown key (no keys here)"


def check_bounds(t: Table, key: str, v: float, lo, hi, lo_open=False, hi_open=False) -> None:
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise t.error(key, f"must be {'>' if lo_open else '>='} {lo}, got {v}")
    if hi is not None and (v >= hi if hi_open else v > hi):
        raise t.error(key, f"must be {'<' if hi_open else '<='} {hi}, got {v}")
