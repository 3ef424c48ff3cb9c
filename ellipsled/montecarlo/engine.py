"""Running a campaign on Dask distributed: one task per run, rows recorded as they finish.

The client draws every run (``campaign.draw_run``), ships the dispersed Scenario itself
(workers need the installed package, not the data files), and keeps a bounded window of
tasks in flight. Finished rows are buffered and appended to the result store at least
every ``flush_s`` seconds; a resumed campaign skips every run_id already recorded.

- embedded cluster (default): LocalCluster of worker processes, one thread each, every
  listener on 127.0.0.1, dashboard off unless asked (then 127.0.0.1, random port);
- ``scheduler="tcp://host:8786"``: an existing cluster, used unchanged.

A run that raises is a row with status "failed" and its error; a worker that dies
mid-run has its task re-run elsewhere by the scheduler (``distributed.scheduler.
allowed-failures``); a task the scheduler gives up on is recorded failed as well.
"""
from __future__ import annotations

import json
import logging
import math
import os
import shutil
import signal
import socket
import sys
import threading
import time
import traceback
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import pyarrow as pa

from common.config import resolve
from common.model import INERTIA_KEYS, Scenario, load_scenario
from ellipsled.sil.history import budget_refusal

from .campaign import (AERO_KEYS, Campaign, Criteria, apply_dispersion, campaign_base, dispersion_columns, draw_run,
                       load_campaign, with_deploy_trigger)
from .store import ResultStore, flatten

META_FILE = "campaign.json"
SCENARIO_FILE = "scenario.toml"
RESULTS_DIR = "results.parquet"
FORMAT = 3      # 3: + guidance.released; 2: every part file has RECORD_SCHEMA (1: types inferred per part)

# summary.json figures that measure the machine, not the flight: not reproducible run to run.
TIMING_COLUMNS = frozenset({"wall_s", "realtime_factor", "cycle_slips", "events", "allocator.p50_us",
                            "allocator.p99_us", "allocator.max_us"})
RECORD_ONLY_COLUMNS = frozenset({"worker", "host", "pid", "run_wall_s", "run_cpu_s", "success", "failed_criteria",
                                 "traceback"})


def is_reproducible_column(name: str) -> bool:
    """True for the columns a re-run of the same record must reproduce bit for bit."""
    return not (name in TIMING_COLUMNS or name in RECORD_ONLY_COLUMNS or name.startswith("control_cycle."))


# -- the record of one run ----------------------------------------------------------------
# Every column a run's row can hold, with its type: the same schema in every part file of
# DIR/results.parquet, so pyarrow, pandas and DuckDB read the folder as one table as it is
# (a column null in one part and text in another made them refuse it). A row is the run's own
# fields (execute_run), its dispersions (campaign.dispersion_columns) and summary.json
# flattened (store.flatten: nested tables as "a.b", lists as JSON text); a column a run has no
# value for is null in its row. A row with a column not declared here is refused
# (store.check_columns): declare a new summary figure here when adding it.
_F, _I, _B, _S = pa.float64(), pa.int64(), pa.bool_(), pa.string()


def _cols(t, *names: str) -> list:
    return [(n, t) for n in names]


