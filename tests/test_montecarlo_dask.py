"""Monte Carlo campaigns on a real local Dask cluster (2 worker processes), short runs:
expected rows, a failing run recorded, a worker killed mid-campaign, Ctrl-C and resume,
and one run reproduced from its record."""
from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from common.config import DATA_DIR
from common.model import INERTIA_KEYS
from ellipsled.batch import run as batch_run
from ellipsled.montecarlo import apply_campaign_run, load_campaign, scenario_for_run
from ellipsled.montecarlo.campaign import dispersion_columns, draw_run
from ellipsled.montecarlo.engine import _interrupted_sync_cancel, is_reproducible_column, run_campaign
from ellipsled.montecarlo.store import ResultStore, flatten

pytestmark = pytest.mark.timeout(180)

ROOT = Path(__file__).resolve().parent.parent
BREAK = 2


@pytest.fixture(scope="module")
def campaign_file(tmp_path_factory) -> Path:
    """The default campaign with faults early enough for short runs and one run that raises."""
    text = (DATA_DIR / "campaigns" / "default.toml").read_text()
    assert "t_s = [2.0, 300.0]" in text
    text = text.replace("t_s = [2.0, 300.0]", "t_s = [1.0, 3.0]") + f"\n[testing]\nbreak_runs = [{BREAK}]\n"
    p = tmp_path_factory.mktemp("camp") / "short.toml"
    p.write_text(text)
    return p


@pytest.fixture(scope="module")
def cluster():
    """An existing cluster, reached through its scheduler address (the --scheduler path;
    the embedded cluster is exercised by the Ctrl-C test, through the command line)."""
    from distributed import LocalCluster
    c = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None)
    yield c
    c.close()


@pytest.fixture(scope="module")
def finished(campaign_file, cluster, tmp_path_factory):
    """Six 6-second runs on 2 workers."""
    out = tmp_path_factory.mktemp("mc") / "c"
    res = run_campaign(campaign_file, out, runs=6, duration_s=6.0, scheduler=cluster.scheduler_address,
                       progress=False)
    return out, res


def _rows(out: Path) -> list[dict]:
    return ResultStore(out / "results.parquet").rows()


def test_campaign_writes_one_row_per_run_with_dispersions_and_figures(finished, campaign_file):
    out, res = finished
    assert (res.runs, res.recorded, res.new, res.failed_new, res.interrupted) == (6, 6, 6, 1, False)
    rows = _rows(out)
    assert [r["run_id"] for r in rows] == list(range(6))
    camp = load_campaign(campaign_file)
    from common.model import load_scenario
    base = load_scenario(out / "scenario.toml")
    for r in rows:
        seed, disp = draw_run(camp, base, r["run_id"])
        assert r["seed"] == seed
        for k, v in dispersion_columns(disp).items():
            assert r[k] == v, k
        if r["run_id"] == BREAK:
            continue
        assert r["status"] == "ok" and r["error"] is None
        assert r["completed"] is True and r["end_reason"] == "duration" and r["t_end_s"] == pytest.approx(6.0)
        assert r["fault_t_s"] == pytest.approx(disp["fault_t_s"], abs=0.02)      # applied at a control step
        assert isinstance(r["bank_err_max_after_fault_deg"], float) and isinstance(r["propellant_kg"], float)
        dets = json.loads(r["fdir.detections"])                                   # detections as JSON text
        assert isinstance(dets, list)
        assert {d["jet"] for d in dets} <= set(disp["jets_failed_off"] + disp["jets_stuck_on"] + disp["jets_degraded"]) \
            or r["fdir.false_alarms"] > 0
        assert isinstance(r["success"], bool)
    summary = (out / "summary.md").read_text()
    assert "runs recorded: 6 of 6; raised: 1; duplicates: 0" in summary
    for png in ("hist_bank_err_max_after_fault_deg.png", "hist_propellant_kg.png",
                "hist_settle_time_after_reconfig_s.png", "scatter_err_vs_fault_time.png",
                "scatter_err_vs_failed_jets.png"):
        assert (out / png).stat().st_size > 1000 and png in summary


def test_failing_run_is_recorded_failed_with_its_error(finished):
    out, _ = finished
    r = ResultStore(out / "results.parquet").row(BREAK)
    assert r["status"] == "failed" and r["success"] is False
    assert "ConfigError" in r["error"] and "fdir.delay_s" in r["error"] and "Traceback" in r["traceback"]
    assert r["seed"] > 0 and r["disp.fdir_delay_s"] == -1.0
    assert "| 2 | " in (out / "summary.md").read_text().split("## Runs that raised")[1]


def test_a_run_reproduces_its_figures_exactly_from_its_record(finished):
    out, _ = finished
    r = scenario_for_run(out, 3)
    summary, _, _ = batch_run(r.scenario, seed=r.seed, duration_s=r.duration_s)
    again = flatten(summary)
    figures = [k for k in r.record if is_reproducible_column(k) and not k.startswith("disp.")
               and k not in ("run_id", "status", "error")]
    assert len(figures) > 25 and "fdir.detections" in figures and "propellant_kg" in figures
    assert {k: r.record[k] for k in figures} == {k: again.get(k) for k in figures}
    # the batch command's bridge: args filled from the record
    a = argparse.Namespace(scenario=None, seed=None, duration=None, from_campaign=str(out), run=3)
    apply_campaign_run(a)
    assert a.seed == r.seed and a.duration == 6.0 and a.scenario.faults == r.scenario.faults
    assert list(a.scenario.truth.inertia_scale) == [r.record[f"disp.inertia_scale_{k}"] for k in INERTIA_KEYS]
    with pytest.raises(ValueError, match="no record of run 99"):
        scenario_for_run(out, 99)


