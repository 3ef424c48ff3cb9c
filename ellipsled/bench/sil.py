"""SIL benchmarks through the command the user runs (``ellipsled run``):

- lockstep, multi-process over Zenoh, a full nominal entry: simulated time / wall time
  (``summary.json`` and ``sil.json`` realtime_factor; target ≥ 20×);
- real time at 50 Hz, idle and with ``stress-ng --cpu 2``: sensor-to-actuator latency and
  release jitter p50/p99/max, cycle slips (``sil.json``);
- footprint: each real-time process's resident memory with its memory locked (the idle run)
  beside the same run with ``--no-rt`` (nothing locked), from ``sil.json``'s ``memory``
  (target: locked resident <= 1.2x unlocked);
- rate headroom: the idle run again at a 5-ms control period (``--dt-control 0.005``, 200 Hz)
  beside the 50-Hz one: cycle slips, release jitter, commands the plant missed, the control
  task (target: 0 slips, every command answered);
- the latency floor: sensor-to-actuator p99 at 50 and 200 Hz against the Zenoh + codec round
  trip with the SIL's placement paced at that rate, measured just before and just after the
  run (half the run's span each, pooled: ``pooled_floor``), plus the control task (target
  ≤ 1.1×), and the idle run with the nodes' rehearsal off (``--no-rehearse``) beside it.

``ellipsled run <scenario> --lockstep|--realtime --duration S --out DIR --rerun none`` is
called as a subprocess with a timeout. When the command is absent or fails, every figure
is null with the reason.
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ellipsled.node_reports import read_fsw
from ellipsled.procs import ELLIPSLED

from .jitter import jitter_verdict
from .rows import NO_TARGET, Row, fmt, g, ratio, row, speed

LOCKSTEP_TARGETS = {"realtime_factor_min": 20.0}
REALTIME_TARGETS = {"latency_p99_us_max": 1000.0, "slips": 0}   # jitter: as the in-process loop (jitter.py)
FOOTPRINT_TARGETS = {"locked_over_unlocked_rss_max": 1.2}
FOOTPRINT_KEYS = ("fsw_rss_mb", "fsw_unlocked_rss_mb", "fsw_locked_mb", "sim_rss_mb", "sim_unlocked_rss_mb",
                  "sim_locked_mb")
CONTROL_TARGETS = {"sil_over_batch_p99_max": 2.0, "p99_us_max": 100.0}
FAST_DT_S = 0.005       # the rate headroom's control period (200 Hz)


def realtime_seconds(quick: bool) -> float:
    """The simulated span each real-time SIL run flies (its batch baseline: cycle.py)."""
    return 10.0 if quick else 60.0


SIL_KEYS = ("realtime_factor", "latency_p50_us", "latency_p99_us", "jitter_p50_us", "jitter_p99_us",
            "jitter_max_us", "slips")


def run_command_available() -> tuple[bool, str]:
    """Whether ``ellipsled run`` exists in this tree (asks the CLI itself)."""
    try:
        r = subprocess.run(ELLIPSLED + ["run", "--help"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as e:
        return False, f"`ellipsled run --help` failed: {type(e).__name__}: {e}"
    if r.returncode != 0 or "--lockstep" not in r.stdout or "--realtime" not in r.stdout:
        return False, ("`ellipsled run` with --lockstep/--realtime not available in this tree "
                       f"(exit {r.returncode}: {(r.stderr or r.stdout).strip()[-160:]})")
    return True, ""


def sil_run(mode: str, scenario: str, duration_s: float | None, timeout_s: float, extra=()) -> dict:
    """One ``ellipsled run``; returns {summary, sil, wall_s}. Raises RuntimeError with the cause."""
    with tempfile.TemporaryDirectory(prefix="bench-sil-") as d:
        cmd = ELLIPSLED + ["run", scenario, f"--{mode}", "--out", d, "--rerun", "none"]
        if duration_s is not None:
            cmd += ["--duration", f"{duration_s:g}"]
        cmd += list(extra)
        t0 = time.perf_counter()
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"`{' '.join(cmd[2:])}` timed out after {timeout_s:.0f} s") from None
        wall = time.perf_counter() - t0
        out = Path(d)
        summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").is_file() else None
        sil = json.loads((out / "sil.json").read_text()) if (out / "sil.json").is_file() else None
        fsw = read_fsw(out) if (out / "fsw.json").is_file() else None
        if sil is None and summary is None:
            raise RuntimeError(f"`{' '.join(cmd[2:])}` exit {r.returncode}, no summary.json/sil.json: "
                               f"{(r.stderr or r.stdout).strip()[-300:]}")
        return {"summary": summary, "sil": sil, "fsw": fsw, "wall_s": wall, "exit_code": r.returncode,
                "command": "ellipsled " + " ".join(cmd[3:])}


def _nulls(keys, reason: str) -> dict:
    out = {}
    for k in keys:
        out[k] = None
        out[f"{k}_reason"] = reason
    return out


def lockstep(quick: bool, available: tuple[bool, str] | None = None) -> dict:
    ok, why = available or run_command_available()
    if not ok:
        return _nulls(("realtime_factor",), why)
    dur = 60.0 if quick else None
    try:
        r = sil_run("lockstep", "nominal", dur, timeout_s=300 if quick else 1200)
    except Exception as e:
        return _nulls(("realtime_factor",), f"{type(e).__name__}: {e}")
    s, sil = r["summary"] or {}, r["sil"] or {}
    rtf = sil.get("realtime_factor", s.get("realtime_factor"))
    res = {"figure": "lockstep SIL (sim, fsw over Zenoh): simulated time / wall time",
           "realtime_factor": rtf, "baseline_simulated_s": s.get("t_end_s"),
           "wall_s": s.get("wall_s"), "process_wall_s": r["wall_s"], "end_reason": s.get("end_reason"),
           "completed": s.get("completed"), "cycle_slips": s.get("cycle_slips"), "command": r["command"],
           "exit_code": r["exit_code"], "targets": dict(LOCKSTEP_TARGETS)}
    if rtf is None:
        res["realtime_factor_reason"] = "the run wrote no realtime_factor"
    return res


def realtime(quick: bool, available: tuple[bool, str] | None = None) -> dict:
    """Idle and under load: the SIL's own latency / jitter / slips figures."""
    from .jitter import background_load, ensure_tools
    ok, why = available or run_command_available()
    if not ok:
        return {"idle": _nulls(SIL_KEYS[1:], why), "load": _nulls(SIL_KEYS[1:], why),
                "footprint": _nulls(FOOTPRINT_KEYS, why)}
    dur = realtime_seconds(quick)

    def one(extra=()) -> dict:
        try:
            r = sil_run("realtime", "nominal", dur, timeout_s=dur + 180, extra=extra)
        except Exception as e:
            return _nulls(SIL_KEYS[1:], f"{type(e).__name__}: {e}")
        sil = r["sil"]
        if sil is None:
            return _nulls(SIL_KEYS[1:], f"no sil.json written ({r['command']}, exit {r['exit_code']})")
        out = {k: sil.get(k) for k in SIL_KEYS[1:]}
        for k in SIL_KEYS[1:]:
            if out[k] is None:
                out[f"{k}_reason"] = "absent from sil.json"
        out.update(duration_s=dur, command=r["command"], exit_code=r["exit_code"],
                   extra={k: v for k, v in sil.items() if k not in SIL_KEYS})
        return out

    def bracketed(hz: float, extra=()) -> dict:
        """The run ``extra`` at ``hz`` with its latency floor's round trips measured on both
        sides of it (``floor_{hz}hz``)."""
        before = _floor_part(dur / 2, hz)
        out = one(extra)
        res[f"floor_{hz:g}hz"] = pooled_floor(before, _floor_part(dur / 2, hz), hz)
        return out

    res = {"figure": "real-time SIL at 50 Hz: sensor-to-actuator latency and release jitter [us]"}
    res.update(idle=bracketed(50.0),
               # the standard transport instead of the default low-latency one
               idle_standard_transport=one(("--no-zenoh-lowlatency",)),
               # the footprint's baseline: the same run with nothing locked (nor SCHED_FIFO)
               idle_unlocked=one(("--no-rt",)),
               # rate headroom: the same run at 200 Hz
               idle_200hz=bracketed(200.0, ("--dt-control", f"{FAST_DT_S:g}")),
               # the nodes' rehearsal of their receiving paths off: what it takes off the latency
               idle_no_rehearse=one(("--no-rehearse",)))
    res["footprint"] = footprint(res["idle"], res["idle_unlocked"])
    tools_ok, tools_why = ensure_tools()
    if not tools_ok:
        res["load"] = _nulls(SIL_KEYS[1:], f"no background load: {tools_why}")
    else:
        try:
            with background_load(2, timeout_s=dur + 300):
                res["load"] = one()
            res["load"]["background"] = "stress-ng --cpu 2"
        except Exception as e:
            res["load"] = _nulls(SIL_KEYS[1:], f"background load failed: {type(e).__name__}: {e}")
    res["targets"] = dict(REALTIME_TARGETS)
    return res