RECORD_SCHEMA = pa.schema(
    # the run
    [("run_id", _I), ("seed", _I), ("status", _S), ("success", _B), ("failed_criteria", _S), ("error", _S),
     ("traceback", _S), ("worker", _S), ("host", _S), ("pid", _I), ("run_wall_s", _F), ("run_cpu_s", _F)]
    # its dispersions (jet sets, eta and density waves as JSON lists)
    + _cols(_F, *(f"disp.inertia_scale_{k}" for k in INERTIA_KEYS), "disp.density_scale",
            *(f"disp.{k}_scale" for k in AERO_KEYS), "disp.bank0_err_deg", "disp.flight_path_offset_deg",
            "disp.fdir_delay_s", "disp.fault_t_s", "disp.speed_offset_mps", "disp.heading_offset_deg",
            "disp.north_offset_km", "disp.east_offset_km")
    + _cols(_S, "disp.jets_failed_off", "disp.jets_stuck_on", "disp.jets_degraded", "disp.degraded_eta",
            "disp.density_waves")
    + _cols(_I, "disp.n_failed_off", "disp.n_stuck_on", "disp.n_degraded")
    # summary.json (ellipsled/metrics.py summarize, ellipsled/runlib.py judge)
    + [("scenario", _S), ("completed", _B), ("end_reason", _S), ("nonfinite", _B), ("identification", _S),
       ("test_mode", _S)]
    + _cols(_F, "t_end_s", "bank_err_max_after_fault_deg", "bank_err_rms_deg", "bank_err_fault_attrib_max_deg",
            "bank_err_fault_attrib_t_max_s", "bank_err_max_after_transient_deg", "bank_err_rms_after_transient_deg",
            "bank_err_sched_max_after_fault_deg", "settle_time_after_reconfig_s", "settle_time_0p2deg_s",
            "settle_time_fault_attrib_0p2deg_s", "recovery_time_fault_attrib_s", "fault_t_s", "reconfig_t_s",
            "alpha_dev_max_deg", "beta_dev_max_deg", "alpha_dev_max_after_transient_deg",
            "beta_dev_max_after_transient_deg", "omega_err_max_degps", "control_effort_applied",
            "control_effort_cmd", "control_effort_undeliverable_share", "adaptive_param_drift_last20pct",
            "h_end_m", "mach_end", "qbar_max_pa", "propellant_kg", "wall_s", "realtime_factor")
    + _cols(_S, "reversals", "theta_hat_final", "adaptive.names", "adaptive.final", "adaptive.drift_last20pct",
            "adaptive.truth", "adaptive.rel_err", "jet_pulses_per_jet", "fdir.detections", "fdir.missed")
    + _cols(_I, "jet_pulses", "cycle_slips", "events", "fdir.false_alarms")
    + _cols(_F, "control_cycle.compute_p50_us", "control_cycle.compute_p99_us", "control_cycle.compute_max_us")
    + [("control_cycle.compute_overruns", _I)]
    + _cols(_I, "allocator.solves", "allocator.degraded", "allocator.short", "allocator.modulated",
            "allocator.optimality_checked")
    + _cols(_F, "allocator.p50_us", "allocator.p99_us", "allocator.max_us", "allocator.optimality_gap_max")
    + [("allocator.box", _S), ("controllability.controllable", _B), ("controllability.reason", _S)]
    + _cols(_F, "controllability.authority_pos_degps2", "controllability.authority_neg_degps2",
            "controllability.need_degps2", "controllability.bias_Nm", "controllability.residual_Nm",
            "controllability.trim_needed_deg", "controllability.qbar_min_pa")
    # guided entries (deploy figures, the predictor-corrector's statistics)
    + _cols(_F, "deploy_miss_km", "deploy_alt_km", "downrange_err_km", "crossrange_err_km", "peak_heat_rate_wcm2",
            "peak_load_g", "gamma_positive_max_alt_km", "limits.load_g", "limits.heat_rate_wcm2")
    + [("skip", _B), ("guidance_mode", _S), ("reversal_count", _I)]
    + _cols(_I, "guidance.released", "guidance.cycles", "guidance.predictions_per_cycle_max", "guidance.no_root", "guidance.floor_cycles",
            "guidance.held_cycles", "guidance.overruns", "guidance.faults")
    + _cols(_F, "guidance.compute_p50_us", "guidance.compute_p99_us", "guidance.compute_max_us",
            "guidance.predictions_per_cycle_mean", "guidance.k_rho_final", "guidance.k_ld_final",
            "guidance.bank0_final_deg", "guidance.floor_margin_final_m")
    + _cols(_S, "guidance.reversal_times_s", "guidance.reversal_rules")
    # the parachute deploy of a run whose FSW deploys (runlib.deploy_summary)
    + [("deploy.rule", _S), ("deploy.ok", _B), ("deploy.by", _S), ("deploy.edge", _S),
       ("deploy.refused_outside_box", _I)]
    + _cols(_F, "deploy.mach", "deploy.qbar_pa", "deploy.alt_km"))


@dataclass(frozen=True)
class RunTask:
    run_id: int
    seed: int
    disp: dict
    scenario: Scenario
    duration_s: float | None
    criteria: Criteria


_warm = False


def _warm_up(scn: Scenario) -> None:
    """First run in a process: load the numba caches and lazy imports outside a timed
    cycle (else the first control cycle of the first run is a cycle slip)."""
    global _warm
    if not _warm:
        from ellipsled.batch import run
        run(scn.with_(faults=()), seed=0, duration_s=0.2, verify_every=0)
        _warm = True


