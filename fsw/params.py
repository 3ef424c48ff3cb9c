"""FSW parameters: each owner (the module or class that uses a parameter) declares it once
(name, bounds, unit, doc, ground-settable); defaults live in data/fsw/default.toml; a
scenario's [fsw] table and the ground may override them. Every value is validated against
its bounds (finite, within [lo, hi]).

``ParamRegistry`` holds the declarations, the current values and, for every ground-settable
parameter, the hook of its owner that applies a new value (so it takes effect from the next
control cycle on). A ground-settable parameter without a hook is a construction error: a
value the ground sets is never acknowledged and then ignored.

MAVLink param ids (<= 16 characters) are generated from the names (``param_ids``); the
table (``ellipsled params --markdown``) is in the README.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from pathlib import Path

from common.config import FSW_DEFAULTS_FILE, ConfigError, load_toml, unknown_key


def periods(duration_s: float, dt_s: float) -> int:
    """Control periods (at least 1) nearest ``duration_s`` at control period ``dt_s``: how a
    persistence given in seconds becomes a count of per-period samples at any control rate."""
    return max(1, int(round(duration_s / dt_s)))


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
    owner: str = ""         # who declares and applies it (set by ParamRegistry)

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


DEFAULT_FILE = FSW_DEFAULTS_FILE


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


# ---------------------------------------------------------------- MAVLink param ids

PARAM_ID_LEN = 16
PARAM_PREFIX = {"control": "C_", "allocator": "A_", "fdir": "F_", "driver": "D_", "executive": "X_",
                "guidance": "G_", "npc": "N_"}


def param_id(name: str) -> str:
    """MAVLink param_id (<= 16 chars) of a parameter "section.key": a section prefix + the
    key in upper case, cut to 16 characters (collisions aside, see ``param_ids``)."""
    section, key = name.split(".", 1)
    prefix = PARAM_PREFIX.get(section, section[:1].upper() + "_")
    return (prefix + key.upper())[:PARAM_ID_LEN]


def param_ids(names: Iterable[str]) -> dict[str, str]:
    """{name: param_id} for a set of names, unique: sorted order, later colliding names get
    "~1", "~2", ... in their last characters."""
    out: dict[str, str] = {}
    used: set[str] = set()
    for name in sorted(names):
        pid = param_id(name)
        n = 0
        while pid in used:
            n += 1
            suffix = f"~{n}"
            pid = param_id(name)[:PARAM_ID_LEN - len(suffix)] + suffix
        used.add(pid)
        out[name] = pid
    return out


# ---------------------------------------------------------------- the registry

Hook = Callable[[str, float], object]


class ParamRegistry:
    """Every FSW parameter: declaration, value, owner's hook.

    ``declarations``: (owner, [Param, ...]) pairs, each parameter declared by exactly one
    owner. ``values`` is the dict of current values (validated; read by the owners at
    construction). ``bind(owner, hook)`` registers the function that applies a new value
    of that owner's parameters; ``set`` validates, calls the hook (which may refuse with
    ValueError: nothing changes) and only then stores the value.
    """

    def __init__(self, declarations: Iterable[tuple[str, list[Param]]], overrides: dict | None = None,
                 file: str | Path = DEFAULT_FILE) -> None:
        self.table: dict[str, Param] = {}
        for owner, plist in declarations:
            for p in plist:
                if p.name in self.table:
                    raise ValueError(f"{p.name}: declared by {self.table[p.name].owner} and by {owner}")
                self.table[p.name] = replace(p, owner=owner)
        # every name in the defaults file and in the overrides is a declared parameter: a
        # misspelt one is refused (with the nearest name), never ignored
        for where, names in ((str(file), _flatten(load_toml(file))), ("parameter overrides", _flatten(overrides or {}))):
            for name in sorted(set(names) - set(self.table)):
                raise ConfigError(where, name, unknown_key(name, self.table))
        self.values: dict[str, float] = load_params(list(self.table.values()), overrides, file)
        self.defaults = dict(self.values)        # the values at start (file + scenario)
        self._hooks: dict[str, Hook] = {}
        self.ids: dict[str, str] = param_ids(self.settable())

    def settable(self) -> list[str]:
        """Names of the ground-settable parameters, sorted (the MAVLink index order)."""
        return sorted(n for n, p in self.table.items() if p.ground_settable)

    def bind(self, owner: str, hook: Hook) -> None:
        names = [n for n, p in self.table.items() if p.owner == owner]
        if not names:
            raise ValueError(f"{owner}: declares no parameter")
        for n in names:
            self._hooks[n] = hook

    def check_bound(self) -> None:
        """Every ground-settable parameter has its owner's hook (call once, after wiring)."""
        missing = [n for n in self.settable() if n not in self._hooks]
        if missing:
            raise ValueError(f"ground-settable parameters without an owner's hook: {', '.join(missing)}")

    def set(self, name: str, value) -> float:
        """Validated ground set; ValueError (value and owner unchanged) when refused."""
        p = self.table.get(name)
        if p is None:
            raise ValueError(f"{name}: unknown parameter")
        if not p.ground_settable:
            raise ValueError(f"{name}: not settable in flight")
        v = p.check(value)
        old, self.values[name] = self.values[name], v      # an owner may read it in its hook
        try:
            self._hooks[name](name, v)
        except BaseException:
            self.values[name] = old
            raise
        return v

    def describe(self) -> list[dict]:
        """One row per parameter, for tables and machine-readable metadata: name, MAVLink
        id (ground-settable only), owner, unit, min, max (None for a word parameter),
        choices (a word parameter's words, else None), integer, default, description."""
        rows = []
        for name in sorted(self.table):
            p = self.table[name]
            words = bool(p.choices)
            rows.append({"name": name, "param_id": self.ids.get(name), "owner": p.owner, "unit": p.unit,
                         "min": None if words else p.lo, "max": None if words else p.hi,
                         "choices": list(p.choices) if words else None, "integer": p.integer,
                         "ground_settable": p.ground_settable, "default": self.defaults[name], "description": p.doc})
        return rows

    def markdown(self) -> str:
        """The parameter table (README "Flight-software parameters")."""
        def g(x) -> str:
            return "" if x is None else x if isinstance(x, str) else f"{x:g}"
        lines = ["| MAVLink id | parameter | owner | unit | min | max | default | description |",
                 "|---|---|---|---|---|---|---|---|"]
        for r in self.describe():
            pid = f"`{r['param_id']}`" if r["param_id"] else "(not settable)"
            unit = (r["unit"] if r["unit"] not in ("", "-") else "") + (" (integer)" if r["integer"] else "") \
                + (f"one of {', '.join(r['choices'])}" if r["choices"] else "")
            doc = r["description"].replace("|", "\\|")
            lines.append(f"| {pid} | `{r['name']}` | {r['owner']} | {unit.strip()} | {g(r['min'])} | {g(r['max'])} "
                         f"| {g(r['default'])} | {doc} |")
        return "\n".join(lines) + "\n"