def _floor_part(seconds: float, hz: float) -> dict:
    """One side's round trips of a floor (latency.sil_floor), or its failure's reason."""
    from .latency import sil_floor
    try:
        return sil_floor(seconds, hz)
    except Exception as e:
        return {"p99_us": None, "p99_us_reason": f"{type(e).__name__}: {e}"}


def pooled_floor(before: dict, after: dict, hz: float) -> dict:
    """The floor's round trip at ``hz`` from its two parts, measured just before and just after
    the run it judges, each half the run's span at the run's rate: together as many round
    trips as the run has frames, pooled (p50 / p99 / max over all of them) so that the floor
    is taken over the same host spell and the same count as the latency. A single sample
    away from the run is no baseline for a p99: the same round trip's p99 moves 2-3x
    between 10-s samples minutes apart (docs/changelog.md, Benchmarks). Each part's own
    p50 / p99 stays beside it (``parts``); null with the reasons when a part failed."""
    from .latency import stats_us
    parts = {"before": before, "after": after}
    out = {"figure": f"Zenoh + codec round trip, SIL placement, paced at {hz:g} Hz, measured on both sides "
                     "of the run it is the floor of [us]",
           "rate_hz": hz,
           "parts": {w: {k: p.get(k) for k in ("p50_us", "p99_us", "max_us", "n", "lost", "p99_us_reason")
                         if k in p} for w, p in parts.items()}}
    failed = [f"{w}: {p.get('p99_us_reason', 'no round trips')}" for w, p in parts.items() if not p.get("samples_us")]
    if failed:
        out.update(p50_us=None, p99_us=None, max_us=None, p99_us_reason="; ".join(failed))
        return out
    out.update(stats_us(before["samples_us"] + after["samples_us"], before.get("lost", 0) + after.get("lost", 0)))
    return out


