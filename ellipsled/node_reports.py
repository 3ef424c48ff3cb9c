"""The SIL nodes' reports read back after a run, with the timing figures the harness
computes from the raw samples the nodes saved: the plant's sensor-to-actuator latency
(sim.json + sim_latency.npz) and the FSW's release jitter and frame age (fsw.json +
fsw_timing.npz). The nodes record; the launcher and the benchmarks judge.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def _pct(x: np.ndarray, q: float) -> float | None:
    return float(np.percentile(x, q)) if len(x) else None


def _max(x: np.ndarray) -> float | None:
    return float(np.max(x)) if len(x) else None


def lp_split(control_us: np.ndarray, lp_cycle: np.ndarray) -> dict:
    """The control task's duty-cycle LP cycles (a HiGHS solve each, its dearest) apart from the
    rest: their count and the p99 [us] of the other cycles (None if none)."""
    rest = control_us[~lp_cycle]
    return {"lp_cycles": int(lp_cycle.sum()), "p99_without_lp": _pct(rest, 99)}


def by_tenth(x: np.ndarray) -> dict | None:
    """The p50 of each tenth of a run's samples, taken in run order: the lowest, the median
    and the highest of the ten (None under 100 samples). A host's slow spell shows as a
    highest tenth well above the median one; a whole run slower as all three up together."""
    if len(x) < 100:
        return None
    p50s = [_pct(part, 50) for part in np.array_split(np.asarray(x), 10)]
    return {"lowest": min(p50s), "median": float(np.median(p50s)), "highest": max(p50s)}


def latency_split(total_us: np.ndarray, command_us: np.ndarray) -> dict | None:
    """Where the sensor-to-actuator time goes: the sensor leg with the FSW's wait and
    compute (plant publishes -> FSW publishes its answer) and the command leg (FSW
    publishes -> plant has it), p50 / p99 each [us]."""
    if len(total_us) == 0:
        return None
    legs = {"sensor_and_fsw": total_us - command_us, "command": command_us}
    return {f"{name}_{q}_us": float(np.percentile(v, p)) for name, v in legs.items()
            for q, p in (("p50", 50), ("p99", 99))}


def read_sim(out: str | Path) -> dict:
    """The plant process's report (sim.json) with its real-time factor and latency figures [us]."""
    out = Path(out)
    info = json.loads((out / "sim.json").read_text())
    with np.load(out / "sim_latency.npz") as z:
        lat, cmd = z["latency_ns"] / 1e3, z["latency_cmd_ns"] / 1e3
    wall = info["wall_s"]
    info.update({
        "realtime_factor": (info["t_end_s"] / wall) if wall else None,
        "latency_p50_us": _pct(lat, 50), "latency_p99_us": _pct(lat, 99), "latency_max_us": _max(lat),
        "latency_samples": int(len(lat)),
        "latency_split_us": latency_split(lat, cmd),
    })
    return info


def read_fsw(out: str | Path) -> dict:
    """The FSW process's report (fsw.json) with its release jitter and frame age figures [us]."""
    out = Path(out)
    rep = json.loads((out / "fsw.json").read_text())
    with np.load(out / "fsw_timing.npz") as z:
        jit, age = z["jitter_ns"] / 1e3, z["frame_age_ns"] / 1e3
    rep.update({
        "jitter_p50_us": _pct(jit, 50), "jitter_p99_us": _pct(jit, 99), "jitter_max_us": _max(jit),
        "frame_age_p50_us": _pct(age, 50), "frame_age_p99_us": _pct(age, 99),
    })
    return rep
