"""What the wait between two cycles does to the control task (docs/benchmarks.md, section ``wake``).

The control experiment of "the control task as fast in real time as in batch": one child
process under common/rt.py's hygiene (the jitter loop's: single-threaded numerics, SCHED_FIFO,
pinned, memory locked, GC out of the cycle) flies four flight softwares, each with its own
plant on the same scenario, through the FSW's own ``Topology``; each differs only in what
comes before its cycles:

- ``batch``: nothing -- cycles back to back, the plant stepped between them (``LockstepClock``,
  the batch runner's loop); the first ``BATCH_COLD`` of each turn, which follow the other
  flights' turns, are flown but not counted;
- ``spun``: a busy-wait of one control period (``RealTimeClock`` whose final spin is the whole
  period: the core kept busy);
- ``slept``: a sleep of one control period (``RealTimeClock``, the FSW's rehearsal off);
- ``rehearsed``: the real-time FSW's wait (``RealTimeClock.from_params``: the sleep, the
  rehearsal before the release, the final spin).

The four fly in turns of ``block`` cycles each, in an order rotated every round, so that
whatever the host does meanwhile (its slow spells last seconds: docs/decisions.md) meets
the four alike, and so that they fly the same stretch of the entry. The figure is the
executive's ``control`` task time of each cycle (the task the real-time SIL's rows time),
p50 / p99 / max per condition, and the ratios to ``batch``: ``slept`` over ``batch`` is what
the sleep costs on this host, ``spun`` whether keeping the core busy takes it away, and
``rehearsed`` what the FSW's wait gets back.

    python -m ellipsled.bench.wake [--quick]
"""
from __future__ import annotations

# Only the standard library at module level: the child pins the numeric thread pools
# (rt.single_threaded_numerics) before NumPy is imported.
import argparse

from common import argtypes

from .jitter import FAST_PERIOD_US, PERIOD_US, PRIORITY, _cpu, child_arguments, child_or_section, run_json_child
from .rows import NO_TARGET, Row, fmt, g, ratio, row

CONDITIONS = ("batch", "spun", "slept", "rehearsed")
RESULT_TAG = "WAKE-RESULT "
BATCH_COLD = 2          # cycles at the start of each batch turn not counted (see child)
# (key, control period [us], cycles per turn, rounds quick, rounds full): a turn is about
# half a second of flight at either rate
RATES = (("50hz", PERIOD_US, 25, 10, 40), ("200hz", FAST_PERIOD_US, 100, 4, 16))


def clock_for(condition: str, params: dict, period_ns: int, **kw):
    """The clock of a condition's flight (``kw``: RealTimeClock's injectable ``now_ns``,
    ``sleep_until``): ``batch`` a LockstepClock; ``spun`` a RealTimeClock whose final spin is
    the whole period (the release is spun to from the end of the last cycle, never slept to);
    ``slept`` and ``rehearsed`` the FSW's own (``RealTimeClock.from_params``: its final spin),
    the rehearsal being the Topology's, set up when ``executive.rehearse_us`` > 0."""
    from fsw.executive import LockstepClock, RealTimeClock
    if condition == "batch":
        return LockstepClock()
    if condition == "spun":
        return RealTimeClock(period_ns, spin_ns=period_ns - 1, **kw)
    if condition in ("slept", "rehearsed"):
        return RealTimeClock.from_params(params, period_ns, **kw)
    raise ValueError(f"wake: unknown condition {condition!r} (known: {', '.join(CONDITIONS)})")


def restart(clock, k0: int) -> None:
    """Release ``k0`` of a real-time ``clock`` one period from now, the next a period apart:
    the other flights' turns are neither missed releases nor waited out (``RealTimeClock.start``
    counts releases from its t0: the default t0 would put release k0 k0 periods away)."""
    clock.start(t0_ns=clock.now_ns() + (1 - k0) * clock.period_ns, k0=k0)