def footprint(locked: dict, unlocked: dict) -> dict:
    """Each process's resident memory at the end of the locked run beside the unlocked one's
    [MB]: {role}_rss_mb, {role}_unlocked_rss_mb, {role}_locked_mb (resident and locked),
    {role}_ratio, {role}_mlock_mode; null with a reason where a run wrote no figure."""
    out = {"figure": "real-time SIL resident memory at the end of the run, memory locked (--rt) and "
                     "not (--no-rt) [MB]"}
    for role in ("fsw", "sim"):
        m = g(locked, "extra", "memory", role) or {}
        u = g(unlocked, "extra", "memory", role) or {}
        mb = lambda kb: None if kb is None else kb / 1024       # noqa: E731
        out[f"{role}_rss_mb"] = mb(m.get("vm_rss_kb"))
        out[f"{role}_locked_mb"] = mb(m.get("locked_kb"))
        out[f"{role}_unlocked_rss_mb"] = mb(u.get("vm_rss_kb"))
        out[f"{role}_mlock_mode"] = m.get("mlock_mode")
        out[f"{role}_ratio"] = ratio(out[f"{role}_rss_mb"], out[f"{role}_unlocked_rss_mb"])
        for k, run in ((f"{role}_rss_mb", locked), (f"{role}_locked_mb", locked), (f"{role}_unlocked_rss_mb", unlocked)):
            if out[k] is None:
                out[f"{k}_reason"] = next((v for kk, v in run.items() if kk.endswith("_reason")),
                                          "no memory figures in sil.json")
    out["targets"] = dict(FOOTPRINT_TARGETS)
    return out


