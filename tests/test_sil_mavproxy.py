"""MAVProxy, the stock pip package run headless (no GUI module), against a real-time SIL on
loopback: a scripted session on its stdin, checked in what it prints.

It connects with MAVLink 2 and signs with the run's key derived from a passphrase as
MAVProxy's ``signing key`` does (SHA-256 of the passphrase), fetches the parameter list
and shows it, sets one parameter (signed), and shows GLOBAL_POSITION_INT. Checked against
the run itself: every parameter shown equals the value the FSW process reports at the end
of the run (its own record, not the link's), the set parameter changed in the FSW, and
the positions shown match the plant's truth history at the message's time.

MAVProxy is installed without its declared GUI and map dependencies (vtk, opencv-python,
matplotlib, quantized-mesh-tile): its headless core needs only pymavlink and pyserial
(requirements.in says why).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import re
import secrets
import subprocess
import sys
import time

import numpy as np
import pytest

from ellipsled.sil.history import History
from fsw.flightsoftware import declarations
from fsw.params import ParamRegistry
from interfaces.mavlink.signing.keys import SigningKey
from tests.procs import start_ground_sil, stop

pytest.importorskip("MAVProxy", reason="MAVProxy is not installed (requirements.lock pins it, "
                                       "installed with --no-deps)")
pytestmark = [pytest.mark.slow, pytest.mark.realtime]

# a line of MAVProxy's console, once its prompts ("MAV> ", "Mode(1)> ") are stripped
_PROMPT = re.compile(r"^(?:\S*> )+")
_PARAM_LINE = re.compile(r"^([A-Z][A-Z0-9_]{0,15})\s+(-?[0-9.]+(?:e[-+]?\d+)?)$")
_GPI = re.compile(r"GLOBAL_POSITION_INT \{time_boot_ms : (\d+), lat : (-?\d+), lon : (-?\d+), alt : (-?\d+),")
SET_ID, SET_NAME, SET_VALUE = "F_ALT_MAX_M", "fdir.alt_max_m", 900_000.0   # a plausibility bound far above the flight


class Console:
    """MAVProxy's stdin and everything it has printed so far (stdout and stderr in one file)."""

    def __init__(self, proc: subprocess.Popen, out_path):
        self.proc, self.out_path = proc, out_path

    def send(self, line: str) -> None:
        self.proc.stdin.write(line + "\n")
        self.proc.stdin.flush()

    def lines(self) -> list[str]:
        return [_PROMPT.sub("", ln).strip() for ln in self.out_path.read_text(errors="replace").splitlines()]

    def wait_for(self, cond, timeout_s: float):
        """The first non-empty ``cond(lines)`` within ``timeout_s``, else None."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end and self.proc.poll() is None:
            got = cond(self.lines())
            if got:
                return got
            time.sleep(0.2)
        return cond(self.lines()) or None


def _params_shown(lines: list[str]) -> dict[str, float]:
    return {m[1]: float(m[2]) for m in map(_PARAM_LINE.match, lines) if m}


def test_mavproxy_headless_shows_position_and_parameters(tmp_path):
    passphrase = secrets.token_hex(16)
    key = SigningKey(hashlib.sha256(passphrase.encode("ascii")).digest())     # MAVProxy's passphrase_to_key
    sil = start_ground_sil(tmp_path, duration_s=45.0, key=key)
    run, out = sil.run, sil.out
    home = tmp_path / "home"                 # MAVProxy reads ~/.mavproxy: none of the user's settings
    home.mkdir()
    env = dict(os.environ, HOME=str(home), PYTHONUNBUFFERED="1", MAVLINK20="1")
    mp_out = tmp_path / "mavproxy.out"
    with open(mp_out, "w") as f:
        mp = subprocess.Popen(
            [sys.executable, "-m", "MAVProxy.mavproxy", f"--master=udpin:127.0.0.1:{sil.gcs}", "--mav20",
             "--no-state", "--default-modules=signing,param", "--streamrate=-1"],
            stdin=subprocess.PIPE, stdout=f, stderr=subprocess.STDOUT, env=env, cwd=tmp_path, text=True)
    con = Console(mp, mp_out)
    n_params = len(ParamRegistry(declarations()).settable())
    try:
        assert con.wait_for(lambda ls: any("Detected vehicle 1:1" in ln for ln in ls), 120), \
            mp_out.read_text() + sil.log()
        con.send(f"signing key {passphrase}")
        con.send("param fetch")
        assert con.wait_for(lambda ls: any(f"Received {n_params} parameters" in ln for ln in ls), 30), \
            mp_out.read_text()
        con.send("param show *")
        shown = con.wait_for(lambda ls: p if len(p := _params_shown(ls)) >= n_params else None, 10)
        assert shown is not None and len(shown) == n_params, mp_out.read_text()

        con.send(f"param set {SET_ID} {SET_VALUE:g}")
        n_before = len(con.lines())

        for _ in range(10):                   # until the vehicle's PARAM_VALUE has come back
            con.send(f"param show {SET_ID}")
            if con.wait_for(lambda ls: _params_shown(ls[n_before:]).get(SET_ID) == SET_VALUE, 1.0):
                break
        assert _params_shown(con.lines()[n_before:]).get(SET_ID) == SET_VALUE, mp_out.read_text()

        for _ in range(6):
            con.send("status GLOBAL_POSITION_INT")
            time.sleep(1.0)
        assert run.wait(120) == 0, sil.log()
    finally:
        stop(mp, 10.0)
        stop(run)
    text = mp_out.read_text(errors="replace")
    assert "Traceback" not in text, text

    # --- parameters: what MAVProxy showed against the FSW process's own report
    report = json.loads((out / "fsw.json").read_text())["params"]
    ids = ParamRegistry(declarations()).ids
    assert report[SET_NAME] == SET_VALUE
    for name, pid in ids.items():
        if name != SET_NAME:
            assert shown[pid] == pytest.approx(report[name], rel=1e-6), pid     # sent as float32

    # --- position: GLOBAL_POSITION_INT shown against the plant's truth at the message's time
    h = History.load(out / "history.npz")
    t = np.asarray(h["t_s"])
    lon_truth = np.unwrap(np.asarray(h["lon_rad"]))
    checked = 0
    for m in _GPI.finditer(text):
        ts, lat, lon, alt = int(m[1]) * 1e-3, int(m[2]) * 1e-7, int(m[3]) * 1e-7, int(m[4]) * 1e-3
        if not t[0] <= ts <= t[-1]:
            continue
        assert lat == pytest.approx(math.degrees(np.interp(ts, t, np.asarray(h["lat_rad"]))), abs=0.01)
        dlon = math.remainder(math.radians(lon) - float(np.interp(ts, t, lon_truth)), 2 * math.pi)
        assert abs(dlon) < math.radians(0.01)
        assert alt == pytest.approx(float(np.interp(ts, t, np.asarray(h["h_m"]))), abs=500.0)
        checked += 1
    assert checked >= 5, text
