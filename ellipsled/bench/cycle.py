"""FSW control-cycle benchmark (docs/benchmarks.md): compute time of the rate-group
tasks (RG1 control, RG2 fdir_slow) and of a whole cycle, p50/p99/max,
over a full nominal entry flown in lockstep — against the control period.

The loop is the batch runner's (ellipsled/batch.py: Plant -> Topology.tick -> plant.step),
with an executive ring large enough to keep every cycle, so the per-task percentiles cover
the whole entry. Two garbage-collection regimes are measured in the same invocation:

- ``gc_out_of_cycle`` (the real-time FSW process, common/rt.py): collect + freeze after the
  warm-up, automatic GC disabled, young generation collected between cycles (the slack);
- ``gc_default``: automatic GC on, as the batch runner runs.

The headline figures are the first (that is how the cycle runs in real time).

The real-time SIL's baseline (the control task as fast in real time as in batch):
the control task over the same simulated span the real-time SIL flies (the first
``sil.realtime_seconds`` of the nominal entry), at 50 Hz from the first entry and at 200 Hz from
one more flight over that span. The duty-cycle LP's cycles (a HiGHS solve each, the control
task's dearest) fall in the nominal entry's first second: a larger share of the SIL's short
span than of a whole entry, so the whole entry's p99 is not taken over the cycles the SIL's is.
Both are given, and the p99 without the LP's cycles.

    python -m ellipsled.bench.cycle [--quick]
"""
from __future__ import annotations

import gc
import math
import sys
import time

import numpy as np

from common.model import load_scenario
from common.events import EventLog
from ellipsled.node_reports import lp_split
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware
from fsw.topology import Topology
from sim.plant import Plant

from .rows import NO_TARGET, Row, fmt, ratio, row, speed

TARGETS = {"compute_p99_us_max": 1000.0}


def _pct(a: np.ndarray) -> dict:
    if a.size == 0:
        return {"p50_us": None, "p99_us": None, "max_us": None, "runs": 0}
    return {"p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
            "max_us": float(a.max()), "runs": int(a.size)}


def span_figures(control_us: np.ndarray, lp_cycle: np.ndarray, span_s: float, dt_s: float) -> dict:
    """The control task [us] over the first ``span_s`` of simulated time: p50 / p99 / max / runs
    over every cycle, the duty-cycle LP's cycles (``lp_cycles``) and the p99 without them."""
    n = int(round(span_s / dt_s))
    c, lp = control_us[:n], lp_cycle[:n]
    split = lp_split(c, lp)
    return {**_pct(c), "span_s": float(span_s), "lp_cycles": split["lp_cycles"],
            "p99_without_lp_us": split["p99_without_lp"]}


def fly(scenario: str = "nominal", duration_s: float | None = None, gc_mode: str = "out_of_cycle",
        dt_control_s: float | None = None, span_s: float | None = None) -> dict:
    """One entry in lockstep; per-task and whole-cycle compute-time statistics [us]. At control
    period ``dt_control_s`` (None: the scenario's); with ``span_s``, the control task over the
    first ``span_s`` of simulated time as well (``control_span``: span_figures)."""
    if gc_mode not in ("out_of_cycle", "default"):
        raise ValueError(f"cycle.fly: gc_mode must be 'out_of_cycle' or 'default', got {gc_mode!r}")
    scn = load_scenario(scenario)
    if dt_control_s is not None:
        from ellipsled.sil.variant import prepare
        scn = prepare(scn, dt_control_s=dt_control_s)
    if duration_s is not None:
        scn = scn.with_(max_duration_s=float(duration_s))
    n_max = int(math.ceil(scn.max_duration_s / scn.dt_control_s)) + 2
    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog())
    topo = Topology(fsw, LockstepClock(), history=n_max)
    period_us = fsw.dt_s * 1e6
    alloc_us = np.empty(n_max)
    plant_us = np.empty(n_max)
    lp_cycle = np.zeros(n_max, dtype=bool)
    gc_was = gc.isenabled()
    gen0 = 0
    clock = time.perf_counter_ns
    frame = plant.sensors
    n = 0
    reason = ""
    if gc_mode == "out_of_cycle":
        gc.collect()
        gc.freeze()
        gc.disable()
    else:
        gc.enable()
    wall0 = time.perf_counter()
    try:
        while n < n_max:
            topo.tick(frame)
            alloc_us[n] = fsw.alloc_ns * 1e-3
            lp_cycle[n] = fsw.dutycycle.modulated
            n += 1
            done, reason = plant.done()
            if done:
                break
            t0 = clock()
            frame = plant.step(topo.u)
            plant_us[n - 1] = (clock() - t0) * 1e-3
            if gc_mode == "out_of_cycle" and gc.get_count()[0] >= 200:
                gc.collect(0)            # in the slack, outside the measured cycle
                gen0 += 1
    finally:
        wall = time.perf_counter() - wall0
        if gc_mode == "out_of_cycle":
            gc.unfreeze()
        if gc_was:
            gc.enable()
        else:
            gc.disable()
    st = topo.executive.stats
    m = min(st.n, st.capacity)
    compute = st.compute_ns[:m] * 1e-3
    tasks = {}
    for name in st.task_names:
        col = st.task_ns[:m, st.task_names.index(name)]
        tasks[name] = _pct(col[col >= 0] * 1e-3)
    worst = int(np.argmax(compute)) if m else -1
    out = {
        "gc_mode": gc_mode, "cycles": int(m), "end_reason": reason, "t_end_s": float(fsw.t_s),
        "wall_s": wall, "period_us": period_us,
        "compute": _pct(compute), "tasks": tasks,
        "allocator_in_control": _pct(alloc_us[:n]),
        "plant_step": _pct(plant_us[: max(n - 1, 0)]),
        "slips": int(topo.executive.slips),
        "gen0_collections_in_slack": gen0,
        "worst_cycle_k": int(st.k[worst]) if m else None,
        "cycles_over_1ms": int(np.sum(compute > 1000.0)),
    }
    if span_s is not None:
        col = st.task_ns[:m, st.task_names.index("control")] * 1e-3
        out["control_span"] = span_figures(col, lp_cycle[:m], span_s, scn.dt_control_s)
    return out