RATE_TARGETS = {"slips": 0, "missed_commands": 0}
FLOOR_TARGETS = {"latency_over_floor_p99_max": 1.1}
# the real-time runs the floor is stated for: (sil_realtime key, control rate [Hz])
FLOOR_RUNS = (("idle", 50.0), ("idle_200hz", 200.0))


def _missed(s: dict):
    return g(s, "extra", "sim_counts", "missed_commands")


def _answered(s: dict) -> str | None:
    """"m of n" commands missed after the FSW's first answer; beside them the steps the plant
    itself reached past its deadline (the host held the plant: it waited for no command) and
    the steps before the first answer."""
    n, m = g(s, "extra", "latency_samples"), _missed(s)
    if n is None or m is None:
        return None
    late = g(s, "extra", "sim_counts", "missed_plant_late") or 0
    start = g(s, "extra", "sim_counts", "unanswered_at_start")
    return (f"{m} of {n + m + late}" + (f" (+{late} the plant reached past its deadline)" if late else "")
            + (f" (+{start} before the first command)" if start is not None else ""))


def _own(s: dict):
    """The run's slips the FSW's own work explains; all of them when the run did not say."""
    own = g(s, "extra", "own_slips")
    return s.get("slips") if own is None else own


def rate_rows(res: dict) -> list[Row]:
    """The idle run at 200 Hz beside the same run at 50 Hz; its jitter against cyclictest at
    the same 5-ms period (the jitter section's 200-Hz regime)."""
    fast, base = g(res, "sil_realtime", "idle_200hz") or {}, g(res, "sil_realtime", "idle") or {}
    if not fast:
        return []

    def ctl(s, q):
        return g(s, "extra", "fsw_control_us", q)
    own, missed = _own(fast), _missed(fast)
    ct99 = g(res, "jitter", "idle_200hz", "cyclictest_p99_us")
    # judged by the rate headroom's target (p99 against cyclictest at 5 ms); its max beside it
    target, ok, absolute = jitter_verdict("fast", fast.get("jitter_p99_us"), fast.get("jitter_max_us"), ct99)
    return [
        row("real-time SIL at 200 Hz: cycle slips by the FSW's own work (all); commands missed",
            f"{fmt(own)} ({fmt(fast.get('slips'))}); {_answered(fast) or 'n/m'}",
            f"50 Hz {fmt(_own(base))} ({fmt(base.get('slips'))}); {_answered(base) or 'n/m'}", "", "0; 0",
            None if own is None or missed is None
            else own == RATE_TARGETS["slips"] and missed == RATE_TARGETS["missed_commands"]),
        row("real-time SIL at 200 Hz: release jitter p50 / p99 / max [us]",
            f"{fmt(fast.get('jitter_p50_us'))} / {fmt(fast.get('jitter_p99_us'))} / {fmt(fast.get('jitter_max_us'))}",
            f"cyclictest at 5 ms p99 {fmt(ct99)} max {fmt(g(res, 'jitter', 'idle_200hz', 'cyclictest_max_us'))}; "
            f"50 Hz {fmt(base.get('jitter_p99_us'))}",
            f"{fmt(ratio(fast.get('jitter_p99_us'), ct99))}x (p99)", target, ok, absolute=absolute,
            machine=speed(res)),
        row("real-time SIL at 200 Hz: control task p50 / p99 [us]", f"{fmt(ctl(fast, 'p50'))} / {fmt(ctl(fast, 'p99'))}",
            f"50 Hz {fmt(ctl(base, 'p50'))} / {fmt(ctl(base, 'p99'))}",
            f"{fmt(ratio(ctl(fast, 'p99'), ctl(base, 'p99')))}x (p99)", "", NO_TARGET),
    ]


