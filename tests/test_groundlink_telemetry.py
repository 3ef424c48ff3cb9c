"""Ground link telemetry: configured rates are met, every event becomes one STATUSTEXT,
the attitude and entry-state telemetry agree with the plant's truth, a stock pymavlink
client with only common.xml sees the vehicle, its attitude and its STATUSTEXT.

Independent truth: sim.plant.Plant.truth() (altitude, speed, gamma, psi, latitude,
longitude, bank), pymavlink's own quaternion-to-Euler conversion, and counting.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.quaternion import Quaternion

from fsw.groundlink import DEFAULT_RATES_HZ, GroundLink
from interfaces.mavlink import dialect as mav

from tests.rig import Clock, Rig, flown, write_key


@pytest.fixture
def rig(tmp_path):
    with flown(tmp_path, 0) as r:
        yield r


def test_stream_rates_follow_the_configuration(tmp_path):
    rates = {"ATTITUDE": 4.0, "ELLIPSLED_ENTRY_STATE": 2.0, "ATTITUDE_TARGET": 0.0}
    r = Rig(tmp_path, rates=rates)
    try:
        r.fly(500)                                # 10 s of flight, link ticked at 10 Hz
        r.exchange(lambda: False, 0.3)
        n = r.gcs.state.rx_counts
        # first sample at t=0.1 s then one per period over 10 s (fake clock)
        assert n["HEARTBEAT"] == 10
        assert n["ATTITUDE"] == 40
        assert n["ELLIPSLED_ENTRY_STATE"] == 20
        assert n["ATTITUDE_QUATERNION"] == 100                # default 10 Hz
        assert "ATTITUDE_TARGET" not in n
        assert n["NAMED_VALUE_FLOAT"] == 6 * 50
    finally:
        r.close()


def test_bad_rate_configuration_is_refused(tmp_path, rig):
    key = write_key(tmp_path, "k2")
    for bad in ({"ATTITUDE": -1.0}, {"ATTITUDE": float("nan")}, {"NOPE": 1.0}, {"ATTITUDE": 1000.0}):
        with pytest.raises(ValueError, match="rates"):
            GroundLink(rig.fsw, key, bind="udp:127.0.0.1:0", rates=bad, clock=Clock())
    with pytest.raises(ValueError, match="gcs"):
        GroundLink(rig.fsw, key, gcs="udp:localhost", bind="udp:127.0.0.1:0")
    assert set(DEFAULT_RATES_HZ) >= {"HEARTBEAT", "ACTUATOR_OUTPUT_STATUS", "ELLIPSLED_LOOP_TIMING"}


def test_every_event_becomes_one_statustext_with_its_severity(rig):
    rig.fly(20)
    for i in range(5):
        rig.fsw.events.emit(rig.fsw.t_s, 3 + (i % 3), "test", f"code{i}", f"TEST EVENT {i}")
    rig.fsw.events.drain()                       # another consumer draining the queue changes nothing
    rig.exchange(lambda: False, 0.2)
    hist = rig.fsw.events.history
    got = [(e.severity, e.text) for e in rig.gcs.state.events]
    assert got == [(int(e.severity), e.text[:50]) for e in hist]
    assert ("MODE STANDBY->ENTRY (start)" in [t for _, t in got])


def test_events_after_the_last_tick_are_flushed_at_shutdown(rig):
    rig.fly(20)
    rig.exchange(lambda: False, 0.1)
    rig.fsw.events.emit(rig.fsw.t_s, 4, "test", "last", "LAST WORDS")      # after the last tick
    rig.gl.flush_events()
    end = time.monotonic() + 2.0
    while "LAST WORDS" not in [e.text for e in rig.gcs.state.events] and time.monotonic() < end:
        rig.gcs.poll(0.02)
    assert [e.text for e in rig.gcs.state.events][-1] == "LAST WORDS"


def test_attitude_and_entry_state_agree_with_the_plant_truth(rig):
    rig.fly(100)
    rig.clock.t += 1.0
    rig.gl.tick(rig.frame)
    rig.exchange(lambda: False, 0.1)
    truth = rig.plant.truth()
    st = rig.gcs.state.latest
    es = st["ELLIPSLED_ENTRY_STATE"]
    assert es.altitude == pytest.approx(truth["h_m"], abs=200.0)
    assert es.speed == pytest.approx(truth["V_rel_mps"], abs=2.0)
    for field, key, tol in (("flight_path_angle", "gamma_rad", 2e-3), ("heading", "psi_rad", 2e-3),
                            ("latitude", "lat_rad", 1e-4), ("longitude", "lon_rad", 1e-4),
                            ("bank", "bank_rad", 0.02), ("alpha", "alpha_rad", 0.02)):
        assert abs(math.remainder(getattr(es, field) - truth[key], 2 * math.pi)) < tol, field
    # ATTITUDE (our 3-2-1 Euler of C_BL) equals pymavlink's Euler of ATTITUDE_QUATERNION
    att, aq = st["ATTITUDE"], st["ATTITUDE_QUATERNION"]
    roll, pitch, yaw = Quaternion([aq.q1, aq.q2, aq.q3, aq.q4]).euler
    for a, b in ((att.roll, roll), (att.pitch, pitch), (att.yaw, yaw)):
        assert abs(math.remainder(a - b, 2 * math.pi)) < 1e-5
    # the reference attitude is near the body attitude (the controller tracks it)
    tgt = st["ATTITUDE_TARGET"]
    dq = abs(float(np.dot([aq.q1, aq.q2, aq.q3, aq.q4], tgt.q)))
    assert 2 * math.degrees(math.acos(min(1.0, dq))) < 10.0
    nv = rig.gcs.state.named
    assert nv["bank_deg"] == pytest.approx(math.degrees(es.bank), abs=1e-3)
    assert nv["berr_deg"] == pytest.approx(math.degrees(math.remainder(es.bank - es.bank_ref, 2 * math.pi)), abs=1e-3)
    assert nv["alt_km"] == pytest.approx(es.altitude / 1e3, rel=1e-6)
    assert all(len(n) <= 10 for n in nv)
    # 18 jets in the 32 slots of ACTUATOR_OUTPUT_STATUS, as commanded
    ao = st["ACTUATOR_OUTPUT_STATUS"]
    assert ao.active == (1 << 18) - 1 and list(ao.actuator[18:]) == [0.0] * 14
    assert list(ao.actuator[:18]) == [float(x) for x in rig.fsw.driver.last_command]
    js = st["ELLIPSLED_JET_STATUS"]
    assert js.commanded == sum(int(u) << i for i, u in enumerate(rig.fsw.driver.last_command))
    fire = sum(1 << i for i, p in enumerate(rig.frame["chamber"]) if p > 0.5)
    assert js.firing == fire and list(js.pulses) == [int(x) for x in rig.fsw.driver.pulses]


def _truth_body_yaw(truth) -> float:
    """Yaw of the body relative to local NED from the plant's truth, by the textbook MRP ->
    DCM formula (C = I + (8 [s x]^2 - 4 (1 - s.s) [s x]) / (1 + s.s)^2) and the NED axes
    from the truth latitude/longitude in the inertial frame."""
    s = np.asarray(truth["sigma_BN"], dtype=float)
    S = np.array([[0, -s[2], s[1]], [s[2], 0, -s[0]], [-s[1], s[0], 0]])
    ss = float(s @ s)
    C_BN = np.eye(3) + (8 * S @ S - 4 * (1 - ss) * S) / (1 + ss) ** 2
    r = np.asarray(truth["r_N"], dtype=float)
    up = r / np.linalg.norm(r)
    lam = math.atan2(r[1], r[0])
    east = np.array([-math.sin(lam), math.cos(lam), 0.0])
    north = np.cross(up, east)
    x_B = C_BN[0]                                   # body x axis in N
    return math.atan2(float(x_B @ east), float(x_B @ north))


def test_position_hud_altitude_and_time_agree_with_the_plant_truth(rig):
    """GLOBAL_POSITION_INT, VFR_HUD, ALTITUDE, SYSTEM_TIME against sim.plant truth (latitude,
    longitude, altitude, speed, flight-path angle, heading, body attitude) within the
    navigation noise; the int16 cm/s velocities saturate at entry speed, never wrap."""
    rig.gl.wall_clock = lambda: 1_700_000_000.25
    rig.fly(100)
    rig.fsw.control_step(rig.frame)                # navigation at the plant's present time
    rig.clock.t += 1.0
    rig.gl.tick(rig.frame)
    rig.exchange(lambda: False, 0.1)
    truth = rig.plant.truth()
    st = rig.gcs.state.latest
    gp, hud, alt, stime = st["GLOBAL_POSITION_INT"], st["VFR_HUD"], st["ALTITUDE"], st["SYSTEM_TIME"]
    assert gp.lat * 1e-7 == pytest.approx(math.degrees(truth["lat_rad"]), abs=1e-3)
    assert gp.lon * 1e-7 == pytest.approx(math.degrees(truth["lon_rad"]), abs=1e-3)
    assert gp.alt * 1e-3 == pytest.approx(truth["h_m"], abs=200.0)
    assert gp.relative_alt == gp.alt
    V, gam, psi = truth["V_rel_mps"], truth["gamma_rad"], truth["psi_rad"]
    v_ned = (V * math.cos(gam) * math.cos(psi), V * math.cos(gam) * math.sin(psi), -V * math.sin(gam))
    for got, want in zip((gp.vx, gp.vy, gp.vz), v_ned):
        if abs(want) > 330.0:
            assert got == math.copysign(32767, want)          # saturated, right sign
        else:
            assert got * 0.01 == pytest.approx(want, abs=3.0)
    assert abs(v_ned[0]) > 330.0 or abs(v_ned[1]) > 330.0      # this case does exercise the saturation
    yaw = _truth_body_yaw(truth)
    assert abs(math.remainder(math.radians(gp.hdg / 100.0) - yaw, 2 * math.pi)) < 0.02
    assert 0 <= gp.hdg < 36000
    assert hud.airspeed == pytest.approx(V, abs=2.0)
    assert hud.groundspeed == pytest.approx(V * math.cos(gam), abs=2.0)
    assert hud.climb == pytest.approx(V * math.sin(gam), abs=2.0)
    assert hud.alt == pytest.approx(truth["h_m"], abs=200.0)
    assert hud.heading == gp.hdg // 100
    assert alt.altitude_amsl == pytest.approx(truth["h_m"], abs=200.0)
    assert alt.altitude_relative == pytest.approx(alt.altitude_amsl) and alt.altitude_terrain < -1000
    assert stime.time_unix_usec == 1_700_000_000_250_000
    assert stime.time_boot_ms == int(rig.fsw.t_s * 1000)


def test_loop_timing_from_the_executive_is_forwarded(rig):
    rig.gl.streams.set_loop_timing(0, jitter_p50_us=12, jitter_p99_us=40, jitter_max_us=90, compute_p50_us=300,
                           compute_p99_us=700, compute_max_us=1500, cycle_slips=2)
    rig.fly(10)
    assert rig.exchange(lambda: "ELLIPSLED_LOOP_TIMING" in rig.gcs.state.latest)
    lt = rig.gcs.state.latest["ELLIPSLED_LOOP_TIMING"]
    assert (lt.rate_group, lt.cycle_slips, lt.compute_p99, lt.jitter_max) == (0, 2, 700.0, 90.0)
    rig.clock.t += 1.0
    rig.exchange(lambda: False, 0.1)
    assert rig.gcs.state.latest["SYS_STATUS"].load == 15          # 300 us of a 20 ms period = 1.5 %


def test_stock_pymavlink_common_client_sees_vehicle_attitude_and_statustext(tmp_path, rig):
    probe = __import__("socket").socket()
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", dialect="common")
    try:
        key = write_key(tmp_path, "k3")
        gl = GroundLink(rig.fsw, key, gcs=f"udp:127.0.0.1:{port}", bind="udp:127.0.0.1:0", clock=rig.clock,
                        tick_clock_ns=lambda: 0)
        try:
            seen = {}
            for _ in range(30):
                u = rig.fsw.control_step(rig.frame)
                rig.clock.t += 0.1
                gl.tick(rig.frame)
                rig.frame = rig.plant.step(u)
                while (m := conn.recv_match(blocking=True, timeout=0.02)) is not None:
                    seen.setdefault(m.get_type(), m)
            assert {"HEARTBEAT", "ATTITUDE", "STATUSTEXT", "SYS_STATUS", "ATTITUDE_QUATERNION", "GLOBAL_POSITION_INT",
                    "VFR_HUD", "ALTITUDE", "SYSTEM_TIME"} <= set(seen)
            assert seen["HEARTBEAT"].get_srcSystem() == 1 and seen["HEARTBEAT"].get_srcComponent() == 1
            assert seen["HEARTBEAT"].system_status == mav.MAV_STATE_ACTIVE
            assert math.isfinite(seen["ATTITUDE"].roll)
            assert conn.target_system == 1
        finally:
            gl.close()
    finally:
        conn.close()


def test_warm_up_encodes_every_stream_and_sends_nothing(rig):
    """The SIL FSW warms the link's encoders on a throwaway FSW before its first real-time
    cycle: no frame leaves, the sequence number, stream schedules and event cursor are as
    before, and the first real tick then sends every stream as usual."""
    from fsw.flightsoftware import FlightSoftware
    spare = FlightSoftware(rig.scn)
    spare.control_step(rig.frame)
    seq, due = rig.gl.link.signer.seq, dict(rig.gl.schedule.next_due)
    tx = rig.gl.stats["tx_frames"]
    calls = []
    orig = rig.gl.link.pack
    rig.gl.link.pack = lambda msg, **kw: (calls.append(msg.get_type()), orig(msg, **kw))[1]
    rig.gl.warm_up(spare, rig.frame)
    rig.gl.link.pack = orig
    spare.close()
    assert rig.gl.stats["tx_frames"] == tx and rig.gl.link.signer.seq == seq
    assert rig.gl.schedule.next_due == due and rig.gl._event_index == 0 and rig.gl.fsw is rig.fsw
    assert {"HEARTBEAT", "ATTITUDE", "ELLIPSLED_ENTRY_STATE", "ELLIPSLED_JET_STATUS", "PARAM_VALUE",
            "STATUSTEXT"} <= set(calls)
    rig.fly(1)
    rig.exchange(lambda: "ATTITUDE" in rig.gcs.state.latest, 2.0)
    assert rig.gl.stats["tx_frames"] > tx and "HEARTBEAT" in rig.gcs.state.latest