def execute_run(task: RunTask) -> dict:
    """One row: fly the dispersed scenario; never raises for the run's own errors."""
    from ellipsled.batch import run
    t0, c0 = time.perf_counter(), time.process_time()
    row = {"run_id": task.run_id, "seed": task.seed, "status": "ok", "success": None,
           "failed_criteria": None, "error": None}
    row.update(dispersion_columns(task.disp))
    try:
        _warm_up(task.scenario)
        summary, _, _ = run(task.scenario, seed=task.seed, duration_s=task.duration_s)
        fails = task.criteria.failures(summary)
        row["success"] = not fails
        row["failed_criteria"] = ",".join(fails) or None
        figures = flatten(summary)
        figures.pop("seed", None)
        row.update(figures)
    except Exception as e:   # the run's own failure is a result, recorded with its seed
        row.update(status="failed", success=False, failed_criteria="raised", error=f"{type(e).__name__}: {e}",
                   traceback="".join(traceback.format_exception(e))[-4000:])
    row["worker"] = _worker_address()
    row["host"] = socket.gethostname()
    row["pid"] = os.getpid()
    row["run_wall_s"] = time.perf_counter() - t0
    row["run_cpu_s"] = time.process_time() - c0    # < run_wall_s: the core was shared
    return row


def _worker_address() -> str | None:
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return None


# -- the campaign folder --------------------------------------------------------------

def prepare_out(out: Path, camp: Campaign, master_seed: int, duration_s: float | None) -> Scenario:
    """Create DIR (campaign.json, a snapshot of the base scenario) or check that an
    existing DIR holds the same campaign; returns the base scenario of the snapshot."""
    out.mkdir(parents=True, exist_ok=True)
    meta = {"format": FORMAT, "campaign": camp.record(), "campaign_file": camp.file,
            "master_seed": int(master_seed), "duration_s": duration_s, "scenario_file": SCENARIO_FILE}
    path = out / META_FILE
    if path.exists():
        old = json.loads(path.read_text())
        if old.get("format") != FORMAT:
            raise ValueError(f"{out}: holds results of format {old.get('format')!r}, this version writes format "
                             f"{FORMAT} (one schema for every part file); choose another --out")
        for key in ("master_seed", "duration_s"):
            if old.get(key) != meta[key]:
                raise ValueError(f"{out}: holds a campaign with {key} = {old.get(key)!r}, not {meta[key]!r}; "
                                 "resume with the same settings or choose another --out")
        for key, v in meta["campaign"].items():
            if key not in ("runs", "description") and old["campaign"].get(key) != v:
                raise ValueError(f"{out}: holds a campaign whose {key} differs from {camp.file}; "
                                 "resume with the same campaign file or choose another --out")
    else:
        shutil.copyfile(resolve("scenarios", camp.scenario), out / SCENARIO_FILE)
        tmp = out / f".{META_FILE}.tmp"
        tmp.write_text(json.dumps(meta, indent=2) + "\n")
        os.replace(tmp, path)
    return campaign_base(meta["campaign"], load_scenario(out / SCENARIO_FILE))


def read_meta(out: Path) -> dict:
    path = Path(out) / META_FILE
    if not path.exists():
        raise ValueError(f"{out}: not a campaign folder (no {META_FILE})")
    return json.loads(path.read_text())


def make_task(camp: Campaign, base: Scenario, run_id: int, master_seed: int, duration_s: float | None) -> RunTask:
    seed, disp = draw_run(camp, base, run_id, master_seed)
    scn = apply_dispersion(base, disp, seed, f"{camp.name}-{run_id}")
    return RunTask(run_id, seed, disp, scn, duration_s, camp.success)


# -- progress -------------------------------------------------------------------------