def latency_floor(res: dict, key: str, hz: float) -> dict:
    """The sensor-to-actuator p99 of the real-time run ``key`` against its floor [us]: the
    Zenoh + codec round trip p99 with the SIL's placement paced at the run's rate, measured
    on both sides of that run (``pooled_floor``), plus the FSW's control task p99 (its share);
    the remainder is the rest. ``parts``: the round trip's p99 before / after the run."""
    s = g(res, "sil_realtime", key) or {}
    lat = s.get("latency_p99_us")
    rt = g(res, "sil_realtime", f"floor_{hz:g}hz", "p99_us")
    parts = tuple(g(res, "sil_realtime", f"floor_{hz:g}hz", "parts", w, "p99_us") for w in ("before", "after"))
    ctl = g(s, "extra", "fsw_control_us", "p99")
    floor = None if rt is None or ctl is None else rt + ctl
    return {"latency_p99_us": lat, "roundtrip_p99_us": rt, "control_p99_us": ctl, "floor_p99_us": floor,
            "remainder_us": None if lat is None or floor is None else lat - floor,
            "over_floor": ratio(lat, floor), "parts": parts}


def floor_rows(res: dict) -> list[Row]:
    """Sensor-to-actuator p99 against its floor at 50 and 200 Hz, and where the time goes."""
    k = FLOOR_TARGETS["latency_over_floor_p99_max"]
    R = []
    for key, hz in FLOOR_RUNS:
        s = g(res, "sil_realtime", key) or {}
        if not s:
            continue
        f = latency_floor(res, key, hz)
        r = f["over_floor"]
        R.append(row(f"sensor-to-actuator p99 at {hz:g} Hz against its floor [us]: measured (remainder)",
                     f"{fmt(f['latency_p99_us'])} ({fmt(f['remainder_us'])})",
                     f"floor {fmt(f['floor_p99_us'])} = Zenoh + codec round trip {fmt(f['roundtrip_p99_us'])} "
                     f"(before / after the run {fmt(f['parts'][0])} / {fmt(f['parts'][1])}) "
                     f"+ FSW control task {fmt(f['control_p99_us'])}",
                     f"{fmt(r)}x floor", f"p99 <= {k:g}x floor", None if r is None else r <= k))
        ex = s.get("extra") or {}
        sp = ex.get("latency_split_us") or {}
        R.append(row(f"  where it goes at {hz:g} Hz, p50 / p99 [us]: plant -> FSW has the frame; FSW frame -> "
                     "answer published; FSW publish -> plant has the command",
                     f"{fmt(ex.get('fsw_frame_age_p50_us'))} / {fmt(ex.get('fsw_frame_age_p99_us'))}; "
                     f"{fmt(_minus(sp.get('sensor_and_fsw_p50_us'), ex.get('fsw_frame_age_p50_us')))} / "
                     f"{fmt(_minus(sp.get('sensor_and_fsw_p99_us'), ex.get('fsw_frame_age_p99_us')))}; "
                     f"{fmt(sp.get('command_p50_us'))} / {fmt(sp.get('command_p99_us'))}",
                     f"control task {fmt(g(ex, 'fsw_control_us', 'p50'))} / {fmt(g(ex, 'fsw_control_us', 'p99'))}",
                     "", "", NO_TARGET))
    return R


