"""``ellipsled bench [--quick] --out FILE.json``: every benchmark of spec 50-performance.md
in one invocation, each figure next to its baseline measured in the same run.

Writes FILE.json (machine-readable) and FILE.md (the table, also printed). Each section
runs inside its own try/except: a failure nulls only that section's figures, each with a
``<name>_reason`` key beside it; a figure that was not measured is ``null`` with its
reason, never a made-up number. The JSON is rewritten after every section, so an
interrupted run keeps what it measured.

Sections (ellipsled/bench/<name>.py, each ``run(quick) -> dict``): machine, codec,
allocator, plant, cycle, batch, groundlink, latency, jitter, sil_lockstep, sil_realtime,
sil_router (ellipsled/bench/router.py), flood (a ground flood at the real-time SIL),
bridge; ``rt`` (real-time hygiene) is read from the jitter loop.
"""
from __future__ import annotations

import json
import math
import os
import platform
import sys
import time
import traceback
from pathlib import Path
from typing import Callable

# Figures every consumer may rely on: present in the JSON, a number or null + reason.
REQUIRED: dict[str, tuple[str, ...]] = {
    "machine": ("nproc", "load", "python", "versions"),
    "codec": ("sensors_roundtrip_p99_us", "jets_roundtrip_p99_us"),
    "allocator": ("p50_us", "p99_us", "max_us", "highs_p99_us", "speedup", "mismatches"),
    "plant": ("step_p50_us", "step_p99_us", "entry_real_time_factor"),
    "cycle": ("compute_p50_us", "compute_p99_us", "compute_max_us"),
    "batch": ("realtime_factor",),
    "guidance": ("p50_us", "p99_us", "max_us", "baseline_control_p99_us"),
    "reconfig": ("reconfig_p50_ms", "reconfig_p99_ms", "reconfig_max_ms", "reconfig_first_ms", "baseline_period_ms"),
    "groundlink": ("tick_p99_us",),
    "latency": ("p50_us", "p99_us", "udp_p50_us", "udp_p99_us", "zenoh_p50_us", "zenoh_p99_us"),
    "jitter": (),
    "jitter.idle": ("p50_us", "p99_us", "max_us", "slips", "cyclictest_p99_us", "cyclictest_max_us"),
    "jitter.load": ("p50_us", "p99_us", "max_us", "slips", "cyclictest_p99_us", "cyclictest_max_us"),
    "sil_lockstep": ("realtime_factor",),
    "sil_realtime": (),
    "sil_realtime.idle": ("latency_p50_us", "latency_p99_us", "jitter_p50_us", "jitter_p99_us",
                          "jitter_max_us", "slips"),
    "sil_realtime.load": ("latency_p50_us", "latency_p99_us", "jitter_p50_us", "jitter_p99_us",
                          "jitter_max_us", "slips"),
    "sil_router": ("p50_us", "p99_us", "baseline_p50_us", "baseline_p99_us"),
    "flood": ("flood_compute_p99_us", "flood_compute_max_us", "flood_groundlink_p99_us", "flood_groundlink_max_us",
              "flood_slips", "quiet_compute_p99_us", "quiet_groundlink_p99_us"),
    "bridge": ("cpu_pct", "mem_growth_mb"),
    "rt": ("sched_fifo", "affinity", "mlockall", "messages"),
}

ORDER = ("machine", "codec", "allocator", "reconfig", "plant", "cycle", "batch", "guidance", "groundlink", "latency", "jitter",
         "sil_lockstep", "sil_realtime", "sil_router", "flood", "bridge")


