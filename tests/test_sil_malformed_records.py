"""Records the SIL's processes cannot have been sent are refused and counted, never flown:
the plant refuses a jet command for a step it has not published yet (one far ahead pinned
the real-time plant: every genuine answer then looked stale), a negative step, or a valve
state other than 0/1 (u = 2 killed the plant). The FSW's side here is this test: a Zenoh
session on loopback that answers the plant's frames and slips the bad records in. The plant
is a real `ellipsled sim` process, stopped by its pid."""
from __future__ import annotations

import json
import subprocess
import time

import numpy as np
import pytest

from ellipsled.procs import ELLIPSLED, stop_process
from interfaces import records, transport
from interfaces.codec import Codec
from interfaces.keys import keys


pytestmark = pytest.mark.slow

PREFIX = "ellipsled/malformed"
K = keys(PREFIX)
START_S = 120.0         # a plant's start-up on a loaded machine (imports, compiled kernels)


class FakeFsw:
    """The FSW's Zenoh side of a run, scripted by a test."""

    def __init__(self, endpoint: str, ready: bool):
        self.session = transport.open_session("fsw", None, [endpoint])
        self.pub = transport.publisher(self.session, K.jets)
        self.sub = transport.subscriber(self.session, K.sensors, capacity=4096)
        self.tokens = [transport.declare_alive(self.session, K, "fsw")]
        if ready:
            self.tokens.append(self.session.liveliness().declare_token(K.ready_fsw))
        self.enc = Codec.for_schema("JETS")
        self.dec = Codec.for_schema("SENSORS")
        self.rec = records.new(records.JETS)
        self.seq = 0

    def send(self, k: int, u, deploy: int = 0) -> None:
        self.rec["k"], self.rec["u"], self.rec["deploy"] = k, u, deploy
        self.pub.put(self.enc.encode(self.rec, self.seq, time.monotonic_ns()))
        self.seq += 1

    def frames(self, plant: subprocess.Popen):
        """The step of each sensor frame until the plant ends."""
        deadline = time.monotonic() + START_S
        while plant.poll() is None:
            assert time.monotonic() < deadline, "the plant did not finish"
            s = transport.recv(self.sub, 0.05)
            if s is not None:
                rec = self.dec.decode(s.payload.to_bytes())
                assert rec is not None, self.dec.last_error
                yield int(rec["k"])

    def close(self) -> None:
        transport.close(*self.tokens, self.sub, self.pub, self.session)


def _plant(tmp_path, endpoint: str, mode: str, duration_s: float) -> subprocess.Popen:
    log = open(tmp_path / "sim.log", "w")
    try:
        return subprocess.Popen(ELLIPSLED + ["sim", "nominal", f"--{mode}", "--prefix", PREFIX, "--listen", endpoint,
                                             "--out", str(tmp_path), "--duration", str(duration_s),
                                             "--wait-peers", str(START_S), "--fsw-timeout", "60"],
                                stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    finally:
        log.close()


def _fly(tmp_path, mode: str, duration_s: float, script) -> dict:
    """Run a plant against the fake FSW; ``script(fsw, k, first)`` answers each frame."""
    endpoint = transport.loopback(transport.free_port())
    plant = _plant(tmp_path, endpoint, mode, duration_s)
    fsw = None
    try:
        fsw = FakeFsw(endpoint, ready=mode == "realtime")
        assert transport.wait_for_subscriber(fsw.pub, START_S), (tmp_path / "sim.log").read_text()
        first = True
        for k in fsw.frames(plant):
            script(fsw, k, first)
            first = False
        rc = plant.wait(30)
    finally:
        stop_process(plant, 10)
        if fsw is not None:
            fsw.close()
    log = (tmp_path / "sim.log").read_text()
    assert rc == 0 and "Traceback" not in log, log
    return json.loads((tmp_path / "sim.json").read_text())


OFF = np.zeros(records.N_JETS, dtype=np.uint8)


def test_lockstep_plant_refuses_u_outside_0_1_a_deploy_code_a_future_and_a_negative_step(tmp_path):
    def script(fsw, k, first):
        if first:
            bad_u = OFF.copy()
            bad_u[4] = 2
            fsw.send(k, bad_u)            # the valve state 2 does not exist
            fsw.send(k, OFF, deploy=7)    # nor the deploy command 7
            fsw.send(k + 1, OFF)          # an answer to a frame not yet published
            fsw.send(-1, OFF)             # a step that never was
        fsw.send(k, OFF)
    info = _fly(tmp_path, "lockstep", 0.2, script)
    assert info["end_reason"] == "duration", info
    assert info["rejects"].get("u_range") == 1 and info["rejects"].get("future_step") == 1, info
    assert info["rejects"].get("negative_step") == 1 and info["rejects"].get("deploy_range") == 1, info["rejects"]
    assert info["end_reason"] == "duration" and info["deploy"]["by"] is None, info
    assert info["steps"] >= 10


@pytest.mark.realtime
def test_realtime_plant_is_not_pinned_by_a_command_for_a_far_future_step(tmp_path):
    answered = {"k": -1}

    def script(fsw, k, first):
        if first:
            fsw.send(2**62, OFF)          # would make every genuine answer "stale"
        if k > answered["k"]:
            fsw.send(k, OFF)
            answered["k"] = k
    info = _fly(tmp_path, "realtime", 2.0, script)
    assert info["rejects"].get("future_step") == 1, info
    # every genuine answer was taken as fresh: none counted stale
    assert info["counts"]["stale_commands"] == 0, info["counts"]
