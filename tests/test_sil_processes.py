"""The SIL with real processes: lockstep equals batch, real time locks to the plant and flies, and
the runtime faults (a process killed, garbage and hostile payloads) are survived and
reported. Every process is started here and stopped by its pid, with timeouts."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from ellipsled import batch
from ellipsled.procs import ELLIPSLED, stop_process
from interfaces import transport


pytestmark = [pytest.mark.slow, pytest.mark.realtime]

PREFIX = "ellipsled/test"


class Procs:
    """Processes of one test; whatever is still running at the end is killed."""

    def __init__(self, tmp: Path):
        self.tmp = tmp
        self.p: dict[str, subprocess.Popen] = {}

    def start(self, name: str, argv: list[str]) -> subprocess.Popen:
        log = open(self.tmp / f"{name}.log", "w")
        p = subprocess.Popen(ELLIPSLED + argv, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        self.p[name] = p
        return p

    def log(self, name: str) -> str:
        return (self.tmp / f"{name}.log").read_text()

    def stop(self, name: str, sig=signal.SIGTERM, timeout: float = 10.0) -> int:
        """``sig``, then SIGKILL after ``timeout``; a process that had to be killed fails the test."""
        p, killed = self.p[name], []
        rc = stop_process(p, timeout, sig=sig, on_kill=lambda: killed.append(True))
        if killed:
            raise AssertionError(f"{name} (pid {p.pid}) did not stop within {timeout} s")
        return rc

    def wait(self, name: str, timeout: float) -> int:
        try:
            return self.p[name].wait(timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"{name} did not finish within {timeout} s:\n{self.log(name)[-2000:]}")

    def cleanup(self) -> None:
        for p in self.p.values():
            if p.poll() is None:
                p.kill()
                p.wait(5)


@pytest.fixture
def procs(tmp_path):
    pr = Procs(tmp_path)
    yield pr
    pr.cleanup()
    for name, p in pr.p.items():
        assert p.poll() is not None, f"{name} left running"


def _node(role, scenario, mode, out, *, listen=None, connect=None, extra=()):
    argv = [role, scenario, f"--{mode}", "--prefix", PREFIX, "--out", str(out)]
    for e in listen or ():
        argv += ["--listen", e]
    for e in connect or ():
        argv += ["--connect", e]
    return argv + list(extra)


def _json(path: Path) -> dict:
    return json.loads(path.read_text())


def test_lockstep_sil_equals_batch_bit_for_bit(tmp_path):
    """`ellipsled run --lockstep` (sim and fsw processes over Zenoh) flies exactly the
    batch run: every history array and every summary figure equal, faults at 2.5 s."""
    out = tmp_path / "sil"
    r = subprocess.run(ELLIPSLED + ["run", "case1", "--lockstep", "--duration", "30", "--out", str(out),
                                    "--rerun", "none", "--no-plots"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    s_sil = _json(out / "summary.json")
    s_bat, h_bat, _ = batch.run("case1", duration_s=30)
    h_sil = np.load(out / "history.npz")
    assert h_sil["k"].shape == h_bat["k"].shape
    for name in h_sil.files:
        if name in ("compute_us", "alloc_us"):      # wall-clock measurements, not trajectory
            continue
        assert np.array_equal(h_sil[name], h_bat[name]), name
    timing = {"wall_s", "realtime_factor", "control_cycle", "allocator", "mode", "cycle_slips", "events"}
    for key, val in s_bat.items():
        if key not in timing:
            assert s_sil[key] == val, key
    assert s_sil["allocator"]["solves"] == s_bat["allocator"]["solves"]
    # lockstep: the frame comes with the tick; no input task waiting for frames (it cost 3 ms a step)
    assert "input" not in _json(out / "fsw.json")["tasks_us"]
    # the control task's time of every tick is saved, and sil.json's figure covers them all
    with np.load(out / "fsw_timing.npz") as z:
        control_ns = z["control_ns"]
    assert len(control_ns) == _json(out / "fsw.json")["ticks"] == h_bat["k"].shape[0]
    assert (control_ns > 0).all() and _json(out / "sil.json")["fsw_control_us"]["runs"] == len(control_ns)
    assert [d["jet"] for d in s_sil["fdir"]["detections"]] == [2, 17, 18, 1] or \
        sorted(d["jet"] for d in s_sil["fdir"]["detections"]) == [1, 2, 17, 18]


def test_guided_lockstep_sil_equals_batch_bit_for_bit(tmp_path):
    """Guidance mode npc computes on a worker thread; its answer is applied at a fixed step
    after the release, so the multi-process lockstep run still equals the batch run."""
    out = tmp_path / "sil"
    r = subprocess.run(ELLIPSLED + ["run", "guided-nominal", "--lockstep", "--duration", "30", "--out", str(out),
                                    "--rerun", "none", "--no-plots"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    s_bat, h_bat, _ = batch.run("guided-nominal", duration_s=30)
    h_sil = np.load(out / "history.npz")
    assert h_sil["k"].shape == h_bat["k"].shape
    for name in h_sil.files:
        if name not in ("compute_us", "alloc_us"):
            assert np.array_equal(h_sil[name], h_bat[name]), name
    s_sil = _json(out / "summary.json")
    assert s_sil["deploy_miss_km"] == s_bat["deploy_miss_km"]
    assert s_sil["guidance"]["bank0_final_deg"] == s_bat["guidance"]["bank0_final_deg"]
    assert s_sil["guidance"]["cycles"] == s_bat["guidance"]["cycles"] == 30


def test_guided_lockstep_sil_deploys_where_batch_deploys(tmp_path):
    """The whole guided entry: the FSW's deploy command crosses the process boundary with the
    jet command, and the plant deploys at the same step as in batch, bit for bit."""
    out = tmp_path / "sil"
    r = subprocess.run(ELLIPSLED + ["run", "guided-nominal", "--lockstep", "--out", str(out),
                                    "--rerun", "none", "--no-plots"], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stdout + r.stderr
    s_bat, h_bat, _ = batch.run("guided-nominal")
    s_sil = _json(out / "summary.json")
    assert s_sil["end_reason"] == s_bat["end_reason"] == "deploy"
    assert s_sil["deploy"] == s_bat["deploy"] and s_bat["deploy"]["ok"]
    h_sil = np.load(out / "history.npz")
    assert h_sil["k"].shape == h_bat["k"].shape
    for name in h_sil.files:
        if name not in ("compute_us", "alloc_us"):
            assert np.array_equal(h_sil[name], h_bat[name]), name


def _hogs(n: int) -> list[subprocess.Popen]:
    """n CPU hogs: stress-ng when installed, else plain Python busy loops."""
    import shutil
    if shutil.which("stress-ng"):
        return [subprocess.Popen(["stress-ng", "--cpu", str(n), "--timeout", "120s", "--quiet"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)]
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True) for _ in range(n)]


@pytest.mark.parametrize("load", ["idle", "two_cpu_hogs"])
def test_realtime_sil_locks_to_the_plant_and_flies_the_fault_case(tmp_path, load):
    """The whole SIL (plant, FSW, Rerun bridge) for 20 s of real time at 50 Hz, idle and
    with two CPU hogs: the run completes, the plant waits for the FSW's warm-up and the FSW
    locks to its schedule, every step is accounted for, the FSW answers in time (generous:
    half the steps; a phase lock a period off answers none in time) and the fault case flies
    within the paper's band. Deadlines, jitter and latency are host figures: `ellipsled bench`;
    the lock's logic is tested on scripted frames (tests/test_sil_frame_timing.py)."""
    sil, s, out = _realtime_run(tmp_path / "rt", load)
    print(f"{load}: sil.json {sil}")
    assert s["completed"] and abs(s["t_end_s"] - 20.0) < 1e-6, (s["end_reason"], s["t_end_s"])
    sim, fsw_log = _json(out / "sim.json"), (out / "fsw.log").read_text()
    assert sim["counts"]["warmup_frames"] > 0                  # the plant offered frame 0 ...
    assert "starting anyway" not in (out / "sim.log").read_text()   # ... until the FSW was ready
    assert "phase lock on step" in fsw_log, fsw_log
    steps = sim["steps"]
    assert steps == round(20.0 / 0.02) + 1
    assert (sil["latency_samples"] + sim["counts"]["missed_commands"]     # each step: one of the four
            + sim["counts"]["missed_plant_late"]
            + sim["counts"]["unanswered_at_start"]) == steps
    assert sil["latency_samples"] >= steps // 2, sil
    assert s["bank_err_max_after_fault_deg"] < 5.0
    assert (out / "run.rrd").stat().st_size > 0


