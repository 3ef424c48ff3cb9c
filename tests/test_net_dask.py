"""The Monte Carlo on a real Dask cluster across hosts: the stock `dask scheduler` on one
network namespace, a stock `dask worker` on each of two others (tests/netns.py), and
`ellipsled montecarlo --scheduler ...` beside the scheduler, all over TLS (mutual, the
certificates of `ellipsled pki init`). A worker host torn down mid-campaign (cable cut,
every process killed) loses no run; a client without the certificates is refused."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from ellipsled.net import pki
from ellipsled.procs import ELLIPSLED

from tests import netns


pytestmark = pytest.mark.slow

BIN = Path(sys.executable).parent
START_S = 180                 # process start-up on a loaded 2-core machine


def _results(out: Path) -> list[dict]:
    """The rows recorded so far, read without touching the folder (the store's own
    constructor tidies it: only for a campaign that is not running)."""
    import pyarrow.parquet as pq
    rows = []
    for part in sorted((out / "results.parquet").glob("part-*.parquet")):
        rows += pq.read_table(part).to_pylist()
    return rows


def _cluster(net: netns.Network, tls: Path | None, env: dict | None = None) -> str:  # tls: a pki folder
    """`dask scheduler` on host "sched", one `dask worker` on each of "w1", "w2"; returns the
    scheduler's address."""
    proto = "tls" if tls else "tcp"
    sec = ["--tls-ca-file", str(tls / "ca.pem"), "--tls-cert", str(tls / "dask.pem"),
           "--tls-key", str(tls / "dask.key")] if tls else []
    addr = f"{proto}://{net.addr('sched')}:8786"
    net.start("scheduler", "sched", [str(BIN / "dask"), "scheduler", "--host", net.addr("sched"), "--port", "8786",
                                     "--no-dashboard", "--protocol", proto, *sec], env=env)
    net.wait_log("scheduler", "Scheduler at", START_S)
    for w in ("w1", "w2"):
        net.start(f"worker-{w}", w, [str(BIN / "dask"), "worker", addr, "--host", net.addr(w), "--nworkers", "1",
                                     "--nthreads", "1", "--no-dashboard", *sec], env=env)
    for w in ("w1", "w2"):
        net.wait_log(f"worker-{w}", "Registered to", START_S)
    return addr


@pytest.fixture
def hosts(tmp_path):
    why = netns.skip_reason()
    if why:
        pytest.skip(why)
    n = netns.Network(["sched", "w1", "w2"], tmp_path / "logs")
    try:
        yield n
    finally:
        n.close()
        assert not n.leftovers(), n.leftovers()


def test_tls_campaign_across_hosts_loses_no_run_when_a_worker_host_is_torn_down(hosts, tmp_path):
    import os
    d = tmp_path / "pki"
    pki.init(d, [hosts.addr("sched")])
    tls = ["--tls-ca-file", str(d / "ca.pem"), "--tls-cert", str(d / "dask.pem"), "--tls-key", str(d / "dask.key")]
    # a host that vanishes sends nothing more: the scheduler declares its worker dead after
    # this time without a heartbeat (Dask's default is 5 minutes) and runs its tasks again elsewhere
    env = dict(os.environ, DASK_DISTRIBUTED__SCHEDULER__WORKER_TTL="8s")
    addr = _cluster(hosts, d, env)
    assert addr.startswith("tls://")
    out, runs = tmp_path / "mc", 16
    hosts.start("campaign", "sched", ELLIPSLED + ["montecarlo", "default", "--runs", str(runs), "--duration", "60",
                                                  "--out", str(out), "--scheduler", addr, "--flush-s", "0.2",
                                                  "--no-progress", *tls])
    w2 = f"tls://{hosts.addr('w2')}:"
    deadline = time.monotonic() + START_S
    while not any(str(r.get("worker", "")).startswith(w2) for r in _results(out)):
        assert hosts.procs["campaign"][1].poll() is None, hosts.log("campaign")
        assert time.monotonic() < deadline, "worker w2 finished no run"
        time.sleep(0.1)
    before = len(_results(out))
    assert before < runs, "the campaign ended before the teardown: make the runs longer"
    hosts.remove_host("w2")
    assert hosts.wait("campaign", 240) == 0, hosts.log("campaign")
    rows = _results(out)
    assert sorted(r["run_id"] for r in rows) == list(range(runs))            # every run, once
    assert all(r["status"] == "ok" for r in rows), [(r["run_id"], r["error"]) for r in rows if r["status"] != "ok"]
    assert {str(r["worker"]).split("//")[0] for r in rows} == {"tls:"}
    # every run once (above): w2 flew some (what it recorded before it vanished, however many
    # its last flushes carried: the host's pace decides that, not the code), the surviving
    # worker all the others, those w2 had in hand when it vanished among them
    by_w2 = [r for r in rows if str(r["worker"]).startswith(w2)]
    assert 1 <= len(by_w2) < runs, (len(by_w2), before)
    assert f"{runs} of {runs} runs recorded" in hosts.log("campaign")
    # half the TLS options: refused before connecting; a certificate of another CA: the
    # scheduler refuses the client, nothing is recorded
    hosts.start("nocert", "sched", ELLIPSLED + ["montecarlo", "default", "--runs", "1", "--out", str(tmp_path / "mc2"),
                                                "--scheduler", addr, "--no-progress", *tls[:2]])
    rogue = tmp_path / "rogue"
    pki.init(rogue)
    hosts.start("rogue", "sched", ELLIPSLED + ["montecarlo", "default", "--runs", "1", "--out", str(tmp_path / "mc3"),
                                               "--scheduler", addr, "--no-progress", *tls[:2],
                                               "--tls-cert", str(rogue / "dask.pem"),
                                               "--tls-key", str(rogue / "dask.key")])
    assert hosts.wait("nocert", 120) == 2 and "--tls-cert" in hosts.log("nocert"), hosts.log("nocert")
    assert hosts.wait("rogue", 120) != 0, hosts.log("rogue")
    assert not _results(tmp_path / "mc3")
