"""The ground segment against a real SIL: the nominal scenario flown in real time as
processes; at about 2.5 s case 1's failures are injected from the ground console (Textual,
driven headlessly) and the scripted CLI, each acknowledged; FDIR's STATUSTEXT is seen for
each jet, and the run ends within the case-1 bound."""
from __future__ import annotations

import asyncio
import subprocess
import time

import pytest

from ellipsled.procs import ELLIPSLED
from gse.client import GroundClient
from gse.console import GroundConsole
from gse.tlog import read_records

from tests.procs import start_ground_sil, stop

pytestmark = [pytest.mark.slow, pytest.mark.realtime]



def test_case1_failures_injected_from_the_ground_during_a_realtime_sil(tmp_path):
    sil = start_ground_sil(tmp_path)
    run, key, key_file, vehicle, gcs, out = sil.run, sil.key, sil.key_file, sil.vehicle, sil.gcs, sil.out
    client = GroundClient(key, listen=f"udp:127.0.0.1:{gcs}", vehicle=f"udp:127.0.0.1:{vehicle}",
                          tlog=str(tmp_path / "ground.tlog"))
    log_text = sil.log

    async def console_session():
        """The operator's console (Textual, headless pilot) during the real-time run."""
        app = GroundConsole(client, timeout_s=1.0, retries=3, poll_s=0.05, refresh_s=0.3)
        async with app.run_test(size=(140, 45)) as pilot:
            async def until(cond, timeout_s, what):
                t_end = time.monotonic() + timeout_s
                while not cond():
                    assert run.poll() is None or what == "end", f"{what}:\n{log_text()}"
                    assert time.monotonic() < t_end, f"timed out waiting for {what}; acks {app.ack_lines}"
                    await pilot.pause(0.05)

            async def type_line(line):
                await pilot.press(":")
                for ch in line:
                    await pilot.press("space" if ch == " " else ch)
                await pilot.press("enter")
                await pilot.press("escape")

            await until(lambda: "first jet command" in log_text(), 90, "the SIL to fly")
            t_fly = time.monotonic()
            await until(lambda: time.monotonic() > t_fly + 2.5, 10, "t = 2.5 s")
            top = str(app.query_one("#top").render())
            assert "ENTRY" in top and "ARMED" in top, top
            # jet 18 through the scripted CLI (its own port and link), at the same moment ...
            cli_task = asyncio.create_task(asyncio.to_thread(subprocess.run, ELLIPSLED + [
                "gse", "inject", "--jet", "18", "--kind", "failed_off", "--vehicle", f"udp:127.0.0.1:{vehicle}",
                "--signing-key", str(key_file)], capture_output=True, text=True, timeout=60))
            # ... and jets 2, 17, 1 from the console: two by its command handler (what Enter
            # runs), the last typed key by key on its command line
            for jet in (2, 17):
                app.submit(f"inject {jet} failed_off")
                await until(lambda: f"inject jet {jet} failed_off: ACCEPTED" in app.ack_lines, 10, f"ACK jet {jet}")
            await type_line("inject 1 failed_off")
            await until(lambda: "inject jet 1 failed_off: ACCEPTED" in app.ack_lines, 10, "ACK jet 1")
            cli = await cli_task
            assert cli.returncode == 0 and "ACCEPTED" in cli.stdout, cli.stdout + cli.stderr
            # an invalid request is refused, never silently accepted
            n_before = len(app.ack_lines)
            app.submit("inject 5 degraded 1.5")               # eta out of range: refused before sending
            await pilot.pause(0.2)
            assert len(app.ack_lines) > n_before and "ACCEPTED" not in app.ack_lines[-1], app.ack_lines
            # ... and the vehicle denies it when a station sends it anyway (MAV_RESULT_DENIED = 2)
            assert client.command(420, 101, 4, 5, 1.5, timeout_s=1.0, retries=2) == 2
            # FDIR reports each jet (a failed-off jet shows once it is commanded on)
            want = {f"JET {j} FAILED_OFF" for j in (1, 2, 17, 18)}
            await until(lambda: want <= {e.text for e in client.state.events}, 30, "FDIR STATUSTEXTs")
            await until(lambda: run.poll() is not None, 120, "end")

    try:
        asyncio.run(console_session())
        assert run.wait(30) == 0, log_text()
    finally:
        client.close()
        stop(run)
    import json
    s = json.loads((out / "summary.json").read_text())
    assert s["completed"]
    dets = {d["jet"]: d["kind"] for d in s["fdir"]["detections"]}
    assert {j: dets.get(j) for j in (1, 2, 17, 18)} == {1: "failed_off", 2: "failed_off", 17: "failed_off",
                                                          18: "failed_off"}
    assert s["fdir"]["false_alarms"] == 0, s["fdir"]
    assert s["bank_err_max_after_fault_deg"] <= 5.0
    # the ground's telemetry log holds both directions
    recs = list(read_records(str(tmp_path / "ground.tlog")))
    assert len(recs) > 50
