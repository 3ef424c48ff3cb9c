"""The ground segment against a real SIL: the nominal scenario flown in real time as
processes, case 1's failures injected from the ground at about 2.5 s (the scripted CLI and
the same request path the console uses), each acknowledged, FDIR's STATUSTEXT seen for each
jet, and the run ends within the case-1 bound."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from gse.cli import execute
from gse.client import GroundClient, make_request
from gse.tlog import read_records
from interfaces import transport
from interfaces.mavlink.signing import SigningKey

pytestmark = pytest.mark.slow
PY = [sys.executable, "-m", "ellipsled.cli"]


def _free_udp() -> int:
    import socket
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_case1_failures_injected_from_the_ground_during_a_realtime_sil(tmp_path):
    key_file = tmp_path / "keys" / "signing.key"
    key_file.parent.mkdir()
    key = SigningKey.generate()
    key.write_file(str(key_file))
    vehicle, gcs = _free_udp(), _free_udp()
    out = tmp_path / "run"
    log = open(tmp_path / "run.log", "w")
    run = subprocess.Popen(PY + ["run", "nominal", "--realtime", "--rt", "--duration", "25", "--out", str(out),
                                 "--rerun", "none", "--no-plots", "--signing-key", str(key_file),
                                 "--mavlink-bind", f"udp:127.0.0.1:{vehicle}", "--gcs", f"udp:127.0.0.1:{gcs}"],
                           stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    client = GroundClient(key, listen=f"udp:127.0.0.1:{gcs}", vehicle=f"udp:127.0.0.1:{vehicle}",
                          tlog=str(tmp_path / "ground.tlog"))
    try:
        deadline = time.monotonic() + 90
        while "first jet command" not in (tmp_path / "run.log").read_text():
            assert run.poll() is None and time.monotonic() < deadline, (tmp_path / "run.log").read_text()
            client.poll(0.05)
        t_fly = time.monotonic()
        while time.monotonic() < t_fly + 2.5:
            client.poll(0.02)
        assert client.state.last_heartbeat_t is not None, "the vehicle's heartbeat must reach the ground"
        # three jets through the console's request path, the fourth through the scripted CLI
        for jet in (1, 2, 17):
            assert execute(client, make_request("inject", str(jet), "off"), timeout_s=1.0, retries=3) == 0
        cli = subprocess.run(PY + ["gse", "inject", "--jet", "18", "--kind", "off", "--vehicle",
                                   f"udp:127.0.0.1:{vehicle}", "--signing-key", str(key_file)],
                             capture_output=True, text=True, timeout=60)
        assert cli.returncode == 0, cli.stdout + cli.stderr
        assert "ACCEPTED" in cli.stdout
        # invalid requests are refused, never silently accepted
        assert execute(client, make_request("inject", "5", "degraded", "1.5"), timeout_s=1.0, retries=1) != 0
        # FDIR reports each jet (the jets must be commanded on to show a failed-off fault)
        want = {f"JET {j} FAILED OFF" for j in (1, 2, 17, 18)}
        seen = set()
        deadline = time.monotonic() + 20
        while not want <= seen and time.monotonic() < deadline:
            client.poll(0.05)
            seen |= {e.text for e in client.state.events}
        assert want <= seen, seen
        assert run.wait(120) == 0, (tmp_path / "run.log").read_text()
    finally:
        client.close()
        if run.poll() is None:
            run.send_signal(signal.SIGTERM)
            try:
                run.wait(15)
            except subprocess.TimeoutExpired:
                run.kill()
                run.wait(5)
        log.close()
    import json
    s = json.loads((out / "summary.json").read_text())
    assert s["completed"]
    assert sorted(d["jet"] for d in s["fdir"]["detections"]) == [1, 2, 17, 18]
    assert s["fdir"]["false_alarms"] == 0
    assert s["bank_err_max_after_fault_deg"] <= 5.0
    # the ground's telemetry log holds both directions
    recs = list(read_records(str(tmp_path / "ground.tlog")))
    assert len(recs) > 50