def run(quick: bool) -> dict:
    """Headline: whole-cycle compute p50/p99/max [us] with GC out of the cycle, per task,
    against the 20 ms period; the same with automatic GC in a second entry."""
    from .sil import FAST_DT_S, realtime_seconds
    dur = 120.0 if quick else None
    span = realtime_seconds(quick)
    fly("nominal", 5.0)                         # warm-up: numba cache load, first calls
    rt_run = fly("nominal", dur, "out_of_cycle", span_s=span)
    gc_run = fly("nominal", dur, "default")
    fast = fly("nominal", span, "out_of_cycle", dt_control_s=FAST_DT_S, span_s=span)
    c = rt_run["compute"]
    res = {
        "figure": "FSW control-cycle compute time [us] over a nominal entry (lockstep)",
        "scenario": "nominal", "duration_s": rt_run["t_end_s"], "cycles": rt_run["cycles"],
        "compute_p50_us": c["p50_us"], "compute_p99_us": c["p99_us"], "compute_max_us": c["max_us"],
        "baseline_period_us": rt_run["period_us"],
        "compute_p99_fraction_of_period": (c["p99_us"] / rt_run["period_us"]) if c["p99_us"] else None,
        "gc_disabled_in_cycle": True,
        "tasks": rt_run["tasks"],
        "allocator_in_control": rt_run["allocator_in_control"],
        "plant_step": rt_run["plant_step"],
        "cycles_over_1ms": rt_run["cycles_over_1ms"],
        "worst_cycle_k": rt_run["worst_cycle_k"],
        "gen0_collections_in_slack": rt_run["gen0_collections_in_slack"],
        "with_automatic_gc": {k: gc_run[k] for k in ("compute", "tasks", "cycles_over_1ms", "worst_cycle_k")},
        # the real-time SIL's baseline: the control task over the span it flies, at its two rates
        "control_span_50hz": rt_run["control_span"], "control_span_200hz": fast["control_span"],
        "targets": dict(TARGETS),
    }
    for name, t in rt_run["tasks"].items():
        for q in ("p50_us", "p99_us", "max_us"):
            res[f"{name}_{q}"] = t[q]
    res["pass"] = bool(c["p99_us"] is not None and c["p99_us"] <= TARGETS["compute_p99_us_max"])
    return res


def rows(res: dict) -> list[Row]:
    c = res.get("cycle") or {}
    if not c:
        return []
    per = c.get("baseline_period_us")
    R = [row("control cycle compute p50 / p99 / max [us] (all RG tasks)",
             f"{fmt(c.get('compute_p50_us'))} / {fmt(c.get('compute_p99_us'))} / {fmt(c.get('compute_max_us'))}",
             f"period {fmt(per)}", f"{fmt(ratio(c.get('compute_p99_us'), per))} of period (p99)",
             f"p99 <= {TARGETS['compute_p99_us_max']:g} us", NO_TARGET,
                absolute=(c.get("compute_p99_us"), TARGETS["compute_p99_us_max"], "<="), machine=speed(res))]
    for t, s in (c.get("tasks") or {}).items():
        R.append(row(f"  task {t} p50 / p99 / max [us]",
                     f"{fmt(s.get('p50_us'))} / {fmt(s.get('p99_us'))} / {fmt(s.get('max_us'))}",
                     f"period {fmt(per)}", "", "", NO_TARGET))
    ac = c.get("allocator_in_control") or {}
    if ac:
        R.append(row("  allocator inside control p50 / p99 [us]", f"{fmt(ac.get('p50_us'))} / {fmt(ac.get('p99_us'))}",
                     "", "", "", NO_TARGET))
    return R


if __name__ == "__main__":
    import json
    print(json.dumps(run("--quick" in sys.argv), indent=2))
