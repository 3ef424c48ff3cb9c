"""FSW parameters: each module declares its parameters once (name, bounds, unit, doc);
defaults live in data/fsw/default.toml; a scenario's [fsw] table and the ground may
override them. Every value is validated against its bounds (finite, within [lo, hi]).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from common.config import DATA_DIR, ConfigError, Table, load_toml


@dataclass(frozen=True)
class Param:
    name: str               # "section.key", e.g. "control.lambda_radps"; <= 16 chars after the dot is MAVLink-friendly
    lo: float
    hi: float
    unit: str = ""
    doc: str = ""
    integer: bool = False
    ground_settable: bool = True
    choices: tuple[str, ...] = ()   # a word parameter (lo/hi unused): its value is one of these

    def check(self, value) -> float | str:
        """The validated value, or ValueError with a reason a user can act on."""
        if self.choices:
            if value not in self.choices:
                raise ValueError(f"{self.name}: must be one of {', '.join(self.choices)}, got {value!r}")
            return value
        if isinstance(value, bool):
            value = float(value)
        if not isinstance(value, (int, float)):
            raise ValueError(f"{self.name}: must be a number, got {value!r}")
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{self.name}: must be finite, got {value!r}")
        if v < self.lo or v > self.hi:
            raise ValueError(f"{self.name}: {v:g} outside [{self.lo:g}, {self.hi:g}] {self.unit}".rstrip())
        if self.integer and not v.is_integer():
            raise ValueError(f"{self.name}: must be an integer, got {v:g}")
        return v


DEFAULT_FILE = DATA_DIR / "fsw" / "default.toml"


def load_params(params: list[Param], overrides: dict | None = None,
                file: str | Path = DEFAULT_FILE) -> dict[str, float]:
    """Values of ``params`` from the defaults file, with ``overrides`` (a scenario's [fsw]
    table, dotted or nested) applied; every value checked against its bounds."""
    raw = load_toml(file)
    out: dict[str, float] = {}
    flat_over = _flatten(overrides or {})
    for p in params:
        section, key = p.name.split(".", 1)
        if p.name in flat_over:
            where, value = "scenario [fsw]", flat_over[p.name]
        else:
            tbl = raw.get(section, {})
            if key not in tbl:
                raise ConfigError(file, p.name, "missing (required)")
            where, value = str(file), tbl[key]
        try:
            out[p.name] = p.check(value)
        except ValueError as e:
            raise ConfigError(where, p.name, str(e).split(": ", 1)[1]) from None
    return out


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        name = f"{prefix}.{k}" if prefix else k
        if isinstance(v, dict):
            out.update(_flatten(v, name))
        else:
            out[name] = v
    return out
