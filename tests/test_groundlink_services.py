"""The link's own services over real signed UDP on loopback: AUTOPILOT_VERSION with honest
capability bits, PROTOCOL_VERSION, MAV_CMD_REQUEST_MESSAGE for every message the vehicle
produces, SET/GET_MESSAGE_INTERVAL changing the rate counted at the ground, COMMAND_INT,
MISSION_COUNT 0; bad requests DENIED, counted, reported, never a crash.

Independent truth: counting messages at the ground against a fake clock, the capability
bits named in common.xml, the rates configured.
"""
# ruff: noqa: F811  (the shared `rig` fixture is imported, then named as a test argument)
from __future__ import annotations

import json
import math
import socket

import pytest

from fsw.groundlink import DEFAULT_RATES_HZ
from interfaces.mavlink import dialect as mav

from tests.rig import ACCEPTED, DENIED, flown, rig  # noqa: F401  (the shared fixture)

TEMP = mav.MAV_RESULT_TEMPORARILY_REJECTED
REQ, SET_IV, GET_IV = mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAV_CMD_GET_MESSAGE_INTERVAL


def msg_id(name: str) -> int:
    return getattr(mav, "MAVLINK_MSG_ID_" + name)


@pytest.fixture
def quiet(tmp_path):
    """Every stream off: whatever arrives was asked for."""
    with flown(tmp_path, rates={n: 0.0 for n in DEFAULT_RATES_HZ}) as r:
        yield r


def arrived(rig, name: str) -> bool:
    return rig.exchange(lambda: name in rig.gcs.state.latest, 1.0)


def test_autopilot_version_claims_only_what_the_link_does(quiet):
    assert quiet.raw_command(mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1) == ACCEPTED
    assert arrived(quiet, "AUTOPILOT_VERSION")
    caps = quiet.gcs.state.latest["AUTOPILOT_VERSION"].capabilities
    P = mav
    # MISSION_INT: the (empty) mission list in its MISSION_ITEM_INT form; without it MAVSDK
    # refuses to download a mission (INT_MESSAGES_NOT_SUPPORTED)
    for bit in (P.MAV_PROTOCOL_CAPABILITY_MAVLINK2, P.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
                P.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT, P.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
                P.MAV_PROTOCOL_CAPABILITY_MISSION_INT):
        assert caps & bit, bit
    for bit in (P.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT,
                P.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE, P.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET,
                P.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED, P.MAV_PROTOCOL_CAPABILITY_TERRAIN,
                P.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION, P.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE,
                P.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY):
        assert not caps & bit, bit
    av = quiet.gcs.state.latest["AUTOPILOT_VERSION"]
    assert any(av.flight_custom_version)                 # the build's source digest
    v = av.flight_sw_version
    assert f"{v >> 24}.{v >> 16 & 0xFF}.{v >> 8 & 0xFF}" == json.loads(
        quiet.gl.files["metadata/general.json"])["firmwareVersion"]      # one version, both places
    del quiet.gcs.state.latest["AUTOPILOT_VERSION"]
    assert quiet.raw_command(REQ, msg_id("AUTOPILOT_VERSION")) == ACCEPTED
    assert arrived(quiet, "AUTOPILOT_VERSION")
    assert quiet.gcs.state.latest["AUTOPILOT_VERSION"].capabilities == caps


def test_protocol_version_says_mavlink_2_only(quiet):
    assert quiet.raw_command(REQ, 300) == ACCEPTED
    assert arrived(quiet, "PROTOCOL_VERSION")
    pv = quiet.gcs.state.latest["PROTOCOL_VERSION"]
    assert (pv.version, pv.min_version, pv.max_version) == (200, 200, 200)
    del quiet.gcs.state.latest["PROTOCOL_VERSION"]
    assert quiet.raw_command(mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1) == ACCEPTED      # the deprecated form
    assert arrived(quiet, "PROTOCOL_VERSION")


