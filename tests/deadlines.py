"""What a real-time run's cycle slips say (fsw.json, executive slip records).

A shared 2-vCPU virtual machine stalls its guest now and then for a few to ~20 ms, even a
bare SCHED_FIFO sleeper (seen on the machines here: 6.4 ms max over 40 s at load 4.7).
Tests of the FSW's deadlines therefore ask which slips the FSW's own work caused."""
from __future__ import annotations


def own_overruns(fsw: dict, period_us: float = 20_000.0) -> list[dict]:
    """The slip records not explained by a late release: the cycle overran by its own
    tasks, or its tasks took half the period or more. Every slip must be recorded (the
    executive keeps the first 32), else every record counts."""
    records = fsw["executive"].get("slip_records", [])
    if len(records) != min(fsw["cycle_slips"], 32):
        return records or [{"cause": "unrecorded", "slips": fsw["cycle_slips"]}]
    return [r for r in records
            if r["cause"] != "late_release" or sum(r["tasks_us"].values()) >= 0.5 * period_us]