class Progress:
    """Runs done, failures, rate and time left: tqdm when installed, else a plain line."""

    def __init__(self, total: int, already: int, enabled: bool = True, stream=sys.stderr):
        self.total, self.done, self.failed, self.enabled, self.stream = total, already, 0, enabled, stream
        self.new = 0
        self.t0 = time.monotonic()
        self._last = 0.0
        self._bar = None
        if enabled:
            try:
                from tqdm import tqdm
                self._bar = tqdm(total=total, initial=already, unit="run", file=stream)
            except ImportError:
                pass

    def eta_s(self) -> float | None:
        el = time.monotonic() - self.t0
        return (self.total - self.done) * el / self.new if self.new else None

    def line(self) -> str:
        el = time.monotonic() - self.t0
        rate = 60.0 * self.new / el if el > 0 else 0.0
        eta = self.eta_s()
        eta_txt = "--" if eta is None else f"{int(eta // 60)}m{int(eta % 60):02d}s"
        return f"{self.done}/{self.total} runs, {self.failed} failed, {rate:.1f} runs/min, ETA {eta_txt}"

    def update(self, row: dict) -> None:
        self.done += 1
        self.new += 1
        self.failed += row.get("status") != "ok"
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.set_postfix(failed=self.failed)
            self._bar.update(1)
            return
        now = time.monotonic()
        tty = self.stream.isatty()
        if tty or now - self._last >= 5.0 or self.done == self.total:
            self._last = now
            print(("\r" if tty else "") + self.line(), end="" if tty else "\n", file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
        elif self.enabled and self.stream.isatty():
            print(file=self.stream)


# -- the cluster ----------------------------------------------------------------------

class _IgnoreSigint:
    """Worker plugin of the embedded cluster: a terminal Ctrl-C reaches the whole process
    group; only the client must act on it (cancel, record, close the cluster)."""
    name = "ellipsled-ignore-sigint"

    def setup(self, worker):
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        except ValueError:   # not the main thread of the worker process
            pass


def connect(scheduler: str | None, workers: int | None, dashboard: bool = False, security=None):
    """(client, cluster or None). ``security``: distributed.security.Security for a TLS
    scheduler."""
    from distributed import Client, LocalCluster
    from distributed.diagnostics.plugin import WorkerPlugin
    if scheduler:
        return Client(scheduler, timeout="30s", security=security), None
    n = workers or os.cpu_count() or 1
    # The scheduler always serves HTTP (health, metrics): a random loopback port, the
    # dashboard pages only when asked for.
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1",
                           scheduler_kwargs={"dashboard": bool(dashboard), "dashboard_address": "127.0.0.1:0"},
                           silence_logs=logging.ERROR)
    client = Client(cluster)
    plugin = type("IgnoreSigint", (_IgnoreSigint, WorkerPlugin), {})()
    client.register_plugin(plugin, name=_IgnoreSigint.name)
    return client, cluster


@dataclass
class CampaignResult:
    out: Path
    runs: int
    recorded: int                 # rows in the store at the end
    new: int                      # rows added by this invocation
    failed_new: int
    interrupted: bool
    wall_s: float
    dashboard: str | None = None
    errors: list = field(default_factory=list)


