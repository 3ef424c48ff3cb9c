"""The SIL across hosts: the router, the plant, the FSW and the viewer each in a network
namespace of its own on a private bridge (tests/netns.py), over mutual TLS with the
router's access-control policy — the shipped data/zenoh/*.json5 files and the commands
of the README's "Running across machines", nothing else.

Lockstep through the router equals the batch run bit for bit; real time answers the plant
in time; a viewer certificate cannot reach the plant; a router killed mid-run is
detected by both nodes (jets held off) and they resume when it is back."""
from __future__ import annotations

import json
import re
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ellipsled import batch
from ellipsled.net import pki
from ellipsled.node_reports import read_fsw, read_sim
from ellipsled.procs import ELLIPSLED
from ellipsled.sil.history import History, merge
from interfaces.keys import keys

from tests import netns


pytestmark = [pytest.mark.slow, pytest.mark.realtime]

ZCONF = Path(__file__).resolve().parent.parent / "data" / "zenoh"
PORT = 7447
HOSTS = ["router", "plant", "fsw", "viewer"]
START_S = 180      # a process's start-up on a loaded 2-core machine (imports, numba caches)


@pytest.fixture(scope="module")
def net(tmp_path_factory):
    why = netns.skip_reason()
    if why:
        pytest.skip(why)
    work = tmp_path_factory.mktemp("hosts")
    n = netns.Network(HOSTS, work / "logs")
    try:
        # `ellipsled pki init pki --router-host <router address>`: the nodes run in `work`
        pki.init(work / "pki", [n.addr("router")])
        n.work = work
        n.router_ep = f"tls/{n.addr('router')}:{PORT}"
        yield n
    finally:
        n.close()
        assert not n.leftovers(), n.leftovers()


def start_router(n: netns.Network, name: str = "router", rt: bool = False) -> None:
    # --rt: on a 2-core machine the router shares the cores with the nodes' spinning
    # real-time loops (on its own machine it would not need it)
    n.start(name, "router", ELLIPSLED + ["router", "--config", str(ZCONF / "router.json5"), "--listen", n.router_ep]
            + (["--rt"] if rt else []), cwd=n.work)
    n.wait_log(name, "listening on", 60)


def node(n: netns.Network, role: str, mode: str, out: Path, prefix: str, extra=()) -> list[str]:
    """`ellipsled sim|fsw ... --zenoh-config data/zenoh/<role>.json5 --connect tls/ROUTER:7447`."""
    return ELLIPSLED + [role, "case1", f"--{mode}", "--prefix", prefix, "--out", str(out),
                        "--zenoh-config", str(ZCONF / f"{role}.json5"), "--connect", n.router_ep, *extra]


def viewer(n: netns.Network, out: Path, prefix: str) -> list[str]:
    return ELLIPSLED + ["viz", "--prefix", prefix, "--rerun", "file", "--out", str(out), "--name", "run",
                        "--zenoh-config", str(ZCONF / "viz.json5"), "--connect", n.router_ep]


def _stop_all(n: netns.Network, *names: str) -> None:
    """SIGTERM, a clean exit expected (generous: a real-time node's exit on a loaded
    machine has taken over 10 s)."""
    for name in names:
        if name in n.procs:
            assert n.stop(name, timeout_s=30.0) == 0, n.log(name)


def test_lockstep_through_the_router_equals_the_batch_run_bit_for_bit_even_across_a_router_restart(net):
    """Plant, FSW and viewer on three hosts, through the TLS router, which is killed mid-run
    and started again: the plant sends its frame again until the answer comes (the FSW
    answers a frame it has flown with the same command), so every history array still
    equals the single-process batch run's and FDIR finds the same jets at the same times;
    the viewer on its own host recorded the run."""
    out, prefix = net.work / "lockstep", "ellipsled/multihost-ls"
    start_router(net, "router-ls1")
    probe = net.work / "watch.py"
    probe.write_text(WATCH)
    try:
        net.start("viz-ls", "viewer", viewer(net, out, prefix), cwd=net.work)
        net.start("fsw-ls", "fsw", node(net, "fsw", "lockstep", out, prefix), cwd=net.work)
        net.wait_log("fsw-ls", "waiting for the plant", START_S)
        # a second viewer-certificate client on the viewer host reports when the flight is under way
        net.start("watch", "viewer", [sys.executable, str(probe), str(ZCONF / "viz.json5"), net.router_ep,
                                      keys(prefix).truth, "300"], cwd=net.work)
        net.wait_log("watch", "watching", START_S)
        net.start("sim-ls", "plant", node(net, "sim", "lockstep", out, prefix,
                                          ["--duration", "120", "--wait-bridge", "--wait-peers", str(START_S),
                                           "--fsw-timeout", str(START_S)]), cwd=net.work)
        net.wait_log("watch", "under way", START_S)
        net.stop("router-ls1", signal.SIGKILL)
        assert net.procs["sim-ls"][1].poll() is None, "the run ended before the router was killed"
        time.sleep(1.0)
        start_router(net, "router-ls2")
        assert net.wait("sim-ls", 300) == 0, net.log("sim-ls")
        _stop_all(net, "fsw-ls", "viz-ls")
    finally:
        _stop_all(net, "router-ls2")
    h_sil = merge(History.load(out / "sim_history.npz"), History.load(out / "fsw_history.npz"))
    s_bat, h_bat, _ = batch.run("case1", duration_s=120)
    assert h_sil["k"].shape == h_bat["k"].shape
    for name in h_bat.a:
        if name in ("compute_us", "alloc_us"):      # wall-clock measurements, not trajectory
            continue
        assert np.array_equal(h_sil[name], h_bat[name]), name
    fsw = json.loads((out / "fsw.json").read_text())
    sim = json.loads((out / "sim.json").read_text())
    assert fsw["detections"] == s_bat["fdir"]["detections"]
    assert sim["counts"]["resent_frames"] >= 1 and fsw["answers_repeated"] + sim["counts"]["resent_frames"] >= 1
    assert (out / "run.rrd").stat().st_size > 0


