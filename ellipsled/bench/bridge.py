"""Benchmark of the Rerun logging path of the bridge (gse/viz/logger.py).

- Logger at 50 Hz over three full entries back to back (3 x 22,500 steps; 450 s each at real
  pace; quick too): CPU seconds per logged step (truth + FSW row), reported as the share of
  one core at 50 Hz (cpu_pct = cpu_per_step x 50 x 100), and RSS over the run. Sinks: an
  .rrd file and the loopback gRPC server (no viewer connected, its memory limit applies).
- Memory is judged flat when the last entry's RSS level is at most
  ``MEM_FLAT_MB_PER_10K_STEPS`` per 10,000 steps above the entry before it (memory_verdict:
  the SDK's buffers warm over the first entry, RSS then saws up and down by a few MB). RSS
  is sampled every ``RSS_SAMPLE_STEPS`` so the shape (linear or saturating) is in the report.
  An SDK FileSink that writes a footer grows linearly (it keeps every chunk's manifest
  entry): gse/viz/sinks.py says why the live file is streamed without one.
- Baseline in the same run: one ``rr.log`` per signal per frame (the ~40 scalar signals)
  vs the batched ``send_columns`` path, per frame.
"""
from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil

from gse.viz import rerun_log  # noqa: F401, I001  (before rerun loads: its log filter, gse/viz/rerun_log.py)
import rerun as rr
from gse.viz.logger import SCALAR_CHANNELS, SOURCE_FIELDS, RerunLogger
from gse.viz.sinks import open_sinks
from interfaces.records import GUID_NPC, GUID_PREDICTION, GUID_TARGET

from .rows import Row, fmt, le, row, speed

RATE_HZ = 50.0
FULL_ENTRY_STEPS = 22_500
RSS_SAMPLE_STEPS = 100           # 225 samples per entry
MEM_FLAT_MB_PER_10K_STEPS = 1.0  # <= 2.25 MB over a full entry's 22,500 steps
ENTRIES = 3                      # entries logged back to back: the last against the one before it
TARGETS = {"cpu_pct_max": 5.0, "mem_mb_per_10k_steps_max": MEM_FLAT_MB_PER_10K_STEPS}


