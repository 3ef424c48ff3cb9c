"""argparse types of the ``ellipsled`` commands (the harness's, the ground station's and the
viewer bridge's: here in common/ so that each tree can use them): a bad value is refused
with a message naming the option and its range, never passed on (argparse turns the
refusal into a usage error, exit status 2)."""
from __future__ import annotations

import argparse
import math

SEED_MAX = 2**63 - 1        # seeds are stored as int64 (campaign results)


def _int_in(s: str, lo: int, hi: int | None) -> int:
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer, got {s!r}") from None
    if v < lo or (hi is not None and v > hi):
        raise argparse.ArgumentTypeError(f"must be >= {lo}, got {v}" if hi is None
                                         else f"must be in [{lo}, {hi}], got {v}")
    return v


def int_range(lo: int, hi: int | None = None):
    """An integer in [lo, hi] (hi None: no upper bound)."""
    def parse(s: str) -> int:
        return _int_in(s, lo, hi)
    parse.__name__ = "integer"
    return parse


def float_range(lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False):
    """A finite number in [lo, hi] (``lo_open``/``hi_open``: the bound excluded)."""
    def parse(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number, got {s!r}") from None
        if not (math.isfinite(v) and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)):
            raise argparse.ArgumentTypeError(
                f"must be a finite number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}, got {s}")
        return v
    parse.__name__ = "number"
    return parse


def positive_int(s: str) -> int:
    return _int_in(s, 1, None)


def nonneg_int(s: str) -> int:
    return _int_in(s, 0, None)


def positive_float(s: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {s!r}") from None
    if not (v > 0 and v < float("inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {s}")
    return v


def choice_list(choices):
    """A comma-separated, non-empty list of names out of ``choices`` (a tuple, in the order given)."""
    def parse(s: str) -> tuple[str, ...]:
        names = tuple(x.strip() for x in s.split(",") if x.strip())
        bad = [x for x in names if x not in choices]
        if not names or bad:
            raise argparse.ArgumentTypeError(f"must be a comma-separated list of {', '.join(choices)}, got {s!r}")
        return names
    parse.__name__ = "list"
    return parse


# the options several commands share, with their ranges
seed = int_range(0, SEED_MAX)
# simulated seconds: an entry lasts minutes; the run's history must also fit the memory
# budget (history.budget_refusal, checked once the scenario's step is known)
MAX_DURATION_S = 86_400.0
duration_s = float_range(0.0, MAX_DURATION_S, lo_open=True)
timeout_s = float_range(0.0, 3600.0, lo_open=True)
# real time: simulated seconds per wall second (0.01: a 20-ms step every 2 s; 100: every 0.2 ms)
speed = float_range(0.01, 100.0)
# a release offset or a wait [us], within one second
offset_us = float_range(-1e6, 1e6)
wait_us = float_range(0.0, 1e6)
rt_priority = int_range(1, 99)
udp_port = int_range(0, 65535)              # 0: an ephemeral port
retries = int_range(0, 100)