def _realtime_run(out: Path, load: str):
    hogs = _hogs(2) if load != "idle" else []
    try:
        r = subprocess.run(ELLIPSLED + ["run", "case1", "--realtime", "--rt", "--duration", "20", "--out", str(out),
                                        "--rerun", "file", "--no-plots"], capture_output=True, text=True, timeout=300)
    finally:
        for h in hogs:
            os.killpg(h.pid, signal.SIGKILL)
            h.wait(10)
    assert r.returncode == 0, r.stdout + r.stderr
    return _json(out / "sil.json"), _json(out / "summary.json"), out


def test_plant_killed_fsw_holds_jets_off_and_recovers(tmp_path, procs):
    """Kill the plant mid-run: the FSW declares its sensors stale, holds the jets off and
    keeps running; a new plant process is picked up and commanded again."""
    e_fsw = transport.loopback(transport.free_port())
    procs.start("fsw", _node("fsw", "case1", "realtime", tmp_path / "fsw", listen=[e_fsw],
                                extra=["--plant-gone-s", "120"]))  # it must outlast the restart
    procs.start("sim1", _node("sim", "case1", "realtime", tmp_path / "sim1", connect=[e_fsw],
                              extra=["--duration", "60"]))
    # start-up (seconds on a loaded machine: imports, compiled kernels, warm-up), then a few
    # seconds flying: the plant logs the FSW's first command
    end = time.monotonic() + 120.0
    while "first jet command" not in procs.log("sim1"):
        assert procs.p["sim1"].poll() is None and time.monotonic() < end, procs.log("sim1") + procs.log("fsw")
        time.sleep(0.2)
    time.sleep(3.0)
    assert procs.p["sim1"].poll() is None, procs.log("sim1")
    procs.stop("sim1", signal.SIGKILL)
    time.sleep(3.0)
    assert procs.p["fsw"].poll() is None, "the FSW must keep running without its plant"
    procs.start("sim2", _node("sim", "case1", "realtime", tmp_path / "sim2", connect=[e_fsw],
                              extra=["--duration", "4"]))
    assert procs.wait("sim2", 60) == 0, procs.log("sim2")
    assert procs.stop("fsw") == 0
    rep = _json(tmp_path / "fsw" / "fsw.json")
    codes = [(e["code"], e["t_s"]) for e in rep["event_log"]]
    stale = [t for c, t in codes if c == "sensors_stale"]
    recovered = [t for c, t in codes if c == "sensors_recovered"]
    assert stale, codes
    assert recovered and recovered[-1] >= 0.0
    # stale declared within 3 periods of the last frame (the FSW's clock advances each release)
    h = np.load(tmp_path / "fsw" / "fsw_history.npz")
    assert any(e["code"] == "new_sensor_source" for e in rep["event_log"])
    assert rep["monitor_counts"]["out_of_order"] == 0, "the restarted plant's frames must be accepted"
    sim2 = np.load(tmp_path / "sim2" / "sim_history.npz")
    assert np.any(np.abs(sim2["tau_jets_B"]).sum(axis=1) > 0), "the new plant must be commanded"
    # the first frame after the kill that the FSW saw came from the new plant, k restarted
    k = h["k"]
    assert np.any(np.diff(k) < 0)