def memory_verdict(rss_MB: list[tuple[int, float]], entry_steps: int = FULL_ENTRY_STEPS) -> dict:
    """Whether RSS stays flat once warm: ``rss_MB`` are (step, RSS [MB]) samples of the logging
    loop, the first at step 0, over ``ENTRIES`` entries of ``entry_steps``. Each entry's level
    is the p90 of its samples (near the top of the allocator's sawtooth, not thrown by one
    spike); the growth is the last entry's level less the one before it, per 10,000 steps:
    flat when <= MEM_FLAT_MB_PER_10K_STEPS. Not a slope within one entry: the SDK's buffers
    warm over the first ~10,000 steps (~30 MB), and RSS then rises and falls by 3-5 MB over
    ~15,000 steps as pages are returned, so the second half of one entry reads 0.7-2.7 MB
    per 10k steps where three entries in a row are flat; a leak raises every entry's level."""
    a = np.asarray(rss_MB, dtype=np.float64)
    n_entries = int(a[-1, 0] // entry_steps)
    levels = [float(np.percentile(a[(a[:, 0] > j * entry_steps) & (a[:, 0] <= (j + 1) * entry_steps), 1], 90))
              for j in range(n_entries)]
    grow = levels[-1] - levels[-2] if n_entries >= 2 else None
    slope = None if grow is None else grow / entry_steps * 10_000
    return {"rss_growth_MB": float(a[-1, 1] - a[0, 1]), "rss_level_MB_by_entry": [round(float(x - a[0, 1]), 2) for x in levels],
            "rss_growth_last_entry_MB": grow, "rss_slope_MB_per_10k_steps": slope,
            "memory_flat": None if slope is None else bool(slope <= MEM_FLAT_MB_PER_10K_STEPS),
            "memory_flat_max_MB_per_10k_steps": MEM_FLAT_MB_PER_10K_STEPS}


def _rows(n: int, rng: np.random.Generator) -> tuple[list[dict], list[dict]]:
    """A pool of realistic truth / FSW rows (values vary so nothing compresses away)."""
    def one(fields, i):
        out = {}
        for f, shp in fields.items():
            if f == "guid_cycles":          # one guidance answer a second, as flown (mode npc)
                out[f] = float(i // int(RATE_HZ))
            elif f == "guid_flags":
                out[f] = float(GUID_TARGET | GUID_PREDICTION | GUID_NPC)
            elif f in ("target_lat_rad", "target_lon_rad"):      # one target per flight
                out[f] = 0.1
            elif f in ("jets_cmd",):
                out[f] = (rng.random(shp) < 0.2).astype(np.uint8)
            elif f in ("health", "mode"):
                out[f] = np.zeros(shp, dtype=np.int8) + (1 if f == "mode" else 0)
            elif f == "sigma_BN" or f == "sigma_RN":
                out[f] = 0.1 * rng.standard_normal(shp)
            elif f == "r_N":
                out[f] = 3.4e6 * np.array([1.0, 0.0, 0.0]) + 1e3 * rng.standard_normal(shp)
            else:
                out[f] = rng.standard_normal(shp) if shp else float(rng.standard_normal())
        return out
    return [one(SOURCE_FIELDS["truth"], i) for i in range(n)], [one(SOURCE_FIELDS["fsw"], i) for i in range(n)]


def _logger_run(n_steps: int, mode: str, out_dir: Path, rng) -> dict:
    proc = psutil.Process()
    sinks = open_sinks(mode, out_dir, name=f"bench-{mode.replace('+', '-')}", display=False, say=lambda m: None)
    log = RerunLogger(sinks.rec, flush_rows=50, flush_s=1.0)
    truth, fsw = _rows(256, rng)
    # warm-up (imports, first chunks), not counted
    for k in range(100):
        log.log_truth(k, k / RATE_HZ, truth[k % 256])
        log.log_fsw(k, k / RATE_HZ, fsw[k % 256])
    log.flush()
    rss_MB = [(0, proc.memory_info().rss / 2**20)]
    c0, w0 = proc.cpu_times(), time.perf_counter()
    for i in range(1, n_steps + 1):
        k = 99 + i
        log.log_truth(k, k / RATE_HZ, truth[k % 256])
        log.log_fsw(k, k / RATE_HZ, fsw[k % 256])
        if i % RSS_SAMPLE_STEPS == 0:
            rss_MB.append((i, proc.memory_info().rss / 2**20))
    log.close()
    c1, w1 = proc.cpu_times(), time.perf_counter()
    rss_closed_MB = proc.memory_info().rss / 2**20             # after the SDK's flush
    sinks.close()
    # process CPU (SDK background threads included)
    cpu_s = (c1.user - c0.user) + (c1.system - c0.system)
    per_step = cpu_s / n_steps
    return {
        "mode": mode, "steps": n_steps,
        "cpu_s": cpu_s, "wall_s": w1 - w0,
        "cpu_us_per_step": per_step * 1e6,
        "cpu_pct_at_50Hz": per_step * RATE_HZ * 100.0,
        **memory_verdict(rss_MB),
        "rss_growth_after_close_MB": rss_closed_MB - rss_MB[0][1],
        "rss_MB_by_step": [(i, round(m - rss_MB[0][1], 2)) for i, m in rss_MB[::10]],   # growth since step 0
        "send_columns_calls": log.stats["send_columns"],
        "send_columns_per_step": log.stats["send_columns"] / n_steps,
        "rrd_MB": (sinks.rrd_path.stat().st_size / 2**20) if sinks.rrd_path and sinks.rrd_path.exists() else None,
    }


def _per_signal_baseline(n_frames: int, out_dir: Path, rng) -> dict:
    """One rr.log per signal per frame, same signals as the logger's scalar channels."""
    rec = rr.RecordingStream("bench-baseline")
    rec.set_sinks(rr.FileSink(out_dir / "baseline.rrd"))
    ents = []
    for c in SCALAR_CHANNELS:
        width = 1 if c.index is not None else int(np.prod(SOURCE_FIELDS[c.source][c.field]) or 1)
        ents.append((c.entity, width))
    vals = rng.standard_normal((n_frames, 64))
    t0 = time.perf_counter()
    for k in range(n_frames):
        rec.set_time("step", sequence=k)
        rec.set_time("sim_time", duration=k / RATE_HZ)
        for e, w in ents:
            rec.log(e, rr.Scalars(vals[k, :w]))
    rec.flush()
    dt = time.perf_counter() - t0
    rec.disconnect()
    return {"signals": len(ents), "frames": n_frames, "us_per_frame": dt / n_frames * 1e6}


def _batched_frames(n_frames: int, out_dir: Path, rng) -> dict:
    rec = rr.RecordingStream("bench-batched")
    rec.set_sinks(rr.FileSink(out_dir / "batched.rrd"))
    log = RerunLogger(rec, flush_rows=50, flush_s=math.inf)
    truth, fsw = _rows(256, rng)
    for k in range(100):                        # warm-up (first-use conversions), not counted
        log.log_truth(k, k / RATE_HZ, truth[k % 256])
        log.log_fsw(k, k / RATE_HZ, fsw[k % 256])
    log.flush()
    t0 = time.perf_counter()
    for k in range(100, 100 + n_frames):
        log.log_truth(k, k / RATE_HZ, truth[k % 256])
        log.log_fsw(k, k / RATE_HZ, fsw[k % 256])
    log.close()
    dt = time.perf_counter() - t0
    rec.disconnect()
    return {"frames": n_frames, "us_per_frame": dt / n_frames * 1e6}


def run(quick: bool) -> dict:
    rng = np.random.default_rng(7)
    n_steps = ENTRIES * FULL_ENTRY_STEPS      # quick too: ~3 s of CPU per entry (memory_verdict)
    n_base = 1000 if quick else 3000
    with tempfile.TemporaryDirectory() as d:
        out = Path(d)
        file_run = _logger_run(n_steps, "file", out, rng)
        web_run = _logger_run(n_steps, "file+web", out, rng) if not quick else None
        base = _per_signal_baseline(n_base, out, rng)
        batched = _batched_frames(n_base, out, rng)
    res = {
        "rate_hz": RATE_HZ, "quick": quick,
        "logger_file": file_run,
        "per_signal_rr_log": base,
        "send_columns_batched": batched,
        "speedup_batched_vs_per_signal": base["us_per_frame"] / batched["us_per_frame"],
    }
    if web_run is not None:
        res["logger_file_and_grpc_server"] = web_run
    return res


def section(quick: bool) -> dict:
    """The suite's ``bridge`` figures: the file-sink run's, the baseline beside them, ``run``'s detail."""
    r = run(quick)
    lf = r["logger_file"]
    web = r.get("logger_file_and_grpc_server") or {}
    return {"cpu_pct": lf["cpu_pct_at_50Hz"], "mem_growth_mb": lf["rss_growth_MB"],
            "mem_level_mb_by_entry": lf["rss_level_MB_by_entry"],
            "mem_growth_last_entry_mb": lf["rss_growth_last_entry_MB"], "steps": lf["steps"],
            "mem_slope_mb_per_10k_steps": lf["rss_slope_MB_per_10k_steps"],
            "mem_growth_with_grpc_server_mb": web.get("rss_growth_MB"),
            "baseline_per_signal_us_per_frame": r["per_signal_rr_log"]["us_per_frame"],
            "batched_us_per_frame": r["send_columns_batched"]["us_per_frame"],
            "speedup_batched_vs_per_signal": r["speedup_batched_vs_per_signal"],
            "targets": dict(TARGETS), "detail": r}


def rows(res: dict) -> list[Row]:
    br = res.get("bridge") or {}
    if not br:
        return []
    # memory flat: the last entry's RSS level against the one before it (memory_verdict); when
    # only the total growth is known, that total is held to the same bound
    mem_max, cpu_max = TARGETS["mem_mb_per_10k_steps_max"], TARGETS["cpu_pct_max"]
    slope = br.get("mem_slope_mb_per_10k_steps")
    mem_ok = le(slope if slope is not None else br.get("mem_growth_mb"), mem_max)
    levels = br.get("mem_level_mb_by_entry")
    web = br.get("mem_growth_with_grpc_server_mb")
    return [row(f"Rerun bridge at 50 Hz: CPU [% of a core] / RSS growth [MB] ({ENTRIES} entries back to back)",
                f"{fmt(br.get('cpu_pct'))} / {fmt(br.get('mem_growth_mb'))}"
                + (f" (level per entry {' / '.join(fmt(x) for x in levels)}: last entry {fmt(slope)} MB per 10k "
                   "steps)" if levels else ""),
                f"per-signal rr.log {fmt(br.get('baseline_per_signal_us_per_frame'))} us/frame vs batched "
                f"{fmt(br.get('batched_us_per_frame'))}"
                + (f"; with the gRPC server sink {fmt(web)} MB (history kept up to its memory limit)"
                   if web is not None else ""),
                f"{fmt(br.get('speedup_batched_vs_per_signal'))}x",
                f"<= {cpu_max:g} %, memory flat once warm (<= {fmt(mem_max)} MB per 10k steps, file sink)",
                mem_ok, absolute=(br.get("cpu_pct"), cpu_max, "<="), machine=speed(res))]


if __name__ == "__main__":
    import json
    import sys
    print(json.dumps(run("--quick" in sys.argv), indent=2))
