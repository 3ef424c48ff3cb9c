"""Rows of the benchmark table: (figure, measured, baseline, ratio, target, verdict).

Each section module (ellipsled/bench/<name>.py) builds its own rows from the suite's
results with these helpers, against the targets it declares next to its measurement, so a
target is written once. A figure that is missing shows "n/m" (its reason is in the JSON).

An absolute target (microseconds, a real-time factor) is judged twice: on the figure as
measured, and on the figure scaled to the speed of the reference machine (docs/benchmarks.md) by
the same run's machine-speed baseline (``machine.speed_factor``: bytes() of a SENSORS
record, see ellipsled/bench/suite.py). The verdict names which failed: on a slow or busy
machine "FAIL (absolute)" alone is the machine; "machine-scaled" too is the code.
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


def speed(res: dict):
    """This run's machine-speed factor (> 1: slower than the reference machine)."""
    return g(res, "machine", "speed_factor")


def split_verdict(ok, abs_ok, scaled_ok) -> str:
    """A verdict naming what failed: the row's other targets (``ok``, e.g. a same-run ratio),
    its absolute target, or the absolute target at reference machine speed."""
    if ok is NO_TARGET:
        ok = True
    if ok is None or abs_ok is None:
        return "n/m"
    failed = [name for name, x in (("ratio", ok), ("absolute", abs_ok), ("machine-scaled", scaled_ok))
              if x is False]
    if failed:
        return "**FAIL** (" + ", ".join(failed) + ")"
    return "pass" if scaled_ok is not None else "pass (machine-scaled n/m)"


def row(fig: str, meas: str, base: str, rat: str, target: str, ok, *, absolute=None, machine=None) -> Row:
    """``ok``: the verdict of the row's targets but its absolute one; ``absolute``: (value,
    limit, "<=" or ">=") of an absolute target, judged also at reference speed with
    ``machine`` (the speed factor, ``speed(res)``)."""
    if absolute is None:
        return (fig, meas, base, rat, target, verdict(ok))
    value, limit, op = absolute
    cmp = ge if op == ">=" else le
    scaled = None
    if isinstance(value, (int, float)) and isinstance(machine, (int, float)) and machine > 0:
        scaled = value * machine if op == ">=" else value / machine
    rat = (rat + "; " if rat else "") + (f"at reference speed {fmt(scaled)} (machine x{fmt(machine)})"
                                         if scaled is not None else "machine speed n/m")
    return (fig, meas, base, rat, target, split_verdict(ok, cmp(value, limit), cmp(scaled, limit)))
