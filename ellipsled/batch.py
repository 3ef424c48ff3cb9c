"""The batch runner: one scenario flown in lockstep in one process (ellipsled/lockstep.py),
judged like a SIL run (ellipsled/runlib.py) against its fault-free twin (ellipsled/reference.py).
"""
from __future__ import annotations

import json
from pathlib import Path

from common.model import Scenario
from fsw.flightsoftware import FlightSoftware

from .lockstep import fly
from .reference import fault_free_reference
from .runlib import exit_code, format_summary, judge
from .sil.fsw_report import fsw_report
from .sil.history import History
from .sil.variant import end_reason_of, prepare, prepare_args
from .terminal import RunProgress, files_written


def run(scenario: Scenario | str, seed: int | None = None, ft_off: bool = False, duration_s: float | None = None,
        verify_every: int = 1000, reference: bool = True, reference_cache: str | Path | None = None,
        identification: str | None = None, initial_error: bool = True,
        on_progress=None, dt_control_s: float | None = None) -> tuple[dict, History, FlightSoftware]:
    """Fly one scenario; returns (summary, history, fsw). ``reference``: also fly (or take
    from ``reference_cache``, default the user cache) the fault-free twin for the
    fault-attributable figures. ``identification``, ``initial_error`` and ``dt_control_s``: see prepare().
    ``on_progress(t_s)`` is called every lockstep.PROGRESS_EVERY steps with the simulated time reached."""
    scn = prepare(scenario, ft_off, duration_s, identification, initial_error, dt_control_s)
    seed = scn.seed if seed is None else seed
    f = fly(scn, seed, verify_every, on_progress)
    h, fsw, wall = f.history, f.fsw, f.wall_s
    rep = fsw_report(fsw, f.slips, f.alloc_samples)
    ref = fault_free_reference(h, scn, seed, f.fault_log, reference_cache) if reference else None
    summary = judge(h, scn, seed, end_reason_of(f.end_reason, duration_s), rep, f.fault_log, fsw.params, ref,
                    deploy=f.deploy)
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
