"""The ground console driven headlessly (Textual's run_test pilot): it shows the vehicle's
state from live telemetry, sends an injection typed on the command line and from keys,
and shows the ACK; bad command lines are answered in the panel, never sent.
"""
from __future__ import annotations

import asyncio
import math

import pytest

from gse.console import GroundConsole
from interfaces.event_catalogue import EV
from interfaces.mavlink import dialect as mav

from tests.rig import Rig, flown


@pytest.fixture
def rig(tmp_path):
    with flown(tmp_path, 30) as r:
        yield r


def test_console_shows_state_and_injects_with_ack(rig):
    async def scenario():
        app = GroundConsole(rig.gcs, timeout_s=0.5, retries=2, poll_s=0.1, refresh_s=0.3)
        async with app.run_test(size=(140, 45)) as pilot:
            async def pump(n=4):
                for _ in range(n):
                    rig.fly(5)                     # the vehicle flies and its link ticks
                    await pilot.pause(0.11)        # the console polls every 0.1 s

            await pump(4)
            top = str(app.query_one("#top").render())
            assert "ENTRY" in top and "ACTIVE" in top and "ARMED" in top
            entry = app.query_one("#entry").render()
            assert entry is not None and "ELLIPSLED_ENTRY_STATE" in rig.gcs.state.latest
            jets_txt = app._jet_table()
            assert jets_txt.row_count == 3
            # command line: inject jet 17 failed_off
            await pilot.press(":")
            for ch in "inject 17 failed_off":
                await pilot.press("space" if ch == " " else ch)
            await pilot.press("enter")
            await pump()
            assert rig.injected and rig.injected[-1] == (17, "failed_off", 1.0), app.ack_lines
            assert "inject jet 17 failed_off: ACCEPTED" in app.ack_lines
            # keys: Escape leaves the command line; "1" writes the STANDBY request on it, sent
            # by Enter only
            await pilot.press("escape")
            await pilot.press("1")
            await pump()
            assert not any(a.startswith("mode standby") for a in app.ack_lines) and int(rig.fsw.modes.mode) == 1
            assert app.query_one("#cmdline").value == "mode standby"
            await pilot.press("enter")
            await pump()
            assert "mode standby: ACCEPTED" in app.ack_lines and int(rig.fsw.modes.mode) == 0
            # a bad line is explained, not sent
            n_acks = len(rig.gcs.state.acks)
            app.submit("inject 19 failed_off")
            assert any("jet: must be in 0..18" in a for a in app.ack_lines)
            await pump(2)
            assert len(rig.gcs.state.acks) == n_acks
            # events panel carries the FDIR / mode events with severities
            rig.fly(150)
            await pump()
            texts = [e.text for e in rig.gcs.state.events]
            assert "GND INJECT JET 17 FAILED_OFF" in texts
            assert app._events_shown == rig.gcs.state.events_total
            status = rig.gcs.state.latest["HEARTBEAT"].system_status
            assert status in (mav.MAV_STATE_STANDBY, mav.MAV_STATE_CRITICAL)

    asyncio.run(scenario())


def _text(renderable) -> str:
    from rich.console import Console
    con = Console(width=60, record=True, color_system=None)
    con.print(renderable)
    return con.export_text()


@pytest.mark.parametrize("scenario", ["guided-nominal", "case1"])
def test_console_shows_guidance_and_position_as_the_vehicle_reports_them(tmp_path, scenario):
    r = Rig(tmp_path, scenario=scenario)
    try:
        r.fly(120)                     # guided: corrections of the cycles at 0 and 1 s applied

        async def run():
            app = GroundConsole(r.gcs, timeout_s=0.5, retries=2, poll_s=0.05, refresh_s=0.1)
            async with app.run_test(size=(140, 60)) as pilot:
                r.fly(10)
                r.clock.t += 1.0                       # every stream due at the next tick
                r.exchange(lambda: {"ELLIPSLED_GUIDANCE_STATUS", "GLOBAL_POSITION_INT"}
                           <= set(r.gcs.state.latest), 2.0)
                await pilot.pause(0.3)
                return _text(app._guidance_table()), _text(app._entry_table())

        guidance, entry = asyncio.run(run())
        g = r.gcs.state.latest["ELLIPSLED_GUIDANCE_STATUS"]
        gp = r.gcs.state.latest["GLOBAL_POSITION_INT"]
        assert f"{gp.lat * 1e-7:8.4f}°".strip() in entry and f"{gp.lon * 1e-7:9.4f}°".strip() in entry
        assert f"{gp.alt * 1e-6:8.2f} km".strip() in entry
        if scenario == "case1":
            assert "PROFILE" in guidance
            assert "range to go" in guidance and "pred. miss" in guidance
            assert "km" not in guidance and "bank cmd" not in guidance      # "-": not available
        else:
            e = r.fsw.entry
            assert "NPC" in guidance and e.cycles >= 2
            assert f"{g.range_to_go / 1e3:8.1f} km".strip() in guidance
            assert f"{g.predicted_miss / 1e3:6.2f} km".strip() in guidance
            assert f"{g.downrange_error / 1e3:+7.2f}".strip() in guidance
            assert f"{math.degrees(e.bank_cmd):8.2f}°".strip() in guidance
            assert f"reversals {len(e.lateral.reversals)}" in " ".join(guidance.split())
    finally:
        r.close()


def test_the_events_panel_filters_by_the_catalogues_severities_sources_and_names(rig):
    async def scenario():
        app = GroundConsole(rig.gcs, timeout_s=0.5, retries=2, poll_s=0.1, refresh_s=0.3)
        async with app.run_test(size=(140, 45)) as pilot:
            log = rig.fsw.events
            log.emit(rig.fsw.t_s, EV.JET_FAILED_OFF, jet=3)             # fdir, ERROR
            log.emit(rig.fsw.t_s, EV.FDIR_DELAY, delay_s=2.0)           # fdir, NOTICE
            log.emit(rig.fsw.t_s, EV.JETS_DISARMED)                     # driver, NOTICE
            for _ in range(4):
                rig.fly(5)
                await pilot.pause(0.11)

            def shown():
                return [" ".join(seg.text for seg in line).strip() for line in app.query_one("#events").lines]
            assert any("fdir" in s and "JET 3 FAILED_OFF" in s for s in shown())
            app.submit("events fdir")
            await pilot.pause(0.05)
            assert [s.split(None, 3)[-1] for s in shown()] == ["JET 3 FAILED_OFF", "FDIR DELAY 2.00 S"]
            app.submit("events err driver")                              # ERROR and worse, of the driver
            await pilot.pause(0.05)
            assert shown() == []
            app.submit("events jets_dis")
            await pilot.pause(0.05)
            assert [s.split(None, 3)[-1] for s in shown()] == ["JETS DISARMED"]
            app.submit("events jet")                                     # ambiguous: explained, filter kept
            assert app.ack_lines[-1].startswith("! events: 'jet' is ambiguous")
            app.submit("events all")
            await pilot.pause(0.05)
            assert len(shown()) == len(rig.gcs.state.events) and app.ack_lines[-1] == "events shown: all"

    asyncio.run(scenario())
