"""The console's screens without commanding: watching live telemetry without the signing
key (nothing sent), and replaying a recorded .tlog (the same final state and events as the
live session that recorded it). Headless, Textual's pilot; the FSW and its ground link in
this process (tests/rig.py)."""
from __future__ import annotations

import asyncio

import pytest

from gse.client import GroundClient
from gse.console import GroundConsole
from gse.replay import TlogReplay
from gse.tlog import TlogWriter

from tests.rig import Rig


async def _type(pilot, line: str) -> None:
    await pilot.press(":")
    for ch in line:
        await pilot.press("space" if ch == " " else ch)
    await pilot.press("enter")
    await pilot.press("escape")


def test_view_only_console_shows_the_vehicle_and_sends_nothing(tmp_path):
    rig = Rig(tmp_path)
    viewer = GroundClient(None, listen="udp:127.0.0.1:0")
    rig.gl.gcs = viewer.address                # the vehicle's telemetry goes to the viewer
    try:
        async def scenario():
            app = GroundConsole(viewer, poll_s=0.05, refresh_s=0.1)
            async with app.run_test(size=(140, 45)) as pilot:
                for _ in range(8):
                    rig.fly(5)
                    await pilot.pause(0.06)
                top = str(app.query_one("#top").render())
                assert "VIEW ONLY" in top and "ENTRY" in top and "ARMED" in top, top
                assert "ELLIPSLED_ENTRY_STATE" in viewer.state.latest
                rx_before = rig.gl.stats["rx_datagrams"]
                await _type(pilot, "inject 17 failed_off")
                await pilot.press("3")                 # SAFE by key (and Enter): refused too
                await pilot.press("enter")
                for _ in range(4):
                    rig.fly(5)
                    await pilot.pause(0.06)
                assert "inject jet 17 failed_off: not sent (view only: no signing key)" in app.ack_lines, app.ack_lines
                assert any(line.startswith("mode safe: not sent") for line in app.ack_lines)
                assert rig.gl.stats["rx_datagrams"] == rx_before and viewer.stats["tx_frames"] == 0
                assert rig.injected == [] and int(rig.fsw.modes.mode) == 1
        asyncio.run(scenario())
    finally:
        viewer.close()
        rig.close()


def test_replay_of_a_recorded_session_shows_its_final_state_and_events(tmp_path):
    tlog = tmp_path / "session.tlog"
    rig = Rig(tmp_path, tlog=str(tlog))
    try:
        rig.fly(50)
        assert rig.command("inject", "17", "failed_off") == 0
        assert rig.command("mode", "safe") == 0
        rig.fly(200)
        rig.exchange(lambda: False, 0.2)
        live = rig.gcs.state
        live_events = [e.text for e in live.events]
        live_bank = live.latest["ELLIPSLED_ENTRY_STATE"].bank
    finally:
        rig.close()
    assert "GND INJECT JET 17 FAILED_OFF" in live_events

    replay = TlogReplay(tlog, speed=1e6)

    async def scenario():
        app = GroundConsole(replay, poll_s=0.02, refresh_s=0.05)
        async with app.run_test(size=(140, 45)) as pilot:
            for _ in range(20):
                await pilot.pause(0.05)
                if replay.done:
                    break
            await pilot.pause(0.2)
            assert replay.done
            top = str(app.query_one("#top").render())
            assert "REPLAY OF SESSION.TLOG" in top and "(END)" in top and "SAFE" in top, top
            assert [e.text for e in replay.state.events] == live_events
            assert app._events_shown == len(live_events)
            assert replay.state.latest["ELLIPSLED_ENTRY_STATE"].bank == live_bank
            entry = app._entry_table()
            import math
            cells = [str(c) for col in entry.columns for c in col._cells]
            assert f"{math.degrees(live_bank):8.2f}°" in cells, cells
            await _type(pilot, "mode entry")
            assert app.ack_lines[-1] == "mode entry: not sent (replay of session.tlog)"
    asyncio.run(scenario())
    replay.close()


def test_replay_paces_the_recording_by_its_timestamps_times_the_speed(tmp_path):
    rig = Rig(tmp_path)
    frames = []
    try:
        rig.fly(30)
        for name in ("HEARTBEAT", "ELLIPSLED_ENTRY_STATE"):
            frames.append(rig.gl.link.pack(rig.gcs.state.latest[name]))
    finally:
        rig.close()
    path = tmp_path / "paced.tlog"
    with TlogWriter(path) as w:
        for i in range(10):                       # one frame a second for 10 s
            w.write(frames[i % 2], t_unix_s=1_700_000_000.0 + i)
    wall = [100.0]
    r = TlogReplay(path, speed=4.0, monotonic=lambda: wall[0])
    assert r.poll() == 1                          # t = 0: the first frame
    wall[0] += 1.0                                # 1 s of wall = 4 s of recording
    assert r.poll() == 4 and r.position == 5
    assert r.clock() == pytest.approx(1_700_000_004.0)
    wall[0] += 10.0
    r.poll()
    assert r.done and r.state.rx_counts == {"HEARTBEAT": 5, "ELLIPSLED_ENTRY_STATE": 5}
    with pytest.raises(ValueError):
        TlogReplay(path, speed=0)
    (tmp_path / "empty.tlog").write_bytes(b"")
    with pytest.raises(ValueError, match="no MAVLink records"):
        TlogReplay(tmp_path / "empty.tlog")
