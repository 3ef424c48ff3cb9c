"""A hostile ground cannot knock the vehicle off its schedule: while the real-time SIL flies
(real processes, loopback), a flood of random, malformed, unsigned, badly signed, replayed
and oversized datagrams hits the FSW's MAVLink port at >= 2,000 datagrams/s for >= 10 s.
Its HEARTBEAT keeps coming every second, a genuine signed command is ACCEPTED during the
flood and after it, the kernel drops (almost) nothing at the link's socket where the host
verifies the flood within the intake's budget (else what that budget leaves, each drop
counted), and the telemetry carries the drop counters. Bounded: one run of 40 s of
simulated time, a 12-s flood. What the flood costs the loop's deadlines is a host figure:
`ellipsled bench` flood section.

Timing: the heartbeat's period is asserted (1.5 s at most between two); the SIL runs with
--rt (SCHED_FIFO, root) so other load on the machine cannot stretch it."""
from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from common.model import load_scenario
from gse.client import GroundClient
from gse.commands import make_request
from gse.tlog import TlogWriter, read_records
from interfaces.mavlink.framing import parse_header

from tests.procs import start_ground_sil, stop

pytestmark = [pytest.mark.slow, pytest.mark.realtime, pytest.mark.timing]
RATE, FLOOD_S = 2500.0, 12.0
SCENARIO = "nominal"




def test_a_ground_flood_costs_no_deadline_and_genuine_commands_still_pass(tmp_path):
    sil = start_ground_sil(tmp_path, SCENARIO)
    run, key, vehicle, gcs, out = sil.run, sil.key, sil.vehicle, sil.gcs, sil.out
    client = GroundClient(key, listen=f"udp:127.0.0.1:{gcs}", vehicle=f"udp:127.0.0.1:{vehicle}",
                          tlog=str(tmp_path / "ground.tlog"))
    flood = None
    beats: list[float] = []

    def pump(seconds: float) -> None:
        """Listen like a ground station, noting when each vehicle HEARTBEAT arrives."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            client.poll(0.05)
            t = client.state.last_heartbeat_t
            if t is not None and (not beats or t != beats[-1]):
                beats.append(t)

    def command(words) -> int | None:
        req = make_request(*words)
        pc = client.start(req, timeout_s=1.0, retries=4)
        end = time.monotonic() + 6.0
        while not pc.done and time.monotonic() < end:
            pump(0.05)
        return pc.result

    try:
        end = time.monotonic() + 120
        while "first jet command" not in sil.log():
            assert run.poll() is None and time.monotonic() < end, sil.log()
            time.sleep(0.2)
        pump(2.0)
        assert command(("arm", "on")) == 0                      # before: the link works
        # what an eavesdropper captured: the ground's own signed frames, to replay
        with TlogWriter(tmp_path / "captured.tlog") as w:
            for _, frame in read_records(tmp_path / "ground.tlog"):
                if parse_header(frame).sysid == 255:
                    w.write(frame)
        flood = subprocess.Popen([sys.executable, "-m", "ellipsled.bench.flood", "--target",
                                  f"udp:127.0.0.1:{vehicle}", "--rate", str(RATE), "--seconds", str(FLOOD_S),
                                  "--replay", str(tmp_path / "captured.tlog")],
                                 stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        assert flood.stdout.readline().strip() == "flooding"
        t_flood = time.time()
        pump(4.0)
        during = command(("ft", "on"))                           # during the flood
        pump(max(0.0, t_flood + FLOOD_S - time.time()))
        sent = json.loads(flood.stdout.read().strip().splitlines()[-1])
        assert flood.wait(10) == 0
        t_after = time.time()
        after = command(("arm", "on"))                           # after it
        pump(2.0)
        sys_status = client.state.latest["SYS_STATUS"]
        assert run.wait(120) == 0, sil.log()
    finally:
        client.close()
        if flood is not None:
            stop(flood)
        stop(run)

    assert sent["rate_per_s"] >= 2000 and sent["seconds"] >= 10, sent
    assert during == 0 and after == 0, (during, after)
    in_flood = [t for t in beats if t_flood - 1.0 <= t <= t_after + 1.0]
    gaps = [b - a for a, b in zip(in_flood, in_flood[1:])]
    assert len(in_flood) >= FLOOD_S and max(gaps) <= 1.5, gaps          # HEARTBEAT every second
    fsw = json.loads((out / "fsw.json").read_text())
    print("executive:", fsw["executive"], "tasks:", fsw["tasks_us"])
    # the telemetry says what the link refused and dropped (SYS_STATUS, standard fields):
    # errors_comm every rejection, errors_count1 datagrams the kernel dropped on the full
    # queue, errors_count2 those refused before any CRC or signature work
    assert sys_status.errors_comm > 0 and sys_status.errors_count2 > 0, sys_status
    gl = fsw["ground_link"]
    assert gl["refused_early"] > 0 and gl["rx_datagrams"] + gl["kernel_drops"] >= 0.9 * sent["sent"], gl
    # the link reads its socket every control period (GroundLink.listen): where the intake's
    # budget (2 ms a call) reads a period's datagrams, the queue never fills, so no genuine
    # command is lost there (read only at RG2 ticks: ~2/3 dropped). A host too slow to verify
    # the flood within that budget (its calls stop on it: on one, ~3 ms for a period's 50
    # datagrams, a budget hit every cycle of the flood, ~half dropped) drops what the budget
    # leaves: then the drops are the budget's, and each is counted in the telemetry
    # (SYS_STATUS errors_count1, saturating) -- the in-process test on a clock that stands
    # still judges the reading schedule alone (test_groundlink_security.py)
    cycles = FLOOD_S / load_scenario(SCENARIO).dt_control_s
    if gl["rx_budget_hits"] < 0.5 * cycles:
        assert gl["kernel_drops"] <= 0.01 * sent["sent"], gl
    assert sys_status.errors_count1 == min(gl["kernel_drops"], 0xFFFF), (sys_status, gl)