def control_rows(res: dict) -> list[Row]:
    """The control task in the real-time SIL against the same task in batch over the same
    simulated span (cycle.py's ``control_span_*``; its whole-entry p99 for scale), at 50 and
    200 Hz; beside each p99, the p99 without the duty-cycle LP's cycles."""
    k, lim = CONTROL_TARGETS["sil_over_batch_p99_max"], CONTROL_TARGETS["p99_us_max"]
    R = []
    for key, hz in FLOOR_RUNS:
        s = g(res, "sil_realtime", key) or {}
        if not s:
            continue
        ctl = g(s, "extra", "fsw_control_us") or {}
        b = g(res, "cycle", f"control_span_{hz:g}hz") or {}
        r, r_rest = ratio(ctl.get("p99"), b.get("p99_us")), ratio(ctl.get("p99_without_lp"), b.get("p99_without_lp_us"))
        tenth = ctl.get("p50_by_tenth")
        tenths = "" if not tenth else (f"; tenths {fmt(tenth.get('lowest'))} / {fmt(tenth.get('median'))} / "
                                       f"{fmt(tenth.get('highest'))}")
        R.append(row(f"control task at {hz:g} Hz, real-time SIL against batch over the same span, p50 / p99 [us] "
                     "(p99 without the duty-cycle LP's cycles; p50 of each tenth of the run, lowest / median / "
                     "highest)",
                     f"{fmt(ctl.get('p50'))} / {fmt(ctl.get('p99'))} ({fmt(ctl.get('p99_without_lp'))}, "
                     f"{fmt(ctl.get('lp_cycles'))} LP cycles{tenths})",
                     f"batch first {fmt(b.get('span_s'))} s {fmt(b.get('p50_us'))} / {fmt(b.get('p99_us'))} "
                     f"({fmt(b.get('p99_without_lp_us'))}, {fmt(b.get('lp_cycles'))} LP cycles); "
                     f"whole batch entry p99 {fmt(g(res, 'cycle', 'control_p99_us'))}",
                     f"{fmt(r)}x (p99; without the LP's cycles {fmt(r_rest)}x)",
                     f"p99 <= {k:g}x batch, <= {lim:g} us", None if r is None else r <= k,
                     absolute=(ctl.get("p99"), lim, "<="), machine=speed(res)))
    return R


def _minus(a, b):
    """a - b (the middle leg of two percentiles: an estimate, percentiles do not subtract exactly)."""
    return None if a is None or b is None else a - b


def footprint_rows(res: dict) -> list[Row]:
    f = g(res, "sil_realtime", "footprint") or {}
    if not f:
        return []
    k = FOOTPRINT_TARGETS["locked_over_unlocked_rss_max"]
    R = []
    for role, name in (("fsw", "flight software"), ("sim", "plant")):
        r = f.get(f"{role}_ratio")
        R.append(row(f"real-time SIL {name} resident / locked [MB] ({f.get(f'{role}_mlock_mode') or 'not locked'})",
                     f"{fmt(f.get(f'{role}_rss_mb'))} / {fmt(f.get(f'{role}_locked_mb'))}",
                     f"unlocked (--no-rt) {fmt(f.get(f'{role}_unlocked_rss_mb'))}", f"{fmt(r)}x",
                     f"<= {k:g}x unlocked", None if r is None else r <= k))
    return R


def lockstep_rows(res: dict) -> list[Row]:
    sl = res.get("sil_lockstep") or {}
    if not sl:
        return []
    m = LOCKSTEP_TARGETS["realtime_factor_min"]
    return [row("lockstep SIL real-time factor (multi-process, Zenoh)", f"{fmt(sl.get('realtime_factor'))}x",
                f"simulated {fmt(sl.get('baseline_simulated_s'))} s", "", f">= {m:g}x", NO_TARGET,
                absolute=(sl.get("realtime_factor"), m, ">="), machine=speed(res))]


