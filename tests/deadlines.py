"""What a real-time run's cycle slips say (fsw.json, executive slip records).

A shared 2-vCPU virtual machine stalls its guest now and then for a few to ~20 ms, even a
bare SCHED_FIFO sleeper (seen on the machines here: 6.4 ms max over 40 s at load 4.7).
Tests of the FSW's deadlines therefore ask which slips the FSW's own work caused."""
from __future__ import annotations

from fsw.executive import own_slips


def own_overruns(fsw: dict, period_us: float = 20_000.0, last_k: int | None = None) -> list[dict]:
    """The slip records not explained by a late release (fsw.executive.own_slips: the cycle
    overran by its own tasks, or its tasks took half the period or more), up to the plant's
    last step ``last_k`` if given. Every slip must be recorded (the executive keeps the first
    32), else every record counts."""
    records = fsw["executive"].get("slip_records", [])
    if len(records) != min(fsw["cycle_slips"], 32):
        return records or [{"cause": "unrecorded", "slips": fsw["cycle_slips"]}]
    return own_slips(records, period_us, last_k)
