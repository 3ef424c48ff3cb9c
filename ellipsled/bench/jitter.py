"""Release jitter of the real-time loop at 50 and 200 Hz (docs/benchmarks.md) next to cyclictest.

The loop: fsw.executive.RealTimeClock + the FSW topology's rate groups (RG1 control,
RG2 fdir_slow) fed by the plant in the same process (an extra RG1 task
steps sim.plant.Plant with the jet command, so the control task always has a fresh frame),
under common/rt.py's hygiene: single-threaded numerics before NumPy is imported, warm-up,
rt.apply (SCHED_FIFO, CPU affinity, mlockall), GC out of the cycle (young generation
collected in the slack). It runs in a child interpreter (``--child``) so that neither the
real-time policy nor the locked memory leaks into the rest of the benchmark.

Jitter is the executive's: cycle start minus its absolute release on the monotonic clock;
a slip is a cycle that ends after its deadline (one period), a missed release a whole
period lost. The floor of the operating system comes from ``cyclictest -m -p <prio> -i
<period> -l <loops> -a <cpu> -q -h <range>`` run right after at the loop's own period, under
the same load; its p50/p99 come from its histogram (1 us bins). Both run idle and with
``stress-ng --cpu 2`` in the background, at the scenario's 50 Hz and again at 200 Hz (the
control period 5 ms, ``--dt-control 0.005``: rate headroom). Missing tools are installed
(apt-get, Debian packages rt-tests and stress-ng) when possible, else the figures are null
with the reason.

    python -m ellipsled.bench.jitter [--quick]
"""
from __future__ import annotations

# Only the standard library at module level: the child must pin the numeric thread pools
# (rt.single_threaded_numerics) before NumPy is imported.
import argparse
import contextlib
import json
import os
import shutil
import subprocess
import sys
import time
from typing import Callable

from common import argtypes
from ellipsled.procs import stop_process

from .rows import NO_TARGET, Row, fmt, g, le, ratio, row, speed

PERIOD_US = 20_000
FAST_PERIOD_US = 5_000          # rate headroom: the same loop at 200 Hz
PRIORITY = 80
RESULT_TAG = "JITTER-RESULT "
TARGETS = {"idle_p99_over_cyclictest_max": 2.0, "load_p99_over_cyclictest_max": 3.0,
           "idle_max_us": 1000.0, "slips": 0,
           # rate headroom at 200 Hz (docs/benchmarks.md): p99 against cyclictest at 5 ms, no
           # absolute max (the host's own wake-ups there reach several ms), and 0 slips of the
           # loop's own work (the host's late wake-ups counted beside them)
           "fast_p99_over_cyclictest_max": 3.0, "fast_own_slips": 0}


# --------------------------------------------------------------------------- system tools
def ensure_tools(tools=("cyclictest", "stress-ng"), packages=("rt-tests", "stress-ng")) -> tuple[bool, str]:
    """(available, reason). Installs the Debian packages when a tool is missing and we are
    root with apt-get; never raises."""
    missing = [t for t in tools if shutil.which(t) is None]
    if not missing:
        return True, ""
    if os.geteuid() != 0 or shutil.which("apt-get") is None:
        return False, f"{', '.join(missing)} not installed and cannot install (not root or no apt-get)"
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    try:
        subprocess.run(["apt-get", "update", "-qq"], env=env, capture_output=True, timeout=300)
        r = subprocess.run(["apt-get", "install", "-y", "-qq", *packages], env=env, capture_output=True,
                           text=True, timeout=600)
    except (OSError, subprocess.TimeoutExpired) as e:
        return False, f"installing {' '.join(packages)} failed: {type(e).__name__}: {e}"
    missing = [t for t in tools if shutil.which(t) is None]
    if missing:
        return False, f"{', '.join(missing)} still missing after apt-get install: {r.stderr.strip()[-200:]}"
    return True, ""


