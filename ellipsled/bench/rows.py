"""Rows of the benchmark table: (figure, measured, baseline, ratio, target, verdict).

Each section module (ellipsled/bench/<name>.py) builds its own rows from the suite's
results with these helpers, against the targets it declares next to its measurement, so a
target is written once. A figure that is missing shows "n/m" (its reason is in the JSON).
"""
from __future__ import annotations

Row = tuple[str, str, str, str, str, str]
NO_TARGET = object()


def g(d: dict | None, *path):
    """d[path[0]][path[1]]..., or None where the path ends early."""
    for p in path:
        if not isinstance(d, dict):
            return None
        d = d.get(p)
    return d


def fmt(v, unit: str = "") -> str:
    if v is None:
        return "n/m"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return f"{v}{unit}"
    if isinstance(v, float):
        a = abs(v)
        s = f"{v:.0f}" if a >= 1000 else f"{v:.1f}" if a >= 10 else f"{v:.2f}" if a >= 0.1 else f"{v:.3g}"
        return s + unit
    return str(v)


def ratio(a, b):
    return (a / b) if isinstance(a, (int, float)) and isinstance(b, (int, float)) and b else None


def verdict(ok) -> str:
    if ok is NO_TARGET:
        return ""
    return "n/m" if ok is None else ("pass" if ok else "**FAIL**")


def le(a, b):
    return None if a is None or b is None else a <= b


def ge(a, b):
    return None if a is None or b is None else a >= b


def all_(*xs):
    """True if every check passed, False if one failed, None (not measured) otherwise."""
    if any(x is None for x in xs):
        return None if not any(x is False for x in xs) else False
    return all(xs)


def row(fig: str, meas: str, base: str, rat: str, target: str, ok) -> Row:
    return (fig, meas, base, rat, target, verdict(ok))
