"""The batch runner: plant and flight software in one process, stepped in lockstep.

No transport: the plant's SENSORS record goes straight to the FSW topology (the same
rate groups the SIL FSW process runs) and the jet command straight back.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

from common.events import EventLog
from common.model import Scenario
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware
from fsw.topology import Topology
from interfaces import records
from interfaces.vocabulary import FAULT_HEALTH, MARK_NAMES, NOMINAL
from sim.plant import Plant

from .history import History, record_fsw, record_truth
from .runlib import (alloc_sample, end_reason_of, exit_code, fault_free_reference, format_summary, fsw_report, judge,
                     prepare, prepare_args)
from .terminal import RunProgress, files_written


def tell_faults(fsw: FlightSoftware, fault_log: list, start: int, eta_of) -> int:
    """Oracle identification (a test mode): hand FDIR the plant's fault-log entries from
    ``start`` on, each at the time the plant applied it; returns the new count told.
    ``eta_of[jet - 1]``: the thrust factor the plant gave a degraded jet."""
    for t, jet, kind in fault_log[start:]:
        fsw.fdir.identified(float(t), int(jet), MARK_NAMES[FAULT_HEALTH.get(kind, NOMINAL)], float(eta_of[jet - 1]))
    return len(fault_log)


PROGRESS_EVERY = 50       # steps between progress reports (1 s of simulated time at 50 Hz)


def run(scenario: Scenario | str, seed: int | None = None, ft_off: bool = False, duration_s: float | None = None,
        verify_every: int = 1000, reference: bool = True, reference_cache: str | Path | None = None,
        identification: str | None = None, initial_error: bool = True,
        on_progress=None) -> tuple[dict, History, FlightSoftware]:
    """Fly one scenario; returns (summary, history, fsw). ``reference``: also fly (or take
    from ``reference_cache``, default the user cache) the fault-free twin for the
    fault-attributable figures. ``identification`` and ``initial_error``: see prepare().
    ``on_progress(t_s)`` is called every PROGRESS_EVERY steps with the simulated time reached."""
    scn = prepare(scenario, ft_off, duration_s, identification, initial_error)
    seed = scn.seed if seed is None else seed
    plant = Plant(scn, seed)
    fsw = FlightSoftware(scn, EventLog())
    topo = Topology(fsw, LockstepClock())
    topo.warm_up(plant.sensors)
    h = History(int(math.ceil(scn.max_duration_s / scn.dt_control_s)) + 2)
    samples = []
    frame = plant.sensors
    trec = records.new(records.TRUTH)     # refilled in place every step
    told = 0                              # oracle mode: fault-log entries handed to FDIR so far
    wall0 = time.perf_counter()
    while True:
        if fsw.fdir.oracle and len(plant.fault_log) > told:
            told = tell_faults(fsw, plant.fault_log, told, plant.fault_eta)
        topo.tick(frame)
        u = topo.u
        if verify_every and plant.k % verify_every == 0:
            samples.append(alloc_sample(fsw))
        if on_progress is not None and plant.k % PROGRESS_EVERY == 0:
            on_progress(plant.t_s)
        i = h.row()
        record_truth(h, i, plant.fill_truth(trec))
        record_fsw(h, i, fsw, u, topo.last_compute_ns)
        done, reason = plant.done()
        if done:
            break
        frame = plant.step(u)
    wall = time.perf_counter() - wall0
    fsw.close()
    rep = fsw_report(fsw, topo.executive.slips, samples)
    ref = fault_free_reference(h, scn, seed, plant.fault_log, reference_cache) if reference else None
    summary = judge(h, scn, seed, end_reason_of(reason, duration_s), rep, plant.fault_log, fsw.params, ref)
    summary["wall_s"] = wall
    summary["realtime_factor"] = (float(h["t_s"][-1]) / wall) if wall > 0 else None
    return summary, h, fsw


def write_outputs(summary: dict, h: History, out: Path, plots: bool = True) -> None:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    h.save(out / "history.npz")
    if plots:
        from .plots import plot_run
        plot_run(h, out, summary["scenario"])


def main(args) -> int:
    scn = prepare_args(args)
    with RunProgress(f"{scn.name} batch", scn.max_duration_s) as bar:
        summary, h, fsw = run(scn, seed=args.seed, duration_s=args.duration, on_progress=bar.update)
    write_outputs(summary, h, Path(args.out), plots=not args.no_plots)
    if getattr(args, "rrd", False):
        from gse.viz import record_history
        print(f"wrote {record_history(h, fsw.events.history, Path(args.out) / 'run.rrd')}")
    print(format_summary(summary))
    print(files_written(Path(args.out)))
    return exit_code(summary["end_reason"])
