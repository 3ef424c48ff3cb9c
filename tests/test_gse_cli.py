"""gse CLI and tlog: scripted commands against a live ground link (ticked in a thread, as
the FSW process would from RG2), exit codes by MAV_RESULT, parameter get/set/list, and the
.tlog read back by pymavlink (mavutil and mavlogdump.py) with both directions present.
"""
from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import pytest
from pymavlink import mavutil

from gse import cli
from gse.tlog import read_records
from interfaces.mavlink import dialect as mav

from tests.rig import Rig


class LiveLink:
    """Ticks the rig's ground link every 20 ms in a background thread (the FSW is not
    stepped concurrently: commands and ticks share this one thread, as in the FSW)."""

    def __init__(self, rig):
        self.rig = rig
        self.stop = threading.Event()
        self.t = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self.stop.is_set():
            self.rig.clock.t += 0.02
            self.rig.gl.tick(self.rig.frame)
            time.sleep(0.01)

    def __enter__(self):
        self.t.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.t.join(2.0)


@pytest.fixture
def live(tmp_path):
    r = Rig(tmp_path)
    r.fly(5)
    keyfile = tmp_path / "ground.key"
    with LiveLink(r):
        yield r, keyfile
    r.close()


def run_cli(r, keyfile, *args, tlog=None):
    argv = ["gse", *args, "--vehicle", f"udp:127.0.0.1:{r.gl.address[1]}", "--signing-key", str(keyfile),
            "--timeout", "0.5", "--retries", "2"]
    if tlog:
        argv += ["--tlog", str(tlog)]
    return cli.main(argv)


def test_inject_accepted_exits_0_and_reaches_the_plant(live, capsys):
    r, key = live
    assert run_cli(r, key, "inject", "--jet", "17", "--kind", "failed_off") == 0
    assert "inject jet 17 failed_off: ACCEPTED" in capsys.readouterr().out
    assert r.plant.fault_state[16] == 1


def test_refusals_exit_nonzero_with_the_result_name_and_the_reason(live, capsys):
    r, key = live
    r.inject_answer = False
    assert run_cli(r, key, "inject", "--jet", "3", "--kind", "degraded", "--eta", "0.5") == 1
    err = capsys.readouterr().err
    assert "TEMPORARILY_REJECTED" in err and "PLANT UNAVAILABLE" in err
    # caught before sending: jet 19, eta missing
    assert run_cli(r, key, "inject", "--jet", "19", "--kind", "failed_off") == 2
    assert run_cli(r, key, "inject", "--jet", "3", "--kind", "degraded") == 2
    # vehicle-side denial: STANDBY -> SAFE is not an allowed transition
    assert run_cli(r, key, "mode", "standby") == 0
    assert run_cli(r, key, "mode", "safe") == 1
    assert "mode safe: DENIED" in capsys.readouterr().err


def test_other_commands(live):
    r, key = live
    assert run_cli(r, key, "arm", "off") == 0 and not r.fsw.driver.armed
    assert run_cli(r, key, "ft", "off") == 0 and not r.fsw.allocator.fault_tolerance
    assert run_cli(r, key, "mark", "--jet", "4", "--kind", "degraded", "--eta", "0.3") == 0
    assert r.fsw.fdir.health_active.state[3] == 3
    assert run_cli(r, key, "clear", "--jet", "4") == 0 and r.fsw.fdir.health_active.state[3] == 0
    assert run_cli(r, key, "delay", "2") == 0 and r.fsw.fdir.delay_s == 2.0


def test_param_get_set_list(live, capsys):
    r, key = live
    assert run_cli(r, key, "param", "set", "C_LAMBDA_RADPS", "1.5") == 0
    assert r.fsw.params["control.lambda_radps"] == 1.5
    assert run_cli(r, key, "param", "set", "C_LAMBDA_RADPS", "50") == 1
    err = capsys.readouterr().err
    assert "REFUSED (value stays 1.5)" in err and "C_LAMBDA_RADPS REFUSED: 50 outside" in err
    assert run_cli(r, key, "param", "get", "c_lambda_radps") == 0
    assert capsys.readouterr().out.strip() == "C_LAMBDA_RADPS 1.5"
    assert run_cli(r, key, "param", "list") == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(r.gl.param_names)
    assert run_cli(r, key, "param", "get", "NOPE") == 3


def test_no_answer_is_a_timeout_and_a_missing_key_a_usage_error(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ELLIPSLED_SIGNING_KEY_FILE", raising=False)
    assert cli.main(["gse", "arm", "on", "--vehicle", "udp:127.0.0.1:9"]) == 2
    assert "ELLIPSLED_SIGNING_KEY_FILE" in capsys.readouterr().err
    r = Rig(tmp_path)
    try:                                          # link never ticked: nobody answers
        t0 = time.monotonic()
        assert cli.main(["gse", "arm", "on", "--vehicle", f"udp:127.0.0.1:{r.gl.address[1]}",
                         "--signing-key", str(tmp_path / "ground.key"), "--timeout", "0.1", "--retries", "1"]) == 3
        assert time.monotonic() - t0 < 2.0
        assert "TIMEOUT" in capsys.readouterr().err
    finally:
        r.close()


def test_tlog_has_both_directions_and_is_read_by_pymavlink(live, tmp_path):
    r, key = live
    tlog = tmp_path / "cmd.tlog"
    assert run_cli(r, key, "inject", "--jet", "2", "--kind", "stuck_on", tlog=tlog) == 0
    recs = list(read_records(tlog))
    assert recs and all(1.5e15 < t < 4e15 for t, _ in recs)            # plausible Unix µs
    assert [t for t, _ in recs] == sorted(t for t, _ in recs)
    m = mavutil.mavlink_connection(str(tlog), dialect="common")
    seen = []
    while (msg := m.recv_match()) is not None:
        seen.append((msg.get_srcSystem(), msg.get_type()))
    m.close()
    assert (255, "COMMAND_LONG") in seen and (255, "HEARTBEAT") in seen       # sent
    assert (1, "COMMAND_ACK") in seen                                          # received
    assert any(s == 1 for s, _ in seen) and any(s == 255 for s, _ in seen)
    out = subprocess.run([sys.executable, os.path.join(os.path.dirname(sys.executable), "mavlogdump.py"),
                          "--types", "COMMAND_LONG,COMMAND_ACK", str(tlog)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0
    assert "COMMAND_LONG" in out.stdout and "COMMAND_ACK" in out.stdout
    assert f"command : 420, result : {mav.MAV_RESULT_ACCEPTED}," in out.stdout