WATCH = r"""
import json, sys, time
import zenoh
from interfaces.codec import Codec
conf_file, endpoint, key, k_min = sys.argv[1:5]
conf = zenoh.Config.from_file(conf_file)
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
s = zenoh.open(conf)
sub = s.declare_subscriber(key, zenoh.handlers.RingChannel(8))     # never holds the run back
dec = Codec.for_schema("TRUTH")
print("watching", flush=True)
while True:
    x = sub.try_recv()
    if x is None:
        time.sleep(0.001)
        continue
    rec = dec.decode(x.payload.to_bytes())
    if rec is not None and int(rec["k"]) >= int(k_min):
        print(f"under way: k={int(rec['k'])}", flush=True)
        break
sub.undeclare()
s.close()
"""


def test_the_viewer_certificate_cannot_command_the_jets(net, tmp_path):
    """A process holding the viewer's certificate publishes jet commands (well-formed,
    newest sequence) from the viewer host: the router drops them, the plant never sees one;
    the genuine FSW's certificate, from the same host, gets through."""
    prefix = "ellipsled/multihost-acl"
    k = keys(prefix)
    start_router(net, "router-acl")
    probe = net.work / "probe.py"
    probe.write_text(PROBE)
    try:
        net.start("rx", "plant", [sys.executable, str(probe), "rx", str(ZCONF / "sim.json5"), net.router_ep,
                                  k.jets], cwd=net.work)
        net.wait_log("rx", "ready", 60)
        for role in ("viz", "fsw"):
            net.start(f"tx-{role}", "viewer", [sys.executable, str(probe), "tx", str(ZCONF / "viz.json5"),
                                               net.router_ep, k.jets, role], cwd=net.work)
            assert net.wait(f"tx-{role}", 60) == 0, net.log(f"tx-{role}")
        assert net.stop("rx", signal.SIGTERM) == 0, net.log("rx")
    finally:
        _stop_all(net, "router-acl")
    got = json.loads(net.log("rx").splitlines()[-1])
    assert got == {"fsw": 20}, got           # 20 genuine commands, not one of the viewer's
    assert "sent 20" in net.log("tx-viz")    # ... which were sent (the router refused them)


PROBE = r"""
import json, signal, sys, time
import zenoh
from interfaces import records, transport
from interfaces.codec import Codec
what, conf_file, endpoint, key = sys.argv[1:5]
conf = zenoh.Config.from_file(conf_file)
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
if what == "tx":          # publish as the role whose certificate is given
    role = sys.argv[5]
    conf.insert_json5("transport/link/tls/connect_certificate", json.dumps(f"pki/{role}.pem"))
    conf.insert_json5("transport/link/tls/connect_private_key", json.dumps(f"pki/{role}.key"))
s = zenoh.open(conf)
if what == "rx":
    sub = s.declare_subscriber(key, zenoh.handlers.FifoChannel(1000))
    dec = Codec.for_schema("JETS")
    stop = []
    signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
    print("ready", flush=True)
    got = {}
    while not stop:
        x = sub.try_recv()
        if x is None:
            time.sleep(0.005); continue
        rec = dec.decode(x.payload.to_bytes())
        if rec is not None:
            who = {7: "viz", 8: "fsw"}[int(rec["k"]) // 1000]
            got[who] = got.get(who, 0) + 1
    print(json.dumps(got), flush=True)
    sub.undeclare()
else:
    pub = s.declare_publisher(key)
    enc = Codec.for_schema("JETS")
    j = records.new(records.JETS)
    base = 7000 if role == "viz" else 8000
    # the plant's subscription reaches this session when the policy allows it (never for the
    # viewer: its puts then go to the router, which drops them)
    transport.wait_for_subscriber(pub, 5.0 if role == "viz" else 60.0)
    for i in range(20):
        j["k"] = base + i
        j["u"][:] = 1
        pub.put(enc.encode(j, base + i, time.monotonic_ns()))
        time.sleep(0.01)
    time.sleep(0.5)
    print(f"sent 20 as {role}", flush=True)
    pub.undeclare()
s.close()
"""