def child(period_us: int, block: int, rounds: int, priority: int | None, cpu: int | None,
          scenario: str = "nominal") -> dict:
    """The four conditions in this process; per condition the control task's p50 / p99 /
    max [us] over its cycles, and the count (plain JSON values)."""
    from common import rt
    rt.single_threaded_numerics()
    import gc

    import numpy as np

    from common.events import EventLog
    from ellipsled.node_reports import lp_split
    from ellipsled.sil.variant import prepare
    from fsw.flightsoftware import FlightSoftware
    from fsw.topology import Topology
    from sim.plant import Plant

    scn = prepare(scenario, dt_control_s=period_us * 1e-6)
    n_max = block * rounds + 8
    flights = {}
    for name in CONDITIONS:
        plant = Plant(scn, scn.seed)
        overrides = {"executive.rehearse_us": 0.0} if name in ("spun", "slept") else None
        fsw = FlightSoftware(scn, EventLog(), param_overrides=overrides)
        period_ns = int(round(fsw.dt_s * 1e9))
        clock = clock_for(name, fsw.params, period_ns)
        if name == "batch":
            topo = Topology(fsw, clock, history=n_max)
        else:
            topo = Topology(fsw, clock, frame_source=lambda p=plant: p.sensors, history=n_max)

            def plant_task(cyc, p=plant, t=topo):
                p.step(t.u)
            topo.add(1, "plant", plant_task)
        topo.warm_up(plant.sensors)
        flights[name] = (plant, fsw, topo, clock)

    lp = {name: np.zeros(n_max, dtype=bool) for name in CONDITIONS}   # the duty-cycle LP's cycles
    # the first cycles of a batch turn come after the others' turns, seconds of other work:
    # cold, not back to back -- flown, not counted
    counted = {name: np.ones(n_max, dtype=bool) for name in CONDITIONS}

    def turn(name: str) -> None:
        plant, fsw, topo, clock = flights[name]
        k, modulated = topo.executive.cycles, lp[name]    # the cycles it has flown so far
        if name == "batch":
            frame = plant.sensors
            counted[name][k:k + BATCH_COLD] = False
            for i in range(k, k + block):
                topo.tick(frame)
                modulated[i] = fsw.dutycycle.modulated
                frame = plant.step(topo.u)
        else:
            restart(clock, k)
            for i in range(k, k + block):
                topo.tick()
                modulated[i] = fsw.dutycycle.modulated

    rt_rep = rt.apply(cpus=[cpu] if cpu is not None else None, priority=priority)
    rt.gc_out_of_cycle()
    try:
        for r in range(rounds):
            order = CONDITIONS[r % len(CONDITIONS):] + CONDITIONS[:r % len(CONDITIONS)]
            for name in order:
                turn(name)
                gc.collect(0)            # between turns, outside every measured cycle
    finally:
        rt.restore()
        for plant, fsw, topo, clock in flights.values():
            topo.close()
            fsw.close()
    res = {"period_us": period_us, "block": block, "rounds": rounds, "priority": priority, "cpu": cpu,
           "sched_fifo": bool(rt_rep.get("sched_fifo"))}
    for name, (plant, fsw, topo, clock) in flights.items():
        st = topo.executive.stats
        m = min(st.n, st.capacity)
        keep = counted[name][:m]
        us = st.task_ns[:m, st.task_names.index("control")][keep] * 1e-3
        res[name] = {"cycles": int(us.size), "p50_us": float(np.percentile(us, 50)),
                     "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max()),
                     **lp_split(us, lp[name][:m][keep]),
                     "rehearsals": int(getattr(clock, "rehearsals", 0)),
                     "missed_releases": int(clock.missed)}
    return res


def run_child(period_us: int, block: int, rounds: int, priority: int | None = PRIORITY,
              cpu: int | None = None) -> dict:
    seconds = period_us * 1e-6 * block * rounds * (len(CONDITIONS) - 1)
    return run_json_child("ellipsled.bench.wake", ["--period-us", str(period_us), "--block", str(block),
                                                   "--rounds", str(rounds),
                                                   "--priority", str(priority or 0),
                                                   "--cpu", str(-1 if cpu is None else cpu)],
                          RESULT_TAG, seconds + 120.0)


def run(quick: bool) -> dict:
    """At 50 and at 200 Hz: the control task after each wait, on the jitter loop's CPU."""
    cpu = _cpu()
    res = {"figure": "control task [us] after the wait between cycles, four flights in one process "
                     "taking turns: back to back, after a spin of one period, after a sleep of one period, "
                     "after the real-time FSW's wait (sleep + rehearsal)",
           "conditions": list(CONDITIONS), "cpu": cpu}
    for key, period_us, block, rq, rf in RATES:
        try:
            res[key] = run_child(period_us, block, rq if quick else rf, PRIORITY, cpu)
        except Exception as e:
            res[key] = {"error": f"{type(e).__name__}: {e}"}
    return res


LABELS = {"spun": "after a spin of one period (the core kept busy)",
          "slept": "after a sleep of one period (no rehearsal)",
          "rehearsed": "after the real-time FSW's wait (sleep, rehearsal, final spin)"}


def rows(res: dict) -> list[Row]:
    R = []
    for key, period_us, *_ in RATES:
        w = g(res, "wake", key) or {}
        b = w.get("batch") or {}
        if not b:
            continue
        for name in ("spun", "slept", "rehearsed"):
            c = w.get(name) or {}
            R.append(row(f"control task at {1e6 / period_us:g} Hz {LABELS[name]}, in process, p50 / p99 [us] "
                         f"(p99 without the duty-cycle LP's cycles; {fmt(c.get('cycles'))} cycles)",
                         f"{fmt(c.get('p50_us'))} / {fmt(c.get('p99_us'))} ({fmt(c.get('p99_without_lp'))})",
                         f"back to back, taking turns with it: {fmt(b.get('p50_us'))} / {fmt(b.get('p99_us'))} "
                         f"({fmt(b.get('p99_without_lp'))})",
                         f"{fmt(ratio(c.get('p50_us'), b.get('p50_us')))}x / "
                         f"{fmt(ratio(c.get('p99_us'), b.get('p99_us')))}x "
                         f"({fmt(ratio(c.get('p99_without_lp'), b.get('p99_without_lp')))}x)", "—", NO_TARGET))
    return R


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--period-us", type=argtypes.int_range(1000, 100_000), default=None,
                    help="run one child at this control period and print its figures")
    ap.add_argument("--block", type=argtypes.int_range(1, 100_000), default=25, help="(child) cycles per turn")
    ap.add_argument("--rounds", type=argtypes.int_range(1, 100_000), default=4, help="(child) turns of each condition")
    child_arguments(ap)
    a = ap.parse_args(argv)
    return child_or_section(a, a.period_us is not None, child, RESULT_TAG, run,
                            period_us=a.period_us, block=a.block, rounds=a.rounds)


if __name__ == "__main__":
    raise SystemExit(main())