def test_fsw_killed_realtime_plant_holds_jets_off(tmp_path, procs):
    """Kill the FSW in real time: the plant notices the missing commands, applies jets off
    and keeps flying to the end of its run."""
    e_sim = transport.loopback(transport.free_port())
    procs.start("sim", _node("sim", "case1", "realtime", tmp_path / "sim", listen=[e_sim],
                             extra=["--duration", "12", "--miss-periods", "3"]))
    procs.start("fsw", _node("fsw", "case1", "realtime", tmp_path / "fsw", connect=[e_sim]))
    # kill the FSW once the plant has flown a few seconds
    deadline = time.monotonic() + 60
    while "first jet command" not in procs.log("sim") and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(3.0)
    procs.stop("fsw", signal.SIGKILL)
    assert procs.wait("sim", 60) == 0, procs.log("sim")
    info = _json(tmp_path / "sim" / "sim.json")
    assert info["counts"]["missed_commands"] >= 3
    assert "jets held off" in procs.log("sim")
    h = np.load(tmp_path / "sim" / "sim_history.npz")
    last = h["tau_jets_B"][-50:]                                # the final second: no command, no torque
    assert np.all(last == 0.0)
    assert np.any(np.abs(h["tau_jets_B"]).sum(axis=1) > 0)     # ... but the FSW did fly it before


def test_fsw_killed_lockstep_plant_ends_with_a_clear_message(tmp_path, procs):
    e_sim = transport.loopback(transport.free_port())
    procs.start("sim", _node("sim", "nominal", "lockstep", tmp_path / "sim", listen=[e_sim],
                             extra=["--fsw-timeout", "2"]))
    procs.start("fsw", _node("fsw", "nominal", "lockstep", tmp_path / "fsw", connect=[e_sim]))
    deadline = time.monotonic() + 60
    while "waiting for the plant" not in procs.log("fsw") and time.monotonic() < deadline:
        time.sleep(0.2)
    time.sleep(3.0)
    procs.stop("fsw", signal.SIGKILL)
    rc = procs.wait("sim", 30)
    assert rc == 3
    info = _json(tmp_path / "sim" / "sim.json")
    assert info["end_reason"] == "fsw_timeout"
    assert "has not answered" in info["message"] and "ending the run" in info["message"]
    assert "has not answered" in procs.log("sim")