def run_campaign(campaign: Campaign | str | Path, out: str | Path, *, runs: int | None = None,
                 master_seed: int | None = None, duration_s: float | None = None, scheduler: str | None = None,
                 workers: int | None = None, dashboard: bool = False, progress: bool = True,
                 flush_rows: int = 50, flush_s: float = 5.0, summary: bool = True,
                 on_result: Callable[[dict, object], None] | None = None, security=None,
                 deploy_trigger: str | None = None) -> CampaignResult:
    """Run (or resume) a campaign into ``out``. ``on_result(row, client)`` is called in
    the client after each finished run (tests use it to kill a worker or interrupt).
    ``deploy_trigger``: every run's FSW deploys by this rule (range | velocity), recorded with
    the campaign (default: the campaign's, else the FSW's)."""
    camp = campaign if isinstance(campaign, Campaign) else load_campaign(campaign)
    if deploy_trigger is not None:
        camp = with_deploy_trigger(camp, deploy_trigger)
    runs = camp.runs if runs is None else runs
    master_seed = camp.master_seed if master_seed is None else master_seed
    for name, v, lo in (("runs", runs, 1), ("master_seed", master_seed, 0), ("workers", workers, 1),
                        ("flush_rows", flush_rows, 1)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < lo):
            raise ValueError(f"{name} must be an integer >= {lo}, got {v!r}")
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be > 0, got {duration_s!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with _exclusive(out):
        base = prepare_out(out, camp, master_seed, duration_s)
        # each run preallocates its history: refused here, not once per run in the workers
        why = budget_refusal(base.max_duration_s if duration_s is None else duration_s, base.dt_control_s)
        if why is not None:
            raise ValueError(why)
        store = ResultStore(out / RESULTS_DIR, RECORD_SCHEMA)
        done = set(store.run_ids())
        todo = [i for i in range(runs) if i not in done]
        t_start = time.monotonic()
        res = CampaignResult(out, runs, len(done), 0, 0, False, 0.0)
        if todo:
            _execute(camp, base, todo, master_seed, duration_s, store, res, scheduler, workers, dashboard,
                     Progress(runs, len(done & set(range(runs))), progress), flush_rows, flush_s, on_result,
                     security)
        res.recorded = len(store.run_ids())
        res.wall_s = time.monotonic() - t_start
        if summary and not res.interrupted:
            from .summary import write_summary
            write_summary(out, camp, store.read(), runs)
    return res


class _exclusive:
    """One campaign process per folder (two would run the same run_ids twice). An
    advisory lock: released by the kernel if the process dies."""

    def __init__(self, out: Path):
        self.path = out / ".lock"

    def __enter__(self):
        import fcntl
        self.f = open(self.path, "a")
        try:
            fcntl.flock(self.f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.f.close()
            raise ValueError(f"{self.path.parent}: another campaign process is running in this folder") from None
        return self

    def __exit__(self, *exc):
        self.f.close()
        return False


def _execute(camp, base, todo, master_seed, duration_s, store, res, scheduler, workers, dashboard, prog,
             flush_rows, flush_s, on_result, security=None) -> None:
    from distributed import as_completed
    token = uuid.uuid4().hex[:8]
    buf: list[dict] = []
    last_flush = time.monotonic()

    def flush():
        nonlocal last_flush
        if buf:
            with _deferred_sigint():   # a part written is a part forgotten from the buffer
                store.append(buf)
                buf.clear()
        last_flush = time.monotonic()

    client = cluster = None
    pending: dict = {}
    tornado_log = logging.getLogger("tornado.application")
    tornado_log.addFilter(_interrupted_sync_cancel)
    try:
        client, cluster = connect(scheduler, workers, dashboard, security)
        res.dashboard = client.dashboard_link if dashboard else None
        queue = iter(todo)

        def submit_next(ac) -> bool:
            rid = next(queue, None)
            if rid is None:
                return False
            fut = client.submit(execute_run, make_task(camp, base, rid, master_seed, duration_s),
                                key=f"ellipsled-mc-{token}-{rid}", retries=2, pure=False)
            pending[fut.key] = (fut, rid)
            ac.add(fut)
            return True

        ac = as_completed()
        window = max(4, 4 * sum(client.nthreads().values()))
        for _ in range(window):
            if not submit_next(ac):
                break
        n_since = 0
        for fut in ac:
            _, rid = pending.pop(fut.key)
            try:
                row = fut.result()
            except Exception as e:   # the engine gave up on it (e.g. KilledWorker): still a row
                seed, disp = draw_run(camp, base, rid, master_seed)
                row = {"run_id": rid, "seed": seed, "status": "failed", "success": False,
                       "failed_criteria": "raised", "error": f"{type(e).__name__}: {e}",
                       **dispersion_columns(disp)}
            fut.release()
            store.check(row)      # a row that does not fit the schema stops the campaign here, not at a flush
            buf.append(row)
            res.new += 1
            res.failed_new += row["status"] != "ok"
            prog.update(row)
            if len(buf) >= flush_rows or time.monotonic() - last_flush >= flush_s:
                flush()
            if on_result is not None:
                on_result(row, client)
            n_since += 1
            if n_since >= 50:
                n_since = 0
                window = max(4, 4 * sum(client.nthreads().values()))
            while ac.count() < window and submit_next(ac):
                pass
    except KeyboardInterrupt:
        res.interrupted = True
    finally:
        old = _ignore_sigint()
        try:
            flush()
            prog.close()
            for fut, _ in pending.values():
                fut.cancel()
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
        finally:
            _restore_sigint(old)
            tornado_log.removeFilter(_interrupted_sync_cancel)


def _interrupted_sync_cancel(record: logging.LogRecord) -> bool:
    """False for the one traceback a Ctrl-C handled here makes Dask's event loop log: the
    client's ``sync`` answers the interruption by queueing a cancel of its call, and when the
    call has not started yet that cancel reads a variable not yet set (NameError on
    ``future``), which tornado logs as an exception in a callback. Nothing was running, so
    nothing is lost; any other record passes."""
    exc = record.exc_info[1] if record.exc_info else None
    return not (isinstance(exc, NameError) and getattr(exc, "name", None) == "future"
                and "sync.<locals>.cancel" in record.getMessage())


class _deferred_sigint:
    """Hold a Ctrl-C until the block is over, then raise it."""

    def __enter__(self):
        self.hit = False
        self.old = None
        if threading.current_thread() is threading.main_thread():
            self.old = signal.signal(signal.SIGINT, lambda *_: setattr(self, "hit", True))
        return self

    def __exit__(self, *exc):
        if self.old is not None:
            signal.signal(signal.SIGINT, self.old)
            if self.hit and exc[0] is None and self.old is not signal.SIG_IGN:
                raise KeyboardInterrupt
        return False


def _ignore_sigint():
    if threading.current_thread() is threading.main_thread():
        return signal.signal(signal.SIGINT, signal.SIG_IGN)
    return None


def _restore_sigint(old) -> None:
    if old is not None:
        signal.signal(signal.SIGINT, old)
