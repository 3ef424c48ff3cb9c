"""Batch benchmark (docs/benchmarks.md): one process, no transport, a full nominal
entry through ``ellipsled.batch.run`` — wall time against the simulated time (real-time
factor, target ≥ 200×).

    python -m ellipsled.bench.batch [--quick]
"""
from __future__ import annotations

import sys

from ellipsled.batch import run as batch_run

from .rows import NO_TARGET, Row, fmt, row, speed

TARGETS = {"realtime_factor_min": 200.0}


def run(quick: bool) -> dict:
    """Real-time factor of the full nominal entry (the same command as ``ellipsled batch``);
    full mode also flies case 1 (faults, reconfiguration) and reports its factor."""
    batch_run("nominal", duration_s=5.0)                 # warm-up: numba cache load
    s, h, _ = batch_run("nominal")
    res = {
        "figure": "batch full entry: simulated time / wall time",
        "scenario": "nominal",
        "realtime_factor": s["realtime_factor"],
        "wall_s": s["wall_s"],
        "baseline_simulated_s": float(h["t_s"][-1]),
        "steps": int(h.n),
        "end_reason": s["end_reason"],
        "completed": s["completed"],
        "us_per_step": s["wall_s"] / h.n * 1e6,
        "control_cycle": s.get("control_cycle"),
        "targets": dict(TARGETS),
    }
    if not quick:
        s1, h1, _ = batch_run("case1")
        res["case1"] = {"realtime_factor": s1["realtime_factor"], "wall_s": s1["wall_s"],
                        "simulated_s": float(h1["t_s"][-1]), "end_reason": s1["end_reason"]}
    rtf = res["realtime_factor"]
    res["pass"] = bool(rtf is not None and rtf >= TARGETS["realtime_factor_min"])
    return res


def rows(res: dict) -> list[Row]:
    b = res.get("batch") or {}
    if not b:
        return []
    return [row("batch real-time factor (one process)", f"{fmt(b.get('realtime_factor'))}x",
                f"simulated {fmt(b.get('baseline_simulated_s'))} s in {fmt(b.get('wall_s'))} s", "",
                f">= {TARGETS['realtime_factor_min']:g}x", NO_TARGET,
                absolute=(b.get("realtime_factor"), TARGETS["realtime_factor_min"], ">="), machine=speed(res))]


if __name__ == "__main__":
    import json
    print(json.dumps(run("--quick" in sys.argv), indent=2))