def test_every_stream_can_be_requested_once(quiet):
    names = [n for n in DEFAULT_RATES_HZ if n != "ELLIPSLED_LOOP_TIMING"]
    for name in names:
        quiet.gcs.state.latest.pop(name, None)
        assert quiet.raw_command(REQ, msg_id(name)) == ACCEPTED, name
        assert arrived(quiet, name), name
    # loop timing exists only once the executive has reported it
    assert quiet.raw_command(REQ, msg_id("ELLIPSLED_LOOP_TIMING")) == TEMP
    quiet.gl.streams.set_loop_timing(0, jitter_p50_us=1, jitter_p99_us=2, jitter_max_us=3, compute_p50_us=4,
                             compute_p99_us=5, compute_max_us=6, cycle_slips=0)
    assert quiet.raw_command(REQ, msg_id("ELLIPSLED_LOOP_TIMING")) == ACCEPTED
    assert arrived(quiet, "ELLIPSLED_LOOP_TIMING")
    # one-shot: nothing was switched on by asking
    quiet.gcs.state.rx_counts.clear()
    quiet.fly(100)
    quiet.exchange(lambda: False, 0.2)
    assert not set(quiet.gcs.state.rx_counts) & set(DEFAULT_RATES_HZ)


def _count(rig, name: str, seconds: float) -> int:
    before = rig.gcs.state.rx_counts.get(name, 0)
    rig.fly(int(round(seconds / rig.scn.dt_control_s)))
    rig.exchange(lambda: False, 0.2)
    return rig.gcs.state.rx_counts.get(name, 0) - before


def test_set_message_interval_changes_the_rate_counted_at_the_ground(rig):
    aid = msg_id("ATTITUDE")
    assert _count(rig, "ATTITUDE", 4.0) == pytest.approx(40, abs=1)               # default 10 Hz
    assert rig.raw_command(SET_IV, aid, 500_000) == ACCEPTED                        # 2 Hz
    assert _count(rig, "ATTITUDE", 4.0) == pytest.approx(8, abs=1)
    assert rig.raw_command(GET_IV, aid) == ACCEPTED
    assert rig.exchange(lambda: "MESSAGE_INTERVAL" in rig.gcs.state.latest, 1.0)
    mi = rig.gcs.state.latest["MESSAGE_INTERVAL"]
    assert (mi.message_id, mi.interval_us) == (aid, 500_000)
    assert rig.raw_command(SET_IV, msg_id("GLOBAL_POSITION_INT"), 100_000) == ACCEPTED   # 10 Hz, the fastest
    assert _count(rig, "GLOBAL_POSITION_INT", 4.0) == pytest.approx(40, abs=1)
    assert rig.raw_command(SET_IV, aid, -1) == ACCEPTED                             # off
    assert _count(rig, "ATTITUDE", 2.0) == 0
    del rig.gcs.state.latest["MESSAGE_INTERVAL"]
    assert rig.raw_command(GET_IV, aid) == ACCEPTED
    assert rig.exchange(lambda: "MESSAGE_INTERVAL" in rig.gcs.state.latest, 1.0)
    assert rig.gcs.state.latest["MESSAGE_INTERVAL"].interval_us == -1
    assert rig.raw_command(SET_IV, aid, 0) == ACCEPTED                              # back to the default
    assert _count(rig, "ATTITUDE", 4.0) == pytest.approx(40, abs=1)
    del rig.gcs.state.latest["MESSAGE_INTERVAL"]
    assert rig.raw_command(GET_IV, msg_id("PARAM_VALUE")) == ACCEPTED               # not a stream
    assert rig.exchange(lambda: "MESSAGE_INTERVAL" in rig.gcs.state.latest, 1.0)
    assert rig.gcs.state.latest["MESSAGE_INTERVAL"].interval_us == 0                # "not available"