def test_killing_a_worker_mid_campaign_loses_no_run(campaign_file, cluster, tmp_path):
    from distributed import Client
    killed = {}

    def kill_busy_worker(row, client):
        if killed:
            return
        busy = {w: ks for w, ks in client.processing().items() if ks}
        w, keys = next(iter(busy.items()))
        pid = client.run(os.getpid, workers=[w])[w]
        os.kill(pid, signal.SIGKILL)
        killed.update(worker=w, pid=pid, runs={int(str(k).rsplit("-", 1)[1]) for k in keys})

    out = tmp_path / "kill"
    res = run_campaign(campaign_file, out, runs=6, duration_s=60.0, scheduler=cluster.scheduler_address,
                       progress=False, on_result=kill_busy_worker)
    assert killed
    rows = _rows(out)
    assert sorted(r["run_id"] for r in rows) == list(range(6))                  # none lost, none twice
    assert all(r["status"] == "ok" for r in rows if r["run_id"] != BREAK)
    redone = [r for r in rows if r["run_id"] in killed["runs"] and r["run_id"] != BREAK]
    assert redone and any(r["worker"] != killed["worker"] for r in redone)     # done again on another worker
    assert res.interrupted is False and res.recorded == 6
    with Client(cluster.scheduler_address) as c:                                # cluster left running (not ours)
        pids = c.run(os.getpid)
        assert pids and killed["pid"] not in pids.values()


def _tornado_records_of_a_sync_interrupted_before_its_call_started() -> list[logging.LogRecord]:
    """Dask's real race, made certain: the client's event loop is kept busy while ``sync`` is
    interrupted at once, so the cancel it queues runs before the call has started."""
    import threading
    import distributed.utils as du
    records: list[logging.LogRecord] = []

    class Keep(logging.Handler):
        def emit(self, record):
            records.append(record)

    class Interrupted(threading.Event):
        def wait(self, timeout=None):
            raise KeyboardInterrupt
    log = logging.getLogger("tornado.application")
    keep = Keep()
    log.addHandler(keep)
    runner = du.LoopRunner(asynchronous=False)
    runner.start()
    try:
        runner.loop.add_callback(time.sleep, 0.2)
        real = du.threading.Event
        du.threading.Event = Interrupted
        try:
            with pytest.raises(KeyboardInterrupt):
                du.sync(runner.loop, asyncio.sleep, 0.01)
        finally:
            du.threading.Event = real
        t_end = time.monotonic() + 10.0
        while not records and time.monotonic() < t_end:
            time.sleep(0.01)
    finally:
        runner.stop()
        log.removeHandler(keep)
    return records


def test_the_traceback_dask_logs_for_an_interrupted_call_is_the_one_muted():
    """What a Ctrl-C can make the client's event loop print (one fresh-clone run in six did):
    the engine's filter drops that record and lets every other one through."""
    rec = _tornado_records_of_a_sync_interrupted_before_its_call_started()
    assert len(rec) == 1 and isinstance(rec[0].exc_info[1], NameError)
    assert _interrupted_sync_cancel(rec[0]) is False
    other = logging.LogRecord("tornado.application", logging.ERROR, __file__, 1, rec[0].msg, (), (
        ZeroDivisionError, ZeroDivisionError("x"), None))
    assert _interrupted_sync_cancel(other) is True
    assert _interrupted_sync_cancel(logging.LogRecord("tornado.application", logging.ERROR, __file__, 1,
                                                      "Exception in callback x", (), None)) is True


def test_ctrl_c_stops_cleanly_and_resume_finishes_without_duplicates(campaign_file, cluster, tmp_path):
    out = tmp_path / "intr"
    runs = 8
    code = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            "from ellipsled.montecarlo.__main__ import _main; sys.exit(_main())")
    p = subprocess.Popen([sys.executable, "-c", code, str(campaign_file), "--runs", str(runs), "--out", str(out),
                          "--workers", "2", "--duration", "30", "--flush-s", "0.2", "--no-progress"],
                         cwd=ROOT, start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        t0 = time.monotonic()
        while time.monotonic() - t0 < 60:
            parts = list((out / "results.parquet").glob("part-*.parquet"))
            if parts:
                break
            time.sleep(0.05)
        assert parts, "no result written within 60 s"
        procs = psutil.Process(p.pid).children(recursive=True) + [psutil.Process(p.pid)]
        os.killpg(p.pid, signal.SIGINT)                          # a terminal Ctrl-C: the whole group
        rc = p.wait(timeout=60)
        stdout, stderr = p.communicate()
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    assert rc == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    gone, alive = psutil.wait_procs(procs, timeout=10)
    assert not alive                                              # workers and nannies closed
    first = ResultStore(out / "results.parquet").run_ids()
    workers = {r["worker"] for r in ResultStore(out / "results.parquet").rows()}
    assert workers and all(w.startswith("tcp://127.0.0.1:") for w in workers)   # embedded cluster: loopback only
    assert 0 < len(first) < runs and len(set(first)) == len(first)
    assert not (out / "summary.md").exists()
    seen = []
    res = run_campaign(campaign_file, out, runs=runs, duration_s=30.0, scheduler=cluster.scheduler_address,
                       progress=False, summary=False, on_result=lambda row, c: seen.append(row["run_id"]))
    assert not set(seen) & set(first)                             # finished runs not redone
    ids = ResultStore(out / "results.parquet").run_ids()
    assert sorted(ids) == list(range(runs))                       # the rest finished, no duplicates
    assert res.new == runs - len(first) and res.recorded == runs