# --------------------------------------------------------------------------- sections
def machine(quick: bool) -> dict:
    import importlib.metadata as md
    versions = {}
    for pkg in ("numpy", "scipy", "numba", "highspy", "eclipse-zenoh", "rerun-sdk", "pymavlink", "psutil"):
        try:
            versions[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            versions[pkg] = None
    cpu = None
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), None)
    except OSError:
        pass
    try:
        affinity = sorted(os.sched_getaffinity(0))
    except OSError:
        affinity = None
    return {"nproc": os.cpu_count(), "affinity": affinity, "load": list(os.getloadavg()),
            "python": sys.version.split()[0], "implementation": platform.python_implementation(),
            "kernel": platform.release(), "cpu": cpu, "versions": versions,
            "euid": os.geteuid(), "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def _allocator(quick):
    from . import allocator
    return allocator.run(quick)


def _reconfig(quick):
    from . import reconfig
    return reconfig.run(quick)


def _plant(quick):
    from . import plant
    return plant.run(quick)


def _codec(quick):
    from . import codec
    return codec.run(quick)


def _cycle(quick):
    from . import cycle
    return cycle.run(quick)


def _batch(quick):
    from . import batch
    return batch.run(quick)


def _guidance(quick):
    from . import guidance
    return guidance.run(quick)


def _groundlink(quick):
    from . import groundlink
    return groundlink.run(quick)


def _latency(quick):
    from . import latency
    return latency.run(quick)      # the SIL's sensor-to-actuator figures are merged in afterwards


def _jitter(quick):
    from . import jitter
    return jitter.run(quick)


def _sil_lockstep(quick):
    from . import sil
    return sil.lockstep(quick)


def _sil_realtime(quick):
    from . import sil
    return sil.realtime(quick)


def _sil_router(quick):
    from . import router
    return router.run(quick)


def _flood(quick):
    from . import flood
    return flood.run(quick)


def _bridge(quick):
    from . import bridge
    r = bridge.run(quick)
    lf = r["logger_file"]
    web = r.get("logger_file_and_grpc_server") or {}
    return {"cpu_pct": lf["cpu_pct_at_50Hz"], "mem_growth_mb": lf["rss_growth_MB"],
            "mem_growth_second_half_mb": lf["rss_growth_second_half_MB"], "steps": lf["steps"],
            "mem_slope_second_half_mb_per_10k_steps": lf["rss_slope_second_half_MB_per_10k_steps"],
            "mem_growth_with_grpc_server_mb": web.get("rss_growth_MB"),
            "baseline_per_signal_us_per_frame": r["per_signal_rr_log"]["us_per_frame"],
            "batched_us_per_frame": r["send_columns_batched"]["us_per_frame"],
            "speedup_batched_vs_per_signal": r["speedup_batched_vs_per_signal"],
            "targets": {"cpu_pct_max": 5.0, "mem_mb_per_10k_steps_max": lf["memory_flat_max_MB_per_10k_steps"]},
            "detail": r}


SECTIONS: dict[str, Callable[[bool], dict]] = {
    "machine": machine, "codec": _codec, "allocator": _allocator, "reconfig": _reconfig, "plant": _plant, "cycle": _cycle,
    "batch": _batch, "guidance": _guidance, "groundlink": _groundlink, "latency": _latency, "jitter": _jitter,
    "sil_lockstep": _sil_lockstep, "sil_realtime": _sil_realtime, "sil_router": _sil_router, "flood": _flood,
    "bridge": _bridge,
}


# --------------------------------------------------------------------------- null + reason
def _sub(res: dict, path: str) -> dict:
    d = res
    for p in path.split("."):
        d = d.setdefault(p, {})
        if not isinstance(d, dict):
            raise TypeError(f"bench: {path} is not a table")
    return d


def fill_required(res: dict, section: str, reason: str) -> None:
    """Every required figure of ``section`` (and its sub-tables) present: a missing one is
    null with ``<name>_reason``; a null without a reason gets ``reason``."""
    for path, keys in REQUIRED.items():
        if path != section and not path.startswith(section + "."):
            continue
        d = _sub(res, path)
        for k in keys:
            if k not in d:
                d[k] = None
            v = d[k]
            if v is None or (isinstance(v, float) and not math.isfinite(v)):
                d[k] = None
                d.setdefault(f"{k}_reason", reason)


def _clean(x):
    """JSON-safe: NaN/inf -> None, numpy scalars -> Python."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if hasattr(x, "item") and not isinstance(x, (str, bytes)):
        try:
            x = x.item()
        except (ValueError, AttributeError):
            return str(x)
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def run_section(name: str, fn: Callable[[bool], dict], quick: bool) -> dict:
    import gc
    t0 = time.perf_counter()
    gc_was = gc.isenabled()
    try:
        out = _clean(fn(quick))
        if not isinstance(out, dict):
            raise TypeError(f"section returned {type(out).__name__}, not a dict")
        reason = "not produced by this section"
    except Exception as e:
        out = {"error": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc()[-2000:]}
        reason = f"section failed: {type(e).__name__}: {e}"
    finally:
        if gc_was:
            gc.enable()
    res = {name: out}
    fill_required(res, name, reason)
    out["section_wall_s"] = time.perf_counter() - t0
    return out


def _derive(res: dict, quick: bool) -> None:
    """Cross-section figures: latency headline from the real-time SIL, rt from the jitter loop."""
    lat = res.get("latency")
    silrt = res.get("sil_realtime") or {}
    if lat is not None:
        idle = silrt.get("idle") or {}
        for k in ("p50_us", "p99_us"):
            v = idle.get(f"latency_{k}")
            lat[k] = v
            lat.pop(f"{k}_reason", None)
            if v is None:
                lat[f"{k}_reason"] = ("real-time SIL sensor-to-actuator latency not measured: "
                                      + str(idle.get(f"latency_{k}_reason", "sil_realtime section absent")))
        load = silrt.get("load") or {}
        lat["load_p99_us"] = load.get("latency_p99_us")
        if lat["load_p99_us"] is None:
            lat["load_p99_us_reason"] = str(load.get("latency_p99_us_reason", "sil_realtime section absent"))
        lat["source"] = ("p50/p99: real-time SIL sensor-to-actuator (plant publishes step k -> plant has "
                         "command k), idle; udp_*/zenoh_*: echo round trips between two processes")
    jit = res.get("jitter") or {}
    rt = dict(jit.get("rt") or {})
    if rt:
        rt["source"] = "the jitter loop's common.rt.apply() report (read back from the kernel)"
        rt["gc_disabled_in_cycle"] = not rt.get("gc", {}).get("enabled_in_loop", True)
        rt["cycle_bench_gc_disabled"] = (res.get("cycle") or {}).get("gc_disabled_in_cycle")
    else:
        rt["error"] = "jitter loop did not run"
    res["rt"] = rt
    fill_required(res, "rt", "jitter loop did not report real-time hygiene: "
                  + str((jit.get("idle") or {}).get("p99_us_reason", jit.get("error", "unknown"))))


def run_suite(quick: bool, out: Path | None = None, only: list[str] | None = None,
              sections: dict[str, Callable[[bool], dict]] | None = None,
              say: Callable[[str], None] = print) -> dict:
    sections = SECTIONS if sections is None else sections
    names = [n for n in (ORDER if sections is SECTIONS else list(sections)) if only is None or n in only]
    if only is not None:
        unknown = sorted(set(only) - set(sections))
        if unknown:
            raise ValueError(f"bench: unknown section(s) {', '.join(unknown)} (known: {', '.join(sections)})")
    res: dict = {"quick": bool(quick), "sections": names}
    t0 = time.perf_counter()
    for name in names:
        say(f"bench: {name} ...")
        res[name] = run_section(name, sections[name], quick)
        say(f"bench: {name} done in {res[name]['section_wall_s']:.1f} s"
            + (f" (FAILED: {res[name]['error']})" if "error" in res[name] else ""))
        if out is not None:
            _write_json(res, out)
    _derive(res, quick)
    res["wall_s"] = time.perf_counter() - t0
    res = _clean(res)
    if out is not None:
        _write_json(res, out)
    return res


def _write_json(res: dict, out: Path) -> None:
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(out.suffix + ".tmp")
    tmp.write_text(json.dumps(_clean(res), indent=2) + "\n")
    tmp.replace(out)


# --------------------------------------------------------------------------- table
def _g(d: dict | None, *path):
    for p in path:
        if not isinstance(d, dict):
            return None
        d = d.get(p)
    return d


def _fmt(v, unit: str = "") -> str:
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


def _ratio(a, b):
    return (a / b) if isinstance(a, (int, float)) and isinstance(b, (int, float)) and b else None


NO_TARGET = object()


def _verdict(ok) -> str:
    if ok is NO_TARGET:
        return ""
    return "n/m" if ok is None else ("pass" if ok else "**FAIL**")


def _le(a, b):
    return None if a is None or b is None else a <= b


def _ge(a, b):
    return None if a is None or b is None else a >= b


def _all(*xs):
    if any(x is None for x in xs):
        return None if not any(x is False for x in xs) else False
    return all(xs)


def rows(res: dict) -> list[tuple[str, str, str, str, str, str]]:
    """(figure, measured, baseline, ratio, target, verdict) rows of the table."""
    R = []

    def add(fig, meas, base, ratio, target, ok):
        R.append((fig, meas, base, ratio, target, _verdict(ok)))
    a = res.get("allocator") or {}
    if a:
        add("allocator solve p50 / p99 / max [us]",
            f"{_fmt(a.get('p50_us'))} / {_fmt(a.get('p99_us'))} / {_fmt(a.get('max_us'))}",
            f"HiGHS {_fmt(a.get('highs_p50_us'))} / {_fmt(a.get('highs_p99_us'))}",
            f"{_fmt(a.get('speedup'))}x (p50)", "p99 <= 100 us, >= 200x",
            _all(_le(a.get("p99_us"), 100.0), _ge(a.get("speedup"), 200.0)))
        add(f"allocator optimality mismatches ({_fmt(a.get('demands'))} demands)", _fmt(a.get("mismatches")),
            f"HiGHS on {_fmt(a.get('highs_demands'))}, enumeration on all", "", "0",
            None if a.get("mismatches") is None else a.get("mismatches") == 0)
    rc = res.get("reconfig") or {}
    if rc:
        per = rc.get("baseline_period_ms")
        add(f"allocator reconfiguration, request -> new tables in use ({_fmt(rc.get('sets'))} fault sets)"
            " p50 / p99 / max [ms]",
            f"{_fmt(rc.get('reconfig_p50_ms'))} / {_fmt(rc.get('reconfig_p99_ms'))} / {_fmt(rc.get('reconfig_max_ms'))}",
            f"period {_fmt(per)}", f"{_fmt(_ratio(rc.get('reconfig_p99_ms'), per))} of period (p99)",
            "p99 <= 20 ms", _le(rc.get("reconfig_p99_ms"), 20.0))
        add("  first reconfiguration after start (fresh process) [ms]", _fmt(rc.get("reconfig_first_ms")),
            f"period {_fmt(per)}", f"{_fmt(_ratio(rc.get('reconfig_first_ms'), per))} of period",
            "<= 20 ms", _le(rc.get("reconfig_first_ms"), 20.0))
    c = res.get("cycle") or {}
    if c:
        per = c.get("baseline_period_us")
        add("control cycle compute p50 / p99 / max [us] (all RG tasks)",
            f"{_fmt(c.get('compute_p50_us'))} / {_fmt(c.get('compute_p99_us'))} / {_fmt(c.get('compute_max_us'))}",
            f"period {_fmt(per)}", f"{_fmt(_ratio(c.get('compute_p99_us'), per))} of period (p99)",
            "p99 <= 1000 us", _le(c.get("compute_p99_us"), 1000.0))
        for t, s in (c.get("tasks") or {}).items():
            add(f"  task {t} p50 / p99 / max [us]",
                f"{_fmt(s.get('p50_us'))} / {_fmt(s.get('p99_us'))} / {_fmt(s.get('max_us'))}",
                f"period {_fmt(per)}", "", "", NO_TARGET)
        ac = c.get("allocator_in_control") or {}
        if ac:
            add("  allocator inside control p50 / p99 [us]", f"{_fmt(ac.get('p50_us'))} / {_fmt(ac.get('p99_us'))}",
                "", "", "", NO_TARGET)
    for regime, mult in (("idle", 2.0), ("load", 3.0)):
        j = _g(res, "jitter", regime) or {}
        if not j:
            continue
        ct99 = j.get("cyclictest_p99_us")
        add(f"release jitter {regime} p50 / p99 / max [us]",
            f"{_fmt(j.get('p50_us'))} / {_fmt(j.get('p99_us'))} / {_fmt(j.get('max_us'))}",
            f"cyclictest {_fmt(j.get('cyclictest_p50_us'))} / {_fmt(ct99)} / {_fmt(j.get('cyclictest_max_us'))}",
            f"{_fmt(_ratio(j.get('p99_us'), ct99))}x (p99)",
            f"p99 <= {mult:g}x cyclictest" + (", max <= 1000 us" if regime == "idle" else ""),
            _all(_le(j.get("p99_us"), None if ct99 is None else mult * ct99),
                 _le(j.get("max_us"), 1000.0) if regime == "idle" else True))
        add(f"cycle slips, in-process loop {regime} ({_fmt(j.get('cycles'))} cycles)", _fmt(j.get("slips")),
            "", "", "0", None if j.get("slips") is None else j.get("slips") == 0)
    for regime, mult in (("idle", 2.0), ("load", 3.0)):
        s = _g(res, "sil_realtime", regime) or {}
        if not s:
            continue
        ct99 = _g(res, "jitter", regime, "cyclictest_p99_us")
        add(f"real-time SIL jitter {regime} p50 / p99 / max [us]",
            f"{_fmt(s.get('jitter_p50_us'))} / {_fmt(s.get('jitter_p99_us'))} / {_fmt(s.get('jitter_max_us'))}",
            f"cyclictest p99 {_fmt(ct99)}", f"{_fmt(_ratio(s.get('jitter_p99_us'), ct99))}x (p99)",
            f"p99 <= {mult:g}x cyclictest" + (", max <= 1000 us" if regime == "idle" else ""),
            _all(_le(s.get("jitter_p99_us"), None if ct99 is None else mult * ct99),
                 _le(s.get("jitter_max_us"), 1000.0) if regime == "idle" else True))
        add(f"real-time SIL cycle slips {regime} ({_fmt(s.get('duration_s'))} s)", _fmt(s.get("slips")), "", "",
            "0", None if s.get("slips") is None else s.get("slips") == 0)
        udp = _g(res, "latency", "udp_p99_us")
        add(f"sensor-to-actuator latency {regime} p50 / p99 [us]",
            f"{_fmt(s.get('latency_p50_us'))} / {_fmt(s.get('latency_p99_us'))}",
            f"UDP round trip p99 {_fmt(udp)}", f"{_fmt(_ratio(s.get('latency_p99_us'), udp))}x (p99)",
            "p99 <= 1000 us", _le(s.get("latency_p99_us"), 1000.0))
    s = _g(res, "sil_realtime", "idle_standard_transport") or {}
    if s:
        add("sensor-to-actuator latency idle, --no-zenoh-lowlatency p50 / p99 [us]",
            f"{_fmt(s.get('latency_p50_us'))} / {_fmt(s.get('latency_p99_us'))}",
            f"low-latency transport p99 {_fmt(_g(res, 'sil_realtime', 'idle', 'latency_p99_us'))}",
            f"{_fmt(_ratio(s.get('latency_p99_us'), _g(res, 'sil_realtime', 'idle', 'latency_p99_us')))}x (p99)",
            "", NO_TARGET)
    sr = res.get("sil_router") or {}
    if sr:
        add(f"sensor-to-actuator latency through the router, mutual TLS ({_fmt(_g(sr, 'router_tls', 'duration_s'))} s)"
            " p50 / p99 [us]", f"{_fmt(sr.get('p50_us'))} / {_fmt(sr.get('p99_us'))}",
            f"peer to peer {_fmt(sr.get('baseline_p50_us'))} / {_fmt(sr.get('baseline_p99_us'))}",
            f"{_fmt(_ratio(sr.get('p99_us'), sr.get('baseline_p99_us')))}x (p99)", "", NO_TARGET)
        add("  cycle slips through the router / peer to peer",
            f"{_fmt(_g(sr, 'router_tls', 'slips'))} / {_fmt(_g(sr, 'peer_to_peer', 'slips'))}", "", "", "0",
            None if _g(sr, "router_tls", "slips") is None else _g(sr, "router_tls", "slips") == 0)
    fl = res.get("flood") or {}
    if fl:
        rate = _g(fl, "flood", "flood", "rate_per_s")
        add(f"real-time SIL under a ground flood ({_fmt(rate)} datagrams/s): cycle compute p99 / max [us]",
            f"{_fmt(fl.get('flood_compute_p99_us'))} / {_fmt(fl.get('flood_compute_max_us'))}",
            f"quiet {_fmt(fl.get('quiet_compute_p99_us'))} / {_fmt(_g(fl, 'quiet', 'compute_max_us'))}",
            f"{_fmt(_ratio(fl.get('flood_compute_p99_us'), fl.get('quiet_compute_p99_us')))}x (p99)", "0 slips",
            None if fl.get("flood_slips") is None else fl.get("flood_slips") == 0)
        add("  ground-link task per RG2 tick under flood p99 / max [us]",
            f"{_fmt(fl.get('flood_groundlink_p99_us'))} / {_fmt(fl.get('flood_groundlink_max_us'))}",
            f"quiet {_fmt(fl.get('quiet_groundlink_p99_us'))} / {_fmt(fl.get('quiet_groundlink_max_us'))}",
            f"{_fmt(_ratio(fl.get('flood_groundlink_max_us'), 20_000.0))}x period (max)", "max < 20,000 (a period)",
            _le(fl.get("flood_groundlink_max_us"), 20_000.0))
        rc = fl.get("receive") or {}
        add("  receive work per tick, in process, flood: intake / previous path p99 [us]",
            f"{_fmt(_g(rc, 'flood_intake', 'p99_us'))} / {_fmt(_g(rc, 'flood_previous', 'p99_us'))}",
            f"quiet {_fmt(_g(rc, 'quiet', 'p99_us'))}; genuine commands through: "
            f"{_fmt(_g(rc, 'flood_intake', 'genuine_handled'))} / {_fmt(_g(rc, 'flood_previous', 'genuine_handled'))}"
            f" of {_fmt(_g(rc, 'flood_intake', 'genuine_sent'))}", "", "", NO_TARGET)
    lat = res.get("latency") or {}
    if lat:
        add("Zenoh + codec round trip p50 / p99 [us] (2 processes)",
            f"{_fmt(lat.get('zenoh_p50_us'))} / {_fmt(lat.get('zenoh_p99_us'))}",
            f"UDP {_fmt(lat.get('udp_p50_us'))} / {_fmt(lat.get('udp_p99_us'))}",
            f"{_fmt(_ratio(lat.get('zenoh_p99_us'), lat.get('udp_p99_us')))}x (p99)", "", NO_TARGET)
    sl = res.get("sil_lockstep") or {}
    if sl:
        add("lockstep SIL real-time factor (multi-process, Zenoh)", f"{_fmt(sl.get('realtime_factor'))}x",
            f"simulated {_fmt(sl.get('baseline_simulated_s'))} s", "", ">= 20x", _ge(sl.get("realtime_factor"), 20.0))
    b = res.get("batch") or {}
    if b:
        add("batch real-time factor (one process)", f"{_fmt(b.get('realtime_factor'))}x",
            f"simulated {_fmt(b.get('baseline_simulated_s'))} s in {_fmt(b.get('wall_s'))} s", "", ">= 200x",
            _ge(b.get("realtime_factor"), 200.0))
    gd = res.get("guidance") or {}
    if gd:
        es = gd.get("entry_state") or {}
        add("guidance cycle (npc) in flight p50 / p99 / max [us]",
            f"{_fmt(gd.get('p50_us'))} / {_fmt(gd.get('p99_us'))} / {_fmt(gd.get('max_us'))}",
            f"control cycle p99 {_fmt(gd.get('baseline_control_p99_us'))}", "", "p99 <= 20000 us",
            _le(gd.get("p99_us"), 20_000.0))
        add("  guidance cycle from entry interface, cold p50 / p99 [us]",
            f"{_fmt(es.get('p50_us'))} / {_fmt(es.get('p99_us'))}",
            f"{_fmt(es.get('predictions_mean'))} predictions", "", "", NO_TARGET)
    p = res.get("plant") or {}
    if p:
        per = p.get("baseline_control_period_us")
        add("plant cost per control period p50 / p99 [us]", f"{_fmt(p.get('step_p50_us'))} / {_fmt(p.get('step_p99_us'))}",
            f"period {_fmt(per)}", f"{_fmt(_ratio(p.get('step_p99_us'), per))} of period", "", NO_TARGET)
        add("plant open-loop entry real-time factor", f"{_fmt(p.get('entry_real_time_factor'))}x",
            f"simulated {_fmt(p.get('baseline_entry_simulated_s'))} s", "", "", NO_TARGET)
    br = res.get("bridge") or {}
    if br:
        # memory flat: RSS slope over the second half of the file-sink run (ellipsled/bench/bridge.py);
        # when only the total growth is known, that total is held to the same bound
        mem_max = (br.get("targets") or {}).get("mem_mb_per_10k_steps_max", 1.0)
        slope = br.get("mem_slope_second_half_mb_per_10k_steps")
        mem_ok = _le(slope if slope is not None else br.get("mem_growth_mb"), mem_max)
        half = br.get("mem_growth_second_half_mb")
        web = br.get("mem_growth_with_grpc_server_mb")
        add("Rerun bridge at 50 Hz: CPU [% of a core] / RSS growth [MB]",
            f"{_fmt(br.get('cpu_pct'))} / {_fmt(br.get('mem_growth_mb'))}"
            + (f" (second half {_fmt(half)}, {_fmt(slope)} MB per 10k steps)" if half is not None else ""),
            f"per-signal rr.log {_fmt(br.get('baseline_per_signal_us_per_frame'))} us/frame vs batched "
            f"{_fmt(br.get('batched_us_per_frame'))}"
            + (f"; with the gRPC server sink {_fmt(web)} MB (history kept up to its memory limit)"
               if web is not None else ""),
            f"{_fmt(br.get('speedup_batched_vs_per_signal'))}x",
            f"<= 5 %, memory flat (<= {_fmt(mem_max)} MB per 10k steps, file sink)",
            _all(_le(br.get("cpu_pct"), 5.0), mem_ok))
    cd = res.get("codec") or {}
    if cd:
        s_, j_ = cd.get("sensors") or {}, cd.get("jets") or {}
        add("codec SENSORS encode / decode p50 [us]", f"{_fmt(s_.get('encode_p50_us'))} / {_fmt(s_.get('decode_p50_us'))}",
            f"bytes() {_fmt(s_.get('baseline_bytes_p50_us'))} / frombuffer {_fmt(s_.get('baseline_frombuffer_p50_us'))}",
            "", "", NO_TARGET)
        add("codec JETS encode / decode p50 [us]", f"{_fmt(j_.get('encode_p50_us'))} / {_fmt(j_.get('decode_p50_us'))}",
            f"bytes() {_fmt(j_.get('baseline_bytes_p50_us'))} / frombuffer {_fmt(j_.get('baseline_frombuffer_p50_us'))}",
            "", "", NO_TARGET)
    gl = res.get("groundlink") or {}
    if gl:
        add("ground link tick at 10 Hz p50 / p99 [us]",
            f"{_fmt(_g(gl, 'rg2_tick_10Hz', 'p50_us'))} / {_fmt(gl.get('tick_p99_us'))}",
            f"control step p99 {_fmt(gl.get('baseline_control_step_p99_us'))}",
            f"{_fmt(gl.get('tick_p99_over_control_p99'))}x", "", NO_TARGET)
    rt = res.get("rt") or {}
    if rt:
        th = rt.get("threads") or {}
        add("real-time hygiene (jitter loop)",
            f"SCHED_FIFO {_fmt(rt.get('sched_fifo'))} prio {_fmt(rt.get('priority'))}, CPUs {rt.get('affinity')}, "
            f"mlockall {_fmt(rt.get('mlockall'))}, GC off in cycle {_fmt(rt.get('gc_disabled_in_cycle'))}, "
            f"threads {_fmt(th.get('process_threads'))} (numba {_fmt(th.get('numba_threads'))})",
            "", "", "used when permitted", NO_TARGET)
    return R


def table(res: dict) -> str:
    m = res.get("machine") or {}
    head = (f"Benchmark ({'quick' if res.get('quick') else 'full'}) on {m.get('nproc')} CPUs "
            f"({m.get('cpu')}), load {', '.join(f'{x:.2f}' for x in (m.get('load') or []))}, "
            f"Python {m.get('python')}, {m.get('time_utc')}; total {_fmt(res.get('wall_s'))} s. "
            "n/m = not measured (reason in the JSON).")
    lines = [head, "", "| figure | measured | baseline (same run) | ratio | target | verdict |",
             "|---|---|---|---|---|---|"]
    for r in rows(res):
        lines.append("| " + " | ".join(x.replace("|", "/") for x in r) + " |")
    reasons = []

    def walk(d, path):
        for k, v in d.items():
            if isinstance(v, dict) and k not in ("detail", "loop", "extra", "cyclictest"):
                walk(v, f"{path}.{k}" if path else k)
            elif k.endswith("_reason") and v and k[:-7] in d:
                reasons.append(f"- `{path}.{k[:-7]}`: {v}")
    walk({k: v for k, v in res.items() if isinstance(v, dict)}, "")
    if reasons:
        lines += ["", "Not measured:", *reasons]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- command line
def add_bench_parser(subparsers) -> None:
    """``ellipsled bench [--quick] --out FILE.json [--only a,b]``."""
    p = subparsers.add_parser("bench", help="benchmark suite: every figure next to its baseline, JSON + table")
    p.add_argument("--quick", action="store_true", help="fewer samples and shorter runs (a few minutes)")
    p.add_argument("--out", default="runs/bench.json", help="JSON file; the table goes to the same name .md")
    p.add_argument("--only", default=None,
                   help=f"comma-separated sections (default all: {','.join(ORDER)})")
    p.set_defaults(func=main_args)


def main_args(a) -> int:
    out = Path(a.out)
    if out.suffix != ".json":
        raise SystemExit(f"ellipsled bench: --out must name a .json file, got {out}")
    only = [s.strip() for s in a.only.split(",") if s.strip()] if a.only else None
    try:
        res = run_suite(a.quick, out, only)
    except ValueError as e:
        print(f"ellipsled bench: {e}", file=sys.stderr)
        return 2
    md = table(res)
    out.with_suffix(".md").write_text(md)
    print(md)
    print(f"wrote {out} and {out.with_suffix('.md')}")
    return 0


def main(argv: list[str] | None = None) -> int:
    import argparse
    ap = argparse.ArgumentParser(prog="ellipsled bench", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd")
    add_bench_parser(sub)
    args = ["bench", *(sys.argv[1:] if argv is None else argv)]
    a = ap.parse_args(args)
    return int(a.func(a) or 0)