ATTACKER = r"""
import sys, time
import numpy as np
from interfaces import records, transport
from interfaces.codec import Codec
from interfaces.keys import keys
K = keys(sys.argv[1])
s = transport.open_session("attacker", [sys.argv[2]], None)     # the plant and the FSW connect to it
pubs = {k: transport.publisher(s, k) for k in (K.sensors, K.jets, K.faults, K.truth, K.state, K.events)}
sub = transport.subscriber(s, K.jets)
print("ready", flush=True)
captured = None
while captured is None:                        # the FSW owns the jets key first
    smp = transport.recv(sub, 0.1)
    if smp is not None:
        captured = smp.payload.to_bytes()
while len(list(s.info.peers_zid())) < 2:       # both nodes are its peers: every put reaches both
    time.sleep(0.01)
print("captured", flush=True)
rng = np.random.default_rng(7)
intruder = Codec.for_schema("JETS")            # another publisher id on the jets key
fake = records.new(records.JETS)
sent = 0
while True:                                    # until killed
    for key, pub in pubs.items():
        pub.put(rng.bytes(int(rng.integers(0, 400))))                   # random bytes
        pub.put(captured[: int(rng.integers(1, len(captured)))])        # truncated
    pubs[K.jets].put(captured)                                          # replay
    fake["k"], fake["u"] = sent, 1
    pubs[K.jets].put(intruder.encode(fake, sent, time.monotonic_ns()))  # second publisher
    sent += 1
    if sent % 100 == 0:
        print("sent", sent, flush=True)
    time.sleep(0.005)
"""


def test_garbage_replays_and_a_second_publisher_on_every_key(tmp_path, procs):
    """While a lockstep run flies, a hostile process puts random bytes, truncated frames,
    replays, out-of-order frames and a second JETS publisher on every key: the run
    completes, every bad payload is rejected and counted, nothing crashes."""
    e_sim = transport.loopback(transport.free_port())
    e_fsw = transport.loopback(transport.free_port())
    e_att = transport.loopback(transport.free_port())
    # the attacker is up (session, publishers, subscriber) before the run starts and both
    # nodes connect to it as they open their sessions, so that it attacks the whole run
    # however fast the run and however slow the host: a lockstep run of 400 s takes a few
    # seconds, and an attacker that connected to them would still be waiting out its retry
    log = open(tmp_path / "attacker.log", "w")
    attacker = subprocess.Popen([sys.executable, "-c", ATTACKER, PREFIX, e_att], stdout=log,
                                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    procs.p["attacker"] = attacker
    deadline = time.monotonic() + 60.0
    while "ready" not in (tmp_path / "attacker.log").read_text() and attacker.poll() is None \
            and time.monotonic() < deadline:
        time.sleep(0.05)
    assert "ready" in (tmp_path / "attacker.log").read_text(), (tmp_path / "attacker.log").read_text()
    procs.start("sim", _node("sim", "case1", "lockstep", tmp_path / "sim", listen=[e_sim], connect=[e_att],
                             extra=["--duration", "400"]))
    procs.start("fsw", _node("fsw", "case1", "lockstep", tmp_path / "fsw", listen=[e_fsw],
                             connect=[e_sim, e_att]))
    try:
        assert procs.wait("sim", 180) == 0, procs.log("sim")
    finally:
        attacker.kill()                           # by pid, whatever state its session is in
        attacker.wait(10)
        log.close()
    assert procs.stop("fsw") == 0
    att = (tmp_path / "attacker.log").read_text()
    assert "captured" in att, att              # it attacked a live run (the counts below show what)
    sim = _json(tmp_path / "sim" / "sim.json")
    fsw = _json(tmp_path / "fsw" / "fsw.json")
    assert sim["end_reason"] == "duration" and sim["t_end_s"] == pytest.approx(400.0)
    rj = sim["rejects"]
    assert rj.get("size", 0) + rj.get("magic", 0) + rj.get("crc", 0) > 0
    assert rj.get("second_publisher", 0) > 0
    assert rj.get("replay_or_out_of_order", 0) > 0
    assert sum(fsw["sensor_rejects"].values()) > 0
    assert any(e["code"].startswith("rx_") for e in fsw["event_log"])
    # nothing hostile reached the plant or the FSW: the attacked lockstep run flew exactly
    # the trajectory of the undisturbed batch run
    h = np.load(tmp_path / "sim" / "sim_history.npz")
    _, hb, _ = batch.run("case1", duration_s=400)
    assert np.array_equal(h["bank_rad"], hb["bank_rad"])
    assert np.array_equal(h["h_m"], hb["h_m"])
