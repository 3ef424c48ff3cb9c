"""``ellipsled bench [--quick] --out FILE.json``: every benchmark of docs/benchmarks.md
in one invocation, each figure next to its baseline measured in the same run.

Writes FILE.json (machine-readable) and FILE.md (the table, also printed). Each section
runs inside its own try/except: a failure nulls only that section's figures, each with a
``<name>_reason`` key beside it; a figure that was not measured is ``null`` with its
reason, never a made-up number. The JSON is rewritten after every section, so an
interrupted run keeps what it measured.

Sections (ellipsled/bench/<name>.py, each ``run(quick) -> dict``): machine, codec,
allocator, plant, cycle, batch, groundlink, latency, jitter, sil_lockstep, sil_realtime,
sil_router (ellipsled/bench/router.py), flood (a ground flood at the real-time SIL),
bridge, wake (what the wait between cycles does to the control task); ``rt`` (real-time hygiene) is read from the jitter loop. The real-time sections
each begin after a settle phase (settle.py: the host back at the run's start). Each
section module declares its TARGETS and builds its own table rows from them
(``rows(res)``); this module only orders them (ROWS).
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

from .rows import Row, fmt

# Figures every consumer may rely on: present in the JSON, a number or null + reason.
REQUIRED: dict[str, tuple[str, ...]] = {
    "machine": ("nproc", "load", "python", "versions", "speed_bytes_p50_us", "speed_factor"),
    "codec": ("sensors_roundtrip_p99_us", "jets_roundtrip_p99_us"),
    "allocator": ("p50_us", "p99_us", "max_us", "flown_p50_us", "flown_p99_us", "highs_p99_us", "speedup", "mismatches"),
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
    "sil_realtime.footprint": ("fsw_rss_mb", "fsw_unlocked_rss_mb", "fsw_locked_mb", "sim_rss_mb",
                               "sim_unlocked_rss_mb", "sim_locked_mb"),
    "sil_router": ("p50_us", "p99_us", "baseline_p50_us", "baseline_p99_us"),
    "flood": ("flood_compute_p99_us", "flood_compute_max_us", "flood_groundlink_p99_us", "flood_groundlink_max_us",
              "flood_slips", "flood_state_changes", "flood_peers_added", "flood_fdir_latency_max_s",
              "quiet_compute_p99_us", "quiet_groundlink_p99_us", "flood_listen_max_us", "flood_kernel_drops"),
    "bridge": ("cpu_pct", "mem_growth_mb"),
    "rt": ("sched_fifo", "affinity", "mlockall", "messages"),
}

ORDER = ("machine", "codec", "allocator", "reconfig", "plant", "cycle", "batch", "guidance", "groundlink", "latency",
         "jitter", "wake", "sil_lockstep", "sil_realtime", "sil_router", "flood", "bridge")


# --------------------------------------------------------------------------- sections
# Machine speed: bytes() of a SENSORS record -- a copy behind one Python call, so it tracks
# what the FSW's Python hot paths get from this CPU now, contention included. Its p50 on the
# reference machine (docs/benchmarks.md; its codec baseline) is the reference; speed_factor =
# this run's p50 / that. Absolute targets are also judged on figures scaled by it (rows.py).
REFERENCE_BYTES_P50_US = 2.05


def machine_speed_us(n: int) -> float:
    """p50 [us] of bytes() of a SENSORS record over ``n`` calls, after a short warm-up."""
    import numpy as np

    from interfaces import records
    rec = records.new(records.SENSORS)
    clock = time.perf_counter_ns
    t = np.empty(n, np.int64)
    for _ in range(200):
        bytes(rec)
    for i in range(n):
        t0 = clock()
        bytes(rec)
        t[i] = clock() - t0
    return float(np.percentile(t, 50)) * 1e-3


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
    speed_us = machine_speed_us(2_000 if quick else 20_000)
    return {"speed_bytes_p50_us": speed_us, "speed_factor": speed_us / REFERENCE_BYTES_P50_US,
            "speed_reference": f"bytes() of a SENSORS record, p50 {REFERENCE_BYTES_P50_US} us on the machine "
                               "of reference (docs/benchmarks.md)",
            "nproc": os.cpu_count(), "affinity": affinity, "load": list(os.getloadavg()),
            "python": sys.version.split()[0], "implementation": platform.python_implementation(),
            "kernel": platform.release(), "cpu": cpu, "versions": versions,
            "euid": os.geteuid(), "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def _lazy(module: str, fn: str = "run") -> Callable[[bool], dict]:
    """A section that imports its module only when it runs (the CLI stays light)."""
    def section(quick: bool) -> dict:
        import importlib
        return getattr(importlib.import_module(f"{__package__}.{module}"), fn)(quick)
    section.__name__ = f"{module}.{fn}"
    return section


# latency: the SIL's sensor-to-actuator figures are merged in afterwards (_derive)
SECTIONS: dict[str, Callable[[bool], dict]] = {
    "machine": machine, "codec": _lazy("codec"), "allocator": _lazy("allocator"), "reconfig": _lazy("reconfig"),
    "plant": _lazy("plant"), "cycle": _lazy("cycle"), "batch": _lazy("batch"), "guidance": _lazy("guidance"),
    "groundlink": _lazy("groundlink"),
    "latency": _lazy("latency"), "jitter": _lazy("jitter"), "wake": _lazy("wake"), "sil_lockstep": _lazy("sil", "lockstep"),
    "sil_realtime": _lazy("sil", "realtime"), "sil_router": _lazy("router"), "flood": _lazy("flood"),
    "bridge": _lazy("bridge", "section"),
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
              say: Callable[[str], None] = print, probe: Callable[[], float] | None = None) -> dict:
    """Run ``sections`` (default: every one, in ORDER), the real-time ones
    (settle.REALTIME_SECTIONS) each after a settle phase against the host's state at the
    start of the run (settle.py; ``probe``: its machine-speed probe, tests pass their own)."""
    from . import settle
    sections = SECTIONS if sections is None else sections
    names = [n for n in (ORDER if sections is SECTIONS else list(sections)) if only is None or n in only]
    if only is not None:
        unknown = sorted(set(only) - set(sections))
        if unknown:
            raise ValueError(f"bench: unknown section(s) {', '.join(unknown)} (known: {', '.join(sections)})")
    res: dict = {"quick": bool(quick), "sections": names}
    t0 = time.perf_counter()
    probe = probe or settle.probe_us
    if any(n in settle.REALTIME_SECTIONS for n in names):
        res["settle_baseline"] = settle.baseline(probe)
    for name in names:
        st = None
        if name in settle.REALTIME_SECTIONS:
            st = settle.settle(res["settle_baseline"]["probe_us"], settle.MAX_WAIT_S[bool(quick)], probe)
            say(f"bench: host {'settled' if st['settled'] else 'NOT settled'} after {st['waited_s']:.1f} s "
                f"(probe {st['last_over_baseline']:.2f}x the run's start)")
        say(f"bench: {name} ...")
        ticks = settle.cpu_ticks()
        res[name] = run_section(name, sections[name], quick)
        if st is not None:
            res[name]["settle"] = {**st, "steal_share_in_section": settle.steal_share(ticks, settle.cpu_ticks())}
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
# The table's rows, in order: each section module builds its own against the targets it
# declares (ellipsled/bench/rows.py); imported only when a table is made.
ROWS = (("allocator", "rows"), ("reconfig", "rows"), ("cycle", "rows"), ("jitter", "rows"), ("sil", "realtime_rows"), ("wake", "rows"), ("router", "rows"),
        ("flood", "rows"), ("latency", "rows"), ("sil", "lockstep_rows"), ("batch", "rows"), ("guidance", "rows"), ("plant", "rows"),
        ("bridge", "rows"), ("codec", "rows"), ("groundlink", "rows"), ("jitter", "rt_rows"), ("settle", "rows"))


def rows(res: dict) -> list[Row]:
    """(figure, measured, baseline, ratio, target, verdict) rows of the table."""
    import importlib
    out: list[Row] = []
    for module, fn in ROWS:
        out += getattr(importlib.import_module(f"{__package__}.{module}"), fn)(res)
    return out


def table(res: dict) -> str:
    m = res.get("machine") or {}
    head = (f"Benchmark ({'quick' if res.get('quick') else 'full'}) on {m.get('nproc')} CPUs "
            f"({m.get('cpu')}), load {', '.join(f'{x:.2f}' for x in (m.get('load') or []))}, "
            f"Python {m.get('python')}, {m.get('time_utc')}; total {fmt(res.get('wall_s'))} s. "
            f"Machine speed: bytes() of a SENSORS record p50 {fmt(m.get('speed_bytes_p50_us'))} us, "
            f"x{fmt(m.get('speed_factor'))} the reference machine's ({REFERENCE_BYTES_P50_US} us); absolute "
            "targets are judged as measured and at that machine's speed, the verdict names which failed. "
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
