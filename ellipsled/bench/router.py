"""The real-time SIL through the Zenoh router, with mutual TLS and access control, beside
the embedded peer-to-peer configuration, in the same invocation.

Through the router: a fresh PKI (``ellipsled pki init``) in a temporary folder,
``ellipsled router --rt`` with ``data/zenoh/router.json5`` on ``tls/localhost:<free port>``,
then ``ellipsled fsw`` and ``ellipsled sim`` (``--realtime --rt``, CPUs 1 and 0) as clients
with ``data/zenoh/fsw.json5`` / ``sim.json5`` — the commands of the README's "Running
across machines", on one machine. Baseline: ``ellipsled run --realtime`` (plant and FSW
peer to peer on loopback, no TLS). Both runs: the nominal scenario for the same duration;
figures from each run's plant report (sensor-to-actuator latency: plant publishes step k ->
plant has the command answering k) and FSW report (release jitter, cycle slips), read with
ellipsled/node_reports.py.

Every process is stopped by its pid (SIGTERM, then SIGKILL after a timeout).
"""
from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ellipsled.node_reports import read_fsw, read_sim
from ellipsled.procs import ELLIPSLED, stop_process

from .rows import NO_TARGET, Row, fmt, g, ratio, row

TARGETS = {"slips": 0}           # through the router; latency is shown beside peer to peer
FIGURES = ("latency_p50_us", "latency_p99_us", "latency_max_us", "jitter_p99_us", "slips")
PREFIX = "ellipsled/bench-router"


class _Procs:
    def __init__(self, d: Path):
        self.d, self.p, self.logs = d, {}, []

    def start(self, name: str, argv: list[str]) -> None:
        log = open(self.d / f"{name}.log", "w")
        self.logs.append(log)
        self.p[name] = subprocess.Popen(ELLIPSLED + argv, cwd=self.d, stdout=log,
                                        stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)

    def log(self, name: str) -> str:
        return (self.d / f"{name}.log").read_text()

    def wait_for(self, name: str, text: str, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while text not in self.log(name):
            if self.p[name].poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"{name}: no {text!r} within {timeout_s:g} s (exit {self.p[name].poll()}): "
                                   f"{self.log(name)[-300:]}")
            time.sleep(0.05)

    def stop(self, name: str, timeout_s: float = 10.0) -> int | None:
        return stop_process(self.p[name], timeout_s)

    def close(self) -> None:
        for name in self.p:
            self.stop(name, 5.0)
        for log in self.logs:
            log.close()


def through_router(duration_s: float, start_timeout_s: float = 180.0) -> dict:
    """One real-time run through ``ellipsled router`` with TLS on loopback."""
    from common.config import DATA_DIR
    from ellipsled.net import pki
    from interfaces import transport
    from ellipsled.sil.common import rt_arguments
    zc = DATA_DIR / "zenoh"
    with tempfile.TemporaryDirectory(prefix="bench-router-") as tmp:
        d = Path(tmp)
        pki.init(d / "pki")
        ep = f"tls/localhost:{transport.free_port()}"
        out = d / "run"
        node = ["nominal", "--realtime", "--duration", f"{duration_s:g}",
                "--prefix", PREFIX, "--out", str(out), "--connect", ep, "--wait-peers", f"{start_timeout_s:g}"]
        pr = _Procs(d)
        try:
            pr.start("router", ["router", "--config", str(zc / "router.json5"), "--listen", ep, "--rt"])
            pr.wait_for("router", "listening on", start_timeout_s)
            pr.start("fsw", ["fsw", *node, "--zenoh-config", str(zc / "fsw.json5"), *rt_arguments("fsw")])
            pr.wait_for("fsw", "waiting for the plant", start_timeout_s)
            pr.start("sim", ["sim", *node, "--zenoh-config", str(zc / "sim.json5"), *rt_arguments("sim")])
            try:
                rc = pr.p["sim"].wait(duration_s + start_timeout_s)
            except subprocess.TimeoutExpired:
                raise RuntimeError(f"the plant did not finish within {duration_s + start_timeout_s:g} s: "
                                   f"{pr.log('sim')[-300:]}") from None
            pr.stop("fsw")
        finally:
            pr.close()
        if not (out / "sim.json").is_file() or not (out / "fsw.json").is_file():
            raise RuntimeError(f"no sim.json/fsw.json (plant exit {rc}): {pr.log('sim')[-300:]}")
        sim, fsw = read_sim(out), read_fsw(out)
    return {"latency_p50_us": sim["latency_p50_us"], "latency_p99_us": sim["latency_p99_us"],
            "latency_max_us": sim["latency_max_us"], "latency_samples": sim["latency_samples"],
            "jitter_p99_us": fsw["jitter_p99_us"], "slips": fsw["cycle_slips"], "exit_code": rc,
            "end_reason": sim["end_reason"], "endpoint": ep, "duration_s": duration_s}


def peer_to_peer(duration_s: float) -> dict:
    """The baseline: ``ellipsled run --realtime`` on the embedded loopback configuration."""
    from .sil import sil_run
    r = sil_run("realtime", "nominal", duration_s, timeout_s=duration_s + 180)
    sil = r["sil"] or {}
    out = {k: sil.get(k) for k in ("latency_p50_us", "latency_p99_us", "latency_max_us", "latency_samples",
                                   "jitter_p99_us", "slips")}
    out.update(command=r["command"], exit_code=r["exit_code"], duration_s=duration_s)
    return out


def _measured(fn, *a) -> dict:
    try:
        return fn(*a)
    except Exception as e:
        why = f"{type(e).__name__}: {e}"
        return {**{k: None for k in FIGURES}, **{f"{k}_reason": why for k in FIGURES}}


def run(quick: bool) -> dict:
    dur = 10.0 if quick else 30.0
    p2p = _measured(peer_to_peer, dur)
    rtr = _measured(through_router, dur)
    return {"figure": "real-time SIL sensor-to-actuator latency through the Zenoh router (mutual TLS, access "
                      "control, loopback) vs peer to peer [us]",
            "p50_us": rtr.get("latency_p50_us"), "p99_us": rtr.get("latency_p99_us"),
            "baseline_p50_us": p2p.get("latency_p50_us"), "baseline_p99_us": p2p.get("latency_p99_us"),
            "router_tls": rtr, "peer_to_peer": p2p, "targets": dict(TARGETS)}


def rows(res: dict) -> list[Row]:
    sr = res.get("sil_router") or {}
    if not sr:
        return []
    slips = g(sr, "router_tls", "slips")
    return [row(f"sensor-to-actuator latency through the router, mutual TLS ({fmt(g(sr, 'router_tls', 'duration_s'))} s)"
                " p50 / p99 [us]", f"{fmt(sr.get('p50_us'))} / {fmt(sr.get('p99_us'))}",
                f"peer to peer {fmt(sr.get('baseline_p50_us'))} / {fmt(sr.get('baseline_p99_us'))}",
                f"{fmt(ratio(sr.get('p99_us'), sr.get('baseline_p99_us')))}x (p99)", "", NO_TARGET),
            row("  cycle slips through the router / peer to peer",
                f"{fmt(slips)} / {fmt(g(sr, 'peer_to_peer', 'slips'))}", "", "", f"{TARGETS['slips']}",
                None if slips is None else slips == TARGETS["slips"])]


if __name__ == "__main__":
    print(json.dumps(run("--quick" in sys.argv), indent=2))