@pytest.mark.parametrize("command, params, why", [
    (SET_IV, (30, 10_000), "MIN 100000"),                          # 100 Hz: faster than the link ticks
    (SET_IV, (30, float("nan")), "DENIED"),
    (SET_IV, (30, float("inf")), "DENIED"),
    (SET_IV, (30, -5), "DENIED"),
    (SET_IV, (30.5, 100_000), "MSG ID 30.5"),
    (SET_IV, (float("nan"), 100_000), "MSG ID nan"),
    (SET_IV, (-1, 100_000), "MSG ID -1"),
    (SET_IV, (2 ** 24, 100_000), "MSG ID"),
    (SET_IV, (22, 100_000), "NOT STREAMED"),                       # PARAM_VALUE
    (REQ, (9999,), "NOT PRODUCED"),
    (REQ, (float("inf"),), "MSG ID inf"),
    (REQ, (30, 0, 0, 0, 0, 0, 3), "TARGET 3"),
    (REQ, (30, 0, 0, 0, 0, 0, float("inf")), "TARGET inf"),     # NaN: a param left unused, 0
    (GET_IV, (1e9,), "MSG ID"),
    (mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, (2,), "CAPABILITIES 2"),
    (mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, (float("nan"),), "CAPABILITIES nan"),
])
def test_bad_requests_are_denied_counted_reported_and_change_nothing(rig, command, params, why):
    rates = dict(rig.gl.rates_hz)
    denied = rig.gl.commands.get(DENIED, 0)
    assert rig.raw_command(command, *params) == DENIED
    assert rig.gl.commands[DENIED] == denied + 1
    assert any(why in t for t in rig.texts()), rig.texts()[-3:]
    assert rig.gl.rates_hz == rates
    rig.fly(10)                                                   # and the link flies on
    assert rig.raw_command(REQ, msg_id("HEARTBEAT")) == ACCEPTED


def test_command_int_is_answered_like_command_long_and_must_be_signed(rig):
    msg = mav.MAVLink_command_int_message(1, 1, 0, mav.MAV_CMD_REQUEST_MESSAGE, 0, 0,
                                          float(msg_id("AUTOPILOT_VERSION")), 0, 0, 0, 0, 0, 0.0)
    rig.gcs.send(msg)
    assert rig.exchange(lambda: "AUTOPILOT_VERSION" in rig.gcs.state.latest and any(
        a.command == mav.MAV_CMD_REQUEST_MESSAGE and a.result == ACCEPTED for a in rig.gcs.state.acks), 2.0)
    rig.gcs.send(mav.MAVLink_command_int_message(1, 1, 0, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0,
                                                 0.0, 0, 0, 0, 0, 0, 0.0))
    assert rig.exchange(lambda: not rig.fsw.driver.armed, 2.0)
    # unsigned: refused before decoding, nothing happens
    raw = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    raw.WIRE_PROTOCOL_VERSION = "2.0"
    frame = mav.MAVLink_command_int_message(1, 1, 0, mav.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0,
                                            1.0, 0, 0, 0, 0, 0, 0.0).pack(raw)
    rejected = rig.gl.rejections
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(frame, rig.gl.address)
    rig.exchange(lambda: rig.gl.rejections > rejected, 1.0)
    assert rig.gl.rejections > rejected and not rig.fsw.driver.armed


def test_a_mission_list_request_is_answered_with_no_items_even_unsigned(rig):
    raw = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        s.settimeout(2.0)
        for mission_type in (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_FENCE, mav.MAV_MISSION_TYPE_RALLY):
            s.sendto(mav.MAVLink_mission_request_list_message(1, 1, mission_type).pack(raw), rig.gl.address)
            got = None
            for _ in range(50):
                rig.gl.tick(rig.frame)
                try:
                    data = s.recv(2048)
                except socket.timeout:
                    continue
                for m in raw.parse_buffer(data) or []:
                    if m.get_type() == "MISSION_COUNT":
                        got = m
                if got is not None:
                    break
            assert got is not None and got.count == 0 and got.mission_type == mission_type
            assert (got.target_system, got.target_component) == (255, 190)


def test_max_rate_is_the_link_tick_rate(rig):
    tick_hz = 1.0 / rig.fsw.params["executive.rg2_period_s"]        # 10 Hz: RG2, whatever the control rate
    assert math.isclose(rig.gl.max_rate_hz, tick_hz)
