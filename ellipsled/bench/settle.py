"""The host's state before each real-time section: a settle phase against the run's own baseline.

Compute-heavy sections (allocator, batch, ...) can leave a shared virtual machine slower for
a while (host throttling of the vCPUs after sustained bursts, cache and frequency state): an
idle real-time loop measured right after them computed about twice as slow as the same loop
alone, and its release jitter followed. So before each real-time section the suite waits
until a short probe of the machine's speed, taken the way an idle real-time loop meets the
CPU — a fixed piece of Python work right after a sleep of most of a 50-Hz period — is back
within ``TOLERANCE`` of the same probe at the start of the run, ``SETTLED_PROBES`` probes
running; the wait is bounded (``MAX_WAIT_S``) and what it found is written beside the
section's figures (``settle``): the section is measured in a known host state, or says it
was not.
"""
from __future__ import annotations

import statistics
import time
from collections.abc import Callable

from .rows import NO_TARGET, Row, fmt, row

SLEEP_S = 0.019                  # an idle 50-Hz loop's sleep between its cycles
SAMPLES = 12                     # sleeps and timed pieces of work in one probe
TOLERANCE = 1.25                 # settled: the probe within this factor of the baseline ...
SETTLED_PROBES = 2               # ... this many probes running
MAX_WAIT_S = {True: 30.0, False: 90.0}       # quick / full: the longest wait before a section
REALTIME_SECTIONS = ("groundlink", "latency", "jitter", "wake", "sil_realtime", "sil_router", "flood")


class Work:
    """The probe's fixed piece of work: copies of a SENSORS record and float arithmetic
    (what the FSW's Python paths do), some tens of us here."""

    def __init__(self) -> None:
        from interfaces import records
        self.rec = records.new(records.SENSORS)

    def __call__(self) -> None:
        x = 0.0
        for i in range(40):
            bytes(self.rec)
            x += i * 0.5


def probe_us(samples: int = SAMPLES, sleep: Callable[[float], None] = time.sleep,
             clock_ns: Callable[[], int] = time.perf_counter_ns, piece: Callable[[], None] | None = None) -> float:
    """p50 [us] of ``piece`` (default: Work) timed right after each of ``samples`` sleeps of SLEEP_S."""
    piece = piece or Work()
    piece()                                  # first call: imports and allocations
    t = []
    for _ in range(samples):
        sleep(SLEEP_S)
        t0 = clock_ns()
        piece()
        t.append(clock_ns() - t0)
    return statistics.median(t) * 1e-3


def cpu_ticks() -> tuple[int, int] | None:
    """(all, stolen) CPU time of the machine so far [clock ticks], from /proc/stat's first
    line (steal: time the host ran something else while a vCPU wanted to run); None where
    there is none."""
    try:
        with open("/proc/stat") as f:
            v = [int(x) for x in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    return (sum(v[:8]), v[7]) if len(v) >= 8 else None


def steal_share(before: tuple[int, int] | None, after: tuple[int, int] | None) -> float | None:
    """The share of the machine's CPU time the host stole between two ``cpu_ticks``."""
    if before is None or after is None or after[0] <= before[0]:
        return None
    return (after[1] - before[1]) / (after[0] - before[0])


def baseline(probe: Callable[[], float] = probe_us, n: int = 3) -> dict:
    """The run's reference: the median of ``n`` probes at its start."""
    got = [probe() for _ in range(n)]
    return {"probe_us": statistics.median(got), "probes_us": got}


def settle(base_us: float, max_wait_s: float, probe: Callable[[], float] = probe_us,
           clock: Callable[[], float] = time.monotonic) -> dict:
    """Probe until SETTLED_PROBES probes running are within TOLERANCE of ``base_us``, or
    ``max_wait_s`` has passed: how long it waited, whether it settled, each probe [us], the
    host's steal share meanwhile."""
    t0, ticks0 = clock(), cpu_ticks()
    got, run = [], 0
    while True:
        p = probe()
        got.append(p)
        run = run + 1 if p <= TOLERANCE * base_us else 0
        waited = clock() - t0
        if run >= SETTLED_PROBES or waited >= max_wait_s:
            return {"settled": run >= SETTLED_PROBES, "waited_s": waited, "baseline_us": base_us,
                    "last_over_baseline": p / base_us, "probes_us": got, "tolerance": TOLERANCE,
                    "max_wait_s": max_wait_s, "steal_share": steal_share(ticks0, cpu_ticks())}


def rows(res: dict) -> list[Row]:
    """One row: the real-time sections' settle phases of this run."""
    st = {name: (res.get(name) or {}).get("settle") for name in REALTIME_SECTIONS}
    st = {k: v for k, v in st.items() if v}
    if not st:
        return []
    unsettled = [k for k, v in st.items() if not v.get("settled")]
    worst = max(v.get("last_over_baseline", 0.0) for v in st.values())
    return [row("host state before the real-time sections: probe after a 19-ms sleep, over the run's start "
                "(worst section); longest wait [s]",
                f"{fmt(worst)}x; {fmt(max(v.get('waited_s', 0.0) for v in st.values()))}",
                f"start of the run {fmt((res.get('settle_baseline') or {}).get('probe_us'))} us",
                "not settled: " + (", ".join(unsettled) if unsettled else "none"),
                f"<= {TOLERANCE:g}x before each", NO_TARGET)]