@contextlib.contextmanager
def background_load(cpus: int = 2, timeout_s: float = 600.0):
    """``stress-ng --cpu <cpus>`` for the duration of the block (started and ended by pid,
    with its own --timeout as a safety net). Raises RuntimeError when it cannot run."""
    if shutil.which("stress-ng") is None:
        raise RuntimeError("stress-ng not installed")
    p = subprocess.Popen(["stress-ng", "--cpu", str(cpus), "--timeout", f"{int(timeout_s)}s", "--quiet"],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        time.sleep(1.0)                     # let the hogs start
        if p.poll() is not None:
            raise RuntimeError(f"stress-ng exited at once (code {p.returncode})")
        yield p
    finally:
        stop_process(p, 5.0, group=True)


# --------------------------------------------------------------------------- cyclictest
def parse_cyclictest(text: str) -> dict:
    """Histogram (-h) output of one thread -> {n, p50_us, p99_us, avg_us, max_us, min_us,
    overflows}. p50/p99 from the 1-us bins; None when they fall into the overflow."""
    bins: list[tuple[int, int]] = []
    summary: dict[str, int] = {}
    for line in text.splitlines():
        line = line.strip()
        if not line:
            continue
        if line.startswith("#"):
            if ":" in line:
                key, _, val = line[1:].partition(":")
                parts = val.split()
                if parts and parts[0].lstrip("-").isdigit():
                    summary[key.strip()] = int(parts[0])
            continue
        parts = line.split()
        if len(parts) >= 2 and parts[0].isdigit() and parts[1].isdigit():
            bins.append((int(parts[0]), int(parts[1])))
    overflows = summary.get("Histogram Overflows", 0)
    n = sum(c for _, c in bins) + overflows
    if n == 0:
        raise ValueError("cyclictest: no histogram samples in its output")

    def q(frac):
        need = frac * n
        acc = 0
        for b, c in bins:
            acc += c
            if acc >= need:
                return float(b)
        return None                          # in the overflow
    return {"n": n, "p50_us": q(0.50), "p99_us": q(0.99),
            "avg_us": float(summary["Avg Latencies"]) if "Avg Latencies" in summary else None,
            "max_us": float(summary["Max Latencies"]) if "Max Latencies" in summary else None,
            "min_us": float(summary["Min Latencies"]) if "Min Latencies" in summary else None,
            "overflows": overflows}


def cyclictest(loops: int, priority: int = PRIORITY, cpu: int | None = None,
               interval_us: int = PERIOD_US, hist_us: int = PERIOD_US) -> dict:
    cmd = ["cyclictest", "-m", "-p", str(priority), "-i", str(interval_us), "-l", str(loops), "-q",
           "-h", str(hist_us)]
    if cpu is not None:
        cmd += ["-a", str(cpu)]
    timeout = loops * interval_us * 1e-6 + 60.0
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    if r.returncode != 0:
        raise RuntimeError(f"cyclictest exit {r.returncode}: {r.stderr.strip()[-300:]}")
    out = parse_cyclictest(r.stdout)
    out["command"] = " ".join(cmd)
    return out


# --------------------------------------------------------------------------- the loop (child)
def _proc_status(field: str) -> int:
    """An integer field of /proc/self/status (e.g. "VmRSS" [kB], "Threads"); -1 if absent."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return -1


def _rss_kb() -> int:
    return _proc_status("VmRSS")


def _threads() -> int:
    return _proc_status("Threads")


def child(seconds: float, priority: int | None, cpu: int | None, scenario: str = "nominal",
          period_us: int = PERIOD_US) -> dict:
    """The real-time loop in this process at control period ``period_us``; returns its
    statistics (plain JSON values)."""
    from common import rt
    threads_rep = rt.single_threaded_numerics()
    import gc

    import numpy as np

    from common.events import EventLog
    from ellipsled.sil.variant import prepare
    from fsw.executive import RealTimeClock
    from fsw.flightsoftware import FlightSoftware
    from fsw.topology import Topology
    from sim.plant import Plant

    scn = prepare(scenario, dt_control_s=period_us * 1e-6)
    # warm-up on a throw-away pair: numba cache loads, first calls, allocator tables
    wp, wf = Plant(scn, scn.seed), FlightSoftware(scn, EventLog())
    fr = wp.sensors
    for _ in range(100):
        fr = wp.step(wf.control_step(fr))

    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog())
    period_ns = int(round(fsw.dt_s * 1e9))
    n_cycles = int(round(seconds * 1e9 / period_ns))
    clock = RealTimeClock.from_params(fsw.params, period_ns)
    topo = Topology(fsw, clock, frame_source=lambda: plant.sensors, history=n_cycles + 8)
    topo.warm_up(plant.sensors)        # as the SIL's FSW does: the rehearsal's first call too
    state = {"done": False, "reason": ""}

    def plant_task(cyc):
        if not state["done"]:
            plant.step(topo.u)
            state["done"], state["reason"] = plant.done()
    topo.add(1, "plant", plant_task)

    numba_threads = None
    try:
        import numba
        numba_threads = int(numba.get_num_threads())
    except Exception:
        pass
    rt_rep = rt.apply(cpus=[cpu] if cpu is not None else None, priority=priority)
    gc_rep = rt.gc_out_of_cycle()
    hook = rt.collect_in_slack()
    rss0 = _rss_kb()
    ex = topo.executive
    try:
        clock.start()
        ran = ex.run(n_cycles, should_stop=lambda: state["done"], on_slack=hook)
        rss1 = _rss_kb()
        gc_enabled_in_loop = gc.isenabled()
    finally:
        rt.restore()
        topo.close()
        fsw.close()
    st = ex.stats
    m = min(st.n, st.capacity)
    jit = st.jitter_ns[:m] * 1e-3
    comp = st.compute_ns[:m] * 1e-3

    def pct(a):
        return {"p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
                "max_us": float(a.max())} if a.size else {"p50_us": None, "p99_us": None, "max_us": None}
    tasks = {}
    for name in st.task_names:
        col = st.task_ns[:m, st.task_names.index(name)]
        tasks[name] = pct(col[col >= 0] * 1e-3)
    j, c = pct(jit), pct(comp)
    return {
        "cycles": int(ran), "seconds": ran * period_ns * 1e-9, "period_us": period_ns * 1e-3,
        "spin_us": clock.spin_ns * 1e-3, "priority": priority, "cpu": cpu,
        "p50_us": j["p50_us"], "p99_us": j["p99_us"], "max_us": j["max_us"],
        "slips": int(ex.slips), "missed_releases": int(clock.missed),
        # each slip judged from the executive's evidence (fsw.executive.slip_is_own): the host's
        # when a late wake-up or preemption covers its lateness, else the loop's own
        "host_slips": int(ex.host_slips), "own_slips": int(ex.slips - ex.host_slips),
        "late_releases": dict(ex.late_releases), "late_records": ex.late_records[:16],
        "slip_records": ex.slip_records[:16],
        "compute_p50_us": c["p50_us"], "compute_p99_us": c["p99_us"], "compute_max_us": c["max_us"],
        "tasks": tasks, "plant_end": state["reason"] if state["done"] else None,
        "rt": rt_rep, "gc": {**gc_rep, "enabled_in_loop": gc_enabled_in_loop,
                             "gen0_collections_in_slack": hook.collections},
        "threads": {"process_threads": _threads(), "numba_threads": numba_threads,
                    "env": threads_rep["env"], "numpy_imported_first": threads_rep["numpy_was_imported"],
                    "messages": threads_rep["messages"]},
        "rss_kb_start": rss0, "rss_kb_end": rss1, "rss_growth_kb": rss1 - rss0,
    }


def run_child(seconds: float, priority: int | None = PRIORITY, cpu: int | None = 1,
              period_us: int = PERIOD_US) -> dict:
    return run_json_child("ellipsled.bench.jitter",
                          ["--child", "--seconds", str(seconds), "--priority", str(priority if priority is not None else 0),
                           "--cpu", str(cpu if cpu is not None else -1), "--period-us", str(period_us)],
                          RESULT_TAG, seconds + 120.0)


def run_json_child(module: str, args: list[str], tag: str, timeout_s: float) -> dict:
    """``python -m module *args`` in its own session (killed with its group on timeout): the
    JSON on its output line that starts with ``tag``. The real-time loops of the benchmark run
    so, that neither their scheduling policy nor their locked memory outlives them."""
    p = subprocess.Popen([sys.executable, "-m", module, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        stop_process(p, 5.0, group=True)
        raise RuntimeError(f"real-time loop child timed out after {timeout_s:.0f} s")
    for line in out.splitlines():
        if line.startswith(tag):
            return json.loads(line[len(tag):])
    raise RuntimeError(f"real-time loop child failed (exit {p.returncode}): {err.strip()[-400:]}")


# --------------------------------------------------------------------------- benchmark
def _cpu() -> int | None:
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except OSError:
        return None
    return cpus[-1] if cpus else None


def measure(seconds: float, cpu: int | None, tools_ok: bool, tools_reason: str,
            period_us: int = PERIOD_US) -> dict:
    """One regime (idle or under load, set by the caller): the loop, then cyclictest, both
    at ``period_us``."""
    res: dict = {"period_us": period_us}
    try:
        loop = run_child(seconds, PRIORITY, cpu, period_us)
        for k in ("p50_us", "p99_us", "max_us", "slips", "own_slips", "host_slips", "missed_releases", "cycles", "spin_us",
                  "compute_p50_us", "compute_p99_us", "compute_max_us", "rss_growth_kb"):
            res[k] = loop[k]
        res["loop"] = loop
    except Exception as e:
        for k in ("p50_us", "p99_us", "max_us", "slips"):
            res[k] = None
            res[f"{k}_reason"] = f"real-time loop failed: {type(e).__name__}: {e}"
    loops = int(round(seconds * 1e6 / period_us))
    if not tools_ok:
        for k in ("cyclictest_p50_us", "cyclictest_p99_us", "cyclictest_max_us"):
            res[k] = None
            res[f"{k}_reason"] = tools_reason
    else:
        try:
            ct = cyclictest(loops, PRIORITY, cpu, interval_us=period_us, hist_us=period_us)
            res["cyclictest_p50_us"], res["cyclictest_p99_us"] = ct["p50_us"], ct["p99_us"]
            res["cyclictest_max_us"], res["cyclictest_avg_us"] = ct["max_us"], ct["avg_us"]
            res["cyclictest"] = ct
            if ct["p99_us"] is None:
                res["cyclictest_p99_us_reason"] = "p99 beyond the histogram range (overflow)"
        except Exception as e:
            for k in ("cyclictest_p50_us", "cyclictest_p99_us", "cyclictest_max_us"):
                res[k] = None
                res[f"{k}_reason"] = f"cyclictest failed: {type(e).__name__}: {e}"
    if res.get("p99_us") is not None and res.get("cyclictest_p99_us"):
        res["p99_over_cyclictest_p99"] = res["p99_us"] / res["cyclictest_p99_us"]
    return res


def _regimes(seconds: float, cpu: int | None, tools_ok: bool, why: str, period_us: int) -> tuple[dict, dict]:
    """(idle, under ``stress-ng --cpu 2``) at ``period_us``."""
    idle = measure(seconds, cpu, tools_ok, why, period_us)
    if shutil.which("stress-ng") is None:
        reason = why or "stress-ng not installed"
        load = {k: None for k in ("p50_us", "p99_us", "max_us", "slips", "cyclictest_p99_us", "cyclictest_max_us")}
        load.update({f"{k}_reason": f"no background load: {reason}" for k in list(load)})
        return idle, load
    try:
        with background_load(2, timeout_s=2 * seconds + 300):
            load = measure(seconds, cpu, tools_ok, why, period_us)
        load["background"] = "stress-ng --cpu 2"
    except Exception as e:
        load = {k: None for k in ("p50_us", "p99_us", "max_us", "slips", "cyclictest_p99_us",
                                  "cyclictest_max_us")}
        load.update({f"{k}_reason": f"background load failed: {type(e).__name__}: {e}" for k in list(load)})
    return idle, load


# the regimes measured: (key in the results, the regime whose targets apply, period [us])
REGIMES = (("idle", "idle", PERIOD_US), ("load", "load", PERIOD_US),
           ("idle_200hz", "idle", FAST_PERIOD_US), ("load_200hz", "load", FAST_PERIOD_US))


def run(quick: bool) -> dict:
    """Idle and under ``stress-ng --cpu 2``, at 50 and at 200 Hz: loop jitter p50/p99/max [us],
    slips, and cyclictest at the same period, priority and CPU."""
    seconds = 10.0 if quick else 60.0
    tools_ok, why = ensure_tools()
    cpu = _cpu()
    idle, load = _regimes(seconds, cpu, tools_ok, why, PERIOD_US)
    idle_fast, load_fast = _regimes(seconds, cpu, tools_ok, why, FAST_PERIOD_US)
    res = {"figure": "release jitter of the real-time loop at 50 and 200 Hz [us] vs cyclictest, same "
                     "period/priority/CPU/load",
           "seconds_per_regime": seconds, "period_us": PERIOD_US, "fast_period_us": FAST_PERIOD_US,
           "priority": PRIORITY, "cpu": cpu,
           "idle": idle, "load": load, "idle_200hz": idle_fast, "load_200hz": load_fast,
           "targets": dict(TARGETS)}
    loop = idle.get("loop") or load.get("loop")
    if loop:
        res["rt"] = {**loop["rt"], "gc": loop["gc"], "threads": loop["threads"]}
    return res


def jitter_verdict(regime: str, p99, max_us, cyclictest_p99) -> tuple[str, object, tuple | None]:
    """(target text, verdict of the ratio target, the absolute target for ``row``) of a
    release jitter against cyclictest in the same regime (also the real-time SIL's,
    ellipsled/bench/sil.py): "idle" and "load" at 50 Hz, "fast" at 200 Hz (idle; its max is
    shown, not judged)."""
    mult = TARGETS[f"{regime}_p99_over_cyclictest_max"]
    text = f"p99 <= {mult:g}x cyclictest" + (f", max <= {TARGETS['idle_max_us']:g} us" if regime == "idle" else "")
    return (text, le(p99, None if cyclictest_p99 is None else mult * cyclictest_p99),
            (max_us, TARGETS["idle_max_us"], "<=") if regime == "idle" else None)


def slip_verdict(period_us: float, own, slips) -> tuple[str, bool | None]:
    """(target text, verdict) of a loop's cycle slips: at 50 Hz every slip counts (the
    original target); at 200 Hz the slips of its own work (the host's late wake-ups, which
    cyclictest shows past the period there, are counted beside them, not judged)."""
    if period_us < PERIOD_US:
        return f"own {TARGETS['fast_own_slips']}", None if own is None else own == TARGETS["fast_own_slips"]
    return f"{TARGETS['slips']}", None if slips is None else slips == TARGETS["slips"]


def rows(res: dict) -> list[Row]:
    R = []
    for key, regime, period_us in REGIMES:
        j = g(res, "jitter", key) or {}
        if not j:
            continue
        ct99 = j.get("cyclictest_p99_us")
        fast = period_us < PERIOD_US and regime == "idle"
        target, ok, absolute = jitter_verdict("fast" if fast else regime, j.get("p99_us"), j.get("max_us"), ct99)
        R.append(row(f"release jitter {regime} at {1e6 / period_us:g} Hz p50 / p99 / max [us]",
                     f"{fmt(j.get('p50_us'))} / {fmt(j.get('p99_us'))} / {fmt(j.get('max_us'))}",
                     f"cyclictest {fmt(j.get('cyclictest_p50_us'))} / {fmt(ct99)} / {fmt(j.get('cyclictest_max_us'))}",
                     f"{fmt(ratio(j.get('p99_us'), ct99))}x (p99)", target, ok, absolute=absolute,
                     machine=speed(res)))
        slips = j.get("slips")
        own = j.get("own_slips", slips)         # older results: every slip the loop's
        target, ok = slip_verdict(period_us, own, slips)
        R.append(row(f"cycle slips, in-process loop {regime} at {1e6 / period_us:g} Hz ({fmt(j.get('cycles'))} "
                     "cycles): own work (all)", f"{fmt(own)} ({fmt(slips)})",
                     f"cyclictest max {fmt(j.get('cyclictest_max_us'))} us", "", target, ok))
    return R


def rt_rows(res: dict) -> list[Row]:
    """The real-time hygiene the jitter loop ran under (the suite's ``rt`` table)."""
    rt = res.get("rt") or {}
    if not rt:
        return []
    th = rt.get("threads") or {}
    return [row("real-time hygiene (jitter loop)",
                f"SCHED_FIFO {fmt(rt.get('sched_fifo'))} prio {fmt(rt.get('priority'))}, CPUs {rt.get('affinity')}, "
                f"mlockall {fmt(rt.get('mlockall'))}, GC off in cycle {fmt(rt.get('gc_disabled_in_cycle'))}, "
                f"threads {fmt(th.get('process_threads'))} (numba {fmt(th.get('numba_threads'))})",
                "", "", "used when permitted", NO_TARGET)]


def child_arguments(ap: argparse.ArgumentParser) -> None:
    """The options a real-time child of the benchmark takes (this loop's and wake.py's):
    ``--priority``, ``--cpu``, and ``--quick`` for the section run alone."""
    ap.add_argument("--priority", type=argtypes.int_range(0, 99), default=PRIORITY, help="SCHED_FIFO priority (0: none)")
    ap.add_argument("--cpu", type=argtypes.int_range(-1, (os.cpu_count() or 1) - 1), default=-1,
                    help="pin to this CPU (-1: no pinning)")
    ap.add_argument("--quick", action="store_true")


def child_or_section(a: argparse.Namespace, is_child: bool, child_fn: Callable[..., dict], tag: str,
                     section: Callable[[bool], dict], **kw) -> int:
    """As a child: ``child_fn(priority, cpu, **kw)``'s figures on one line behind ``tag``
    (run_json_child reads them); else the section run here, its JSON printed."""
    if is_child:
        res = child_fn(priority=a.priority or None, cpu=a.cpu if a.cpu >= 0 else None, **kw)
        print(tag + json.dumps(res), flush=True)
    else:
        print(json.dumps(section(a.quick), indent=2))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", action="store_true", help="run the real-time loop here, print its statistics")
    ap.add_argument("--seconds", type=argtypes.timeout_s, default=10.0)
    ap.add_argument("--period-us", type=argtypes.int_range(1000, 100_000), default=PERIOD_US,
                    help="(child) the loop's control period [us]")
    child_arguments(ap)
    a = ap.parse_args(argv)
    return child_or_section(a, a.child, child, RESULT_TAG, run, seconds=a.seconds, period_us=a.period_us)


if __name__ == "__main__":
    raise SystemExit(main())