def _realtime(net, tag: str, duration: float, prefix: str, sim_extra=(), rt=True):
    out = net.work / tag
    net.start(f"fsw-{tag}", "fsw", node(net, "fsw", "realtime", out, prefix, ["--rt", "--cpu", "1"] if rt else []),
              cwd=net.work)
    net.wait_log(f"fsw-{tag}", "waiting for the plant", START_S)
    net.start(f"sim-{tag}", "plant", node(net, "sim", "realtime", out, prefix,
                                          ["--duration", str(duration), *(["--rt", "--cpu", "0"] if rt else []),
                                           "--wait-peers", str(START_S), *sim_extra]),
              cwd=net.work)
    return out


def test_realtime_through_the_router_answers_the_plant(net):
    """20 s of real time with plant and FSW on two hosts through the TLS router: the run
    completes and the FSW answers the plant in time (generous: half the steps; a phase lock
    a period off answers none). Slips and latency through the router: `ellipsled bench`."""
    prefix = "ellipsled/multihost-rt"
    start_router(net, "router-rt", rt=True)
    try:
        out = _realtime(net, "rt", 20, prefix)
        assert net.wait("sim-rt", 120) == 0, net.log("sim-rt")
        _stop_all(net, "fsw-rt")
    finally:
        _stop_all(net, "router-rt")
    fsw, sim = read_fsw(out), read_sim(out)
    print(f"through the router: latency p50 {sim['latency_p50_us']:.0f} us p99 {sim['latency_p99_us']:.0f} us, "
          f"jitter p99 {fsw['jitter_p99_us']:.0f} us, slips {fsw['cycle_slips']}, samples {sim['latency_samples']}, "
          f"plant counts {sim['counts']}, rejects {sim['rejects']}")
    assert sim["end_reason"] in ("duration", "timeout") or sim["t_end_s"] >= 19.99, sim
    assert (sim["latency_samples"] + sim["counts"]["missed_commands"] + sim["counts"]["missed_plant_late"]
            + sim["counts"]["unanswered_at_start"]) == sim["steps"]
    assert sim["latency_samples"] >= sim["steps"] // 2, sim


def test_router_killed_mid_run_both_nodes_hold_then_resume(net):
    """Kill the router while plant and FSW fly in real time: the FSW declares its sensors
    stale after 3 periods and holds the jets off, the plant holds them off after 3 periods
    without a command; both pick the flight up again when a new router takes the address."""
    prefix = "ellipsled/multihost-kill"
    start_router(net, "router-k1", rt=True)
    try:
        out = _realtime(net, "kill", 120, prefix, ["--miss-periods", "3"])
        net.wait_log("sim-kill", "first jet command", 90)
        time.sleep(3.0)
        net.stop("router-k1", signal.SIGKILL)
        net.wait_log("sim-kill", "jets held off", 10)
        time.sleep(1.0)
        start_router(net, "router-k2", rt=True)
        net.wait_log("sim-kill", "jet commands back: resuming", 60)
        time.sleep(2.0)                              # fly on a little after the resumption
        net.stop("sim-kill")                         # records written on SIGTERM
        net.stop("fsw-kill")
    finally:
        _stop_all(net, "router-k2")
    log = net.log("sim-kill")
    held = re.findall(r"no jet command for (\d+) periods: jets held off", log)
    assert held and int(held[0]) == 3, log
    assert log.index("jets held off") < log.index("jet commands back: resuming"), log
    fsw = json.loads((out / "fsw.json").read_text())
    ev = [(e["code"], e["text"]) for e in fsw["event_log"]]
    codes = [c for c, _ in ev]
    assert "sensors_stale" in codes and "(3 PERIODS)" in ev[codes.index("sensors_stale")][1], ev
    assert "sensors_recovered" in codes[codes.index("sensors_stale"):], ev
    # the plant: the jets fired before the loss, were off during it, and fire again after it
    h = History.load(out / "sim_history.npz")
    firing = np.abs(h["tau_jets_B"]).sum(axis=1) > 0
    off = np.flatnonzero(~firing)
    gaps = np.split(off, np.flatnonzero(np.diff(off) > 1) + 1)
    longest = max(gaps, key=len)
    assert len(longest) >= 50, "no held-off stretch of at least 1 s (the router was down for seconds)"
    assert firing[: longest[0]].any() and firing[longest[-1] + 1:].any()