def latency_rows(res: dict, regime: str, s: dict) -> list[Row]:
    """The latency beside the UDP round trip of the SIL's own placement (FIFO, one CPU per
    process: ``latency.py``), else the default one, for scale: its ratio target is its floor's
    (``floor_rows``: a multiple of UDP is below what Zenoh itself takes); then where the
    time goes."""
    lat_max = REALTIME_TARGETS["latency_p99_us_max"]
    udp, base = g(res, "latency", "sil_udp_p99_us"), "UDP round trip p99 (SIL placement)"
    if udp is None:
        udp, base = g(res, "latency", "udp_p99_us"), "UDP round trip p99"
    r = ratio(s.get("latency_p99_us"), udp)
    R = [row(f"sensor-to-actuator latency {regime} p50 / p99 [us]",
             f"{fmt(s.get('latency_p50_us'))} / {fmt(s.get('latency_p99_us'))}",
             f"{base} {fmt(udp)}", f"{fmt(r)}x (p99)", f"p99 <= {lat_max:g} us (and <= 1.1x its floor: below)",
             True, absolute=(s.get("latency_p99_us"), lat_max, "<="), machine=speed(res))]
    ex = s.get("extra") or {}
    sp, ctl = ex.get("latency_split_us") or {}, ex.get("fsw_control_us") or {}
    if sp:
        zen = g(res, "latency", "sil_zenoh_p50_us"), g(res, "latency", "sil_zenoh_p99_us")
        R.append(row(f"  where it goes ({regime}) p50 / p99 [us]: plant -> FSW frame age; FSW control; "
                     "FSW publish -> plant has the command",
                     f"{fmt(ex.get('fsw_frame_age_p50_us'))} / {fmt(ex.get('fsw_frame_age_p99_us'))}; "
                     f"{fmt(ctl.get('p50'))} / {fmt(ctl.get('p99'))}; "
                     f"{fmt(sp.get('command_p50_us'))} / {fmt(sp.get('command_p99_us'))}",
                     f"Zenoh + codec round trip (SIL placement) {fmt(zen[0])} / {fmt(zen[1])}", "", "", NO_TARGET))
    return R


def realtime_rows(res: dict) -> list[Row]:
    R = []
    slips = REALTIME_TARGETS["slips"]
    for regime in ("idle", "load"):
        s = g(res, "sil_realtime", regime) or {}
        if not s:
            continue
        ct99 = g(res, "jitter", regime, "cyclictest_p99_us")
        target, ok, absolute = jitter_verdict(regime, s.get("jitter_p99_us"), s.get("jitter_max_us"), ct99)
        R.append(row(f"real-time SIL jitter {regime} p50 / p99 / max [us]",
                     f"{fmt(s.get('jitter_p50_us'))} / {fmt(s.get('jitter_p99_us'))} / {fmt(s.get('jitter_max_us'))}",
                     f"cyclictest p99 {fmt(ct99)}", f"{fmt(ratio(s.get('jitter_p99_us'), ct99))}x (p99)", target, ok,
                     absolute=absolute, machine=speed(res)))
        R.append(row(f"real-time SIL cycle slips {regime} ({fmt(s.get('duration_s'))} s)", fmt(s.get("slips")), "", "",
                     f"{slips}", None if s.get("slips") is None else s.get("slips") == slips))
        R += latency_rows(res, regime, s)
        if regime == "idle":
            R += footprint_rows(res) + rate_rows(res) + floor_rows(res) + control_rows(res)
    s = g(res, "sil_realtime", "idle_no_rehearse") or {}
    if s:
        on = g(res, "sil_realtime", "idle") or {}
        R.append(row("sensor-to-actuator latency idle, --no-rehearse p50 / p99 [us]",
                     f"{fmt(s.get('latency_p50_us'))} / {fmt(s.get('latency_p99_us'))}",
                     f"rehearsal on {fmt(on.get('latency_p50_us'))} / {fmt(on.get('latency_p99_us'))}",
                     f"{fmt(ratio(s.get('latency_p50_us'), on.get('latency_p50_us')))}x (p50)", "", NO_TARGET))
    s = g(res, "sil_realtime", "idle_standard_transport") or {}
    if s:
        low = g(res, "sil_realtime", "idle", "latency_p99_us")
        R.append(row("sensor-to-actuator latency idle, --no-zenoh-lowlatency p50 / p99 [us]",
                     f"{fmt(s.get('latency_p50_us'))} / {fmt(s.get('latency_p99_us'))}",
                     f"low-latency transport p99 {fmt(low)}", f"{fmt(ratio(s.get('latency_p99_us'), low))}x (p99)",
                     "", NO_TARGET))
    return R


if __name__ == "__main__":
    q = "--quick" in sys.argv
    print(json.dumps({"lockstep": lockstep(q), "realtime": realtime(q)}, indent=2))
