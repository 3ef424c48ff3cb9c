"""A ground station without the signing key (most stock ones: MAVSDK has no key API) can
identify and watch the vehicle; only a keyed one changes it. The signing policy by message
class (fsw/groundlink/policy.py): read-only requests answered unsigned, to the requester
only, within its read budget, making no telemetry peer; state-changing frames refused
unsigned with no effect, counted in SYS_STATUS and told in one throttled event.

Independent truth: requests are packed here with pymavlink's own packer (unsigned), answers
parsed with pymavlink's parser; the vehicle's state is read from the FSW and the plant; the
position frame is checked against the plant's truth and by differentiating positions.
"""
from __future__ import annotations

import math
import socket
import struct
import time

import numpy as np
import pytest

from fsw.groundlink import ftp, metadata, policy
from fsw.groundlink.services import PRODUCT_ID, VENDOR_ID, flight_sw_version
from fsw.groundlink.link import REFUSAL_EVENT
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing.verify import Reject
from interfaces.vocabulary import Mode

from tests.rig import Keyless, flown, station  # noqa: F401  (the keyless station, over this module's rig)


@pytest.fixture
def rig(tmp_path):
    with flown(tmp_path, 3) as r:
        yield r


def vehicle_sent(rig, name: str) -> list:
    return [m for m in rig.gcs.state.latest.values() if getattr(m, "get_type", lambda: "")() == name]


# ------------------------------------------------------------------ the table
def test_policy_table_reads_are_reads_and_everything_that_changes_state_is_signed_only():
    cmd = lambda c: mav.MAVLink_command_long_message(1, 1, c, 0, 0, 0, 0, 0, 0, 0, 0)      # noqa: E731
    ftp_op = lambda op: mav.MAVLink_file_transfer_protocol_message(0, 1, 1, [0, 0, 0, op] + [0] * 247)  # noqa: E731
    for c in (mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
              mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, mav.MAV_CMD_GET_MESSAGE_INTERVAL, mav.MAV_CMD_RUN_PREARM_CHECKS):
        assert policy.access(cmd(c)) == policy.READ, c
    assert policy.access(mav.MAVLink_request_event_message(1, 1, 0, 0)) == policy.READ
    for c in (mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAV_CMD_INJECT_FAILURE, mav.ELLIPSLED_CMD_SET_MODE,
              mav.ELLIPSLED_CMD_ARM_JETS, mav.MAV_CMD_COMPONENT_ARM_DISARM, mav.ELLIPSLED_CMD_FDIR_MARK_JET,
              mav.ELLIPSLED_CMD_FDIR_CLEAR, mav.ELLIPSLED_CMD_FDIR_SET_DELAY, mav.ELLIPSLED_CMD_FAULT_TOLERANCE,
              mav.MAV_CMD_DO_SET_MODE, 12345):
        assert policy.access(cmd(c)) == policy.WRITE, c
    for op in (ftp.LIST, ftp.OPEN_RO, ftp.READ, ftp.BURST, ftp.CRC32, ftp.TERMINATE, 16, 200):
        assert policy.access(ftp_op(op)) == policy.READ, op      # 16, 200: unknown, answered NAK
    for op in (ftp.RESET, *ftp.WRITE_OPS):
        assert policy.access(ftp_op(op)) == policy.WRITE, op
    assert policy.access(mav.MAVLink_param_set_message(1, 1, b"C_D_MAX", 2.0, 9)) == policy.WRITE
    assert not policy.may_be_unsigned(mav.MAVLINK_MSG_ID_PARAM_SET)
    assert policy.COMMAND_CLASS == {mav.MAVLINK_MSG_ID_COMMAND_LONG, mav.MAVLINK_MSG_ID_COMMAND_INT,
                                    mav.MAVLINK_MSG_ID_PARAM_SET, mav.MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL}


# ------------------------------------------------------------------ identity
def test_identity_is_answered_to_an_unsigned_request_and_to_the_requester_only(rig, station):
    station.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    station.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_PROTOCOL_VERSION, 0, 0, 0, 0, 0,
                    2)                                       # asks for a broadcast answer: requester only all the same
    station.command(mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1)
    station.command(mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1)
    assert station.wait(lambda: len(station.of("AUTOPILOT_VERSION")) == 2 and len(station.of("PROTOCOL_VERSION")) == 2)
    av = station.of("AUTOPILOT_VERSION")[0]
    assert (av.vendor_id, av.product_id) == (VENDOR_ID, PRODUCT_ID) != (0, 0)
    assert av.flight_sw_version == flight_sw_version() and av.flight_sw_version >> 8 == 0x000100     # 0.1.0
    assert av.capabilities & mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert station.of("PROTOCOL_VERSION")[0].version == 200
    assert [a.result for a in station.of("COMMAND_ACK")] == [mav.MAV_RESULT_ACCEPTED] * 4
    # to the requester only: the ground station at gcs saw none of it, and no peer was made
    assert not vehicle_sent(rig, "AUTOPILOT_VERSION") and not vehicle_sent(rig, "PROTOCOL_VERSION")
    assert station.address not in rig.gl.peers and rig.gl.stats["peers_added"] == 0
    assert rig.gl.rejections == 0


def test_ping_and_timesync_are_answered_to_the_requester(rig, station):
    station.send(mav.MAVLink_ping_message(123456, 7, 0, 0))
    station.send(mav.MAVLink_timesync_message(0, 987654321))
    assert station.wait(lambda: station.of("PING") and station.of("TIMESYNC"))
    ping, ts = station.of("PING")[0], station.of("TIMESYNC")[0]
    assert (ping.time_usec, ping.seq, ping.target_system, ping.target_component) == (123456, 7, 245, 190)
    assert ts.ts1 == 987654321 and ts.tc1 > 0
    assert rig.gl.rejections == 0 and station.address not in rig.gl.peers


# ------------------------------------------------------------------ refusals
def test_unsigned_state_changing_frames_are_refused_with_no_effect_and_counted(rig, station):
    rates, params = dict(rig.gl.rates_hz), dict(rig.fsw.params)
    station.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, 1000)
    station.command(mav.MAV_CMD_INJECT_FAILURE, mav.FAILURE_UNIT_SYSTEM_MOTOR, mav.FAILURE_TYPE_OFF, 18)
    station.command(mav.ELLIPSLED_CMD_SET_MODE, int(Mode.SAFE))
    station.send(mav.MAVLink_param_set_message(1, 1, b"F_ALT_MAX_M", 9e5, mav.MAV_PARAM_TYPE_REAL32))
    station.send(mav.MAVLink_file_transfer_protocol_message(0, 1, 1, [0, 0, 0, ftp.RESET] + [0] * 247))
    assert station.wait(lambda: len(station.of("COMMAND_ACK")) == 3)
    rig.exchange(lambda: False, 0.2)
    assert [a.result for a in station.of("COMMAND_ACK")] == [mav.MAV_RESULT_DENIED] * 3
    assert not station.of("FILE_TRANSFER_PROTOCOL") and not station.of("PARAM_VALUE")
    assert rig.injected == [] and rig.fsw.modes.mode != Mode.SAFE
    assert rig.gl.rates_hz == rates and dict(rig.fsw.params) == params
    assert rig.gl.link.counts[Reject.UNSIGNED] == 5 and rig.gl.stats["unsigned_writes"] == 4
    assert station.address not in rig.gl.peers
    # counted in telemetry a stock ground station shows: SYS_STATUS errors_count3
    rig.gcs.state.latest.pop("SYS_STATUS", None)
    rig.clock.t += 1.0
    assert rig.exchange(lambda: "SYS_STATUS" in rig.gcs.state.latest)
    assert rig.gcs.state.latest["SYS_STATUS"].errors_count3 == 5


def test_refusals_are_told_in_one_throttled_event_not_one_each(rig, station):
    """A keyless station retrying a parameter set and a fault injection over two minutes:
    every refusal counted, told at most once a minute (first at once, then summaries)."""
    sets = 0
    for burst in range(8):                                 # every 15 s of FSW time, 2 minutes
        for _ in range(3):
            station.send(mav.MAVLink_param_set_message(1, 1, b"F_ALT_MAX_M", 9e5, mav.MAV_PARAM_TYPE_REAL32))
            station.command(mav.MAV_CMD_INJECT_FAILURE, mav.FAILURE_UNIT_SYSTEM_MOTOR, mav.FAILURE_TYPE_OFF, 18)
            sets += 2
        station.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION)   # and reads
        station.send(mav.MAVLink_ping_message(burst, burst, 0, 0))
        assert station.wait(lambda: rig.gl.link.counts[Reject.UNSIGNED] == sets)
        rig.fly(750)
    refusals = [e for e in rig.fsw.events.history if e.code == REFUSAL_EVENT]
    assert 2 <= len(refusals) <= 3, [e.text for e in refusals]                    # t = 0, 60, 120 s at most
    assert all(e.source == "link" and e.severity == mav.MAV_SEVERITY_WARNING for e in refusals)
    assert not [e for e in rig.fsw.events.history if e.source == "link" and e.code != REFUSAL_EVENT]
    assert rig.injected == [] and rig.gl.stats["params_set"] == 0
    assert len(station.of("AUTOPILOT_VERSION")) == 8 and len(station.of("PING")) == 8


# ------------------------------------------------------------------ FTP, read-only and per client
def _ftp_req(seq, session, op, offset=0, data=b"", size=None):
    head = ftp.HEADER.pack(seq, session, op, len(data) if size is None else size, 0, 0, 0, offset)
    return mav.MAVLink_file_transfer_protocol_message(0, 1, 1, list((head + data).ljust(ftp.PAYLOAD_LEN, b"\0")))


def _ftp_reply(m):
    raw = bytes(m.payload)
    seq, session, op, size, req, burst_complete, _, offset = ftp.HEADER.unpack_from(raw)
    return op, req, session, offset, raw[ftp.HEADER.size:ftp.HEADER.size + size]


def test_metadata_can_be_read_over_ftp_unsigned_in_its_own_session(rig, station):
    other = Keyless(rig)
    try:
        station.send(_ftp_req(1, 0, ftp.OPEN_RO, data=metadata.GENERAL_PATH.encode()))
        assert station.wait(lambda: station.of("FILE_TRANSFER_PROTOCOL"))
        op, req, session, _, data = _ftp_reply(station.of("FILE_TRANSFER_PROTOCOL")[-1])
        size = struct.unpack("<I", data)[0]
        assert (op, req) == (ftp.ACK, ftp.OPEN_RO) and size == len(rig.gl.files[metadata.GENERAL_PATH])
        # another client cannot read or close this session
        other.send(_ftp_req(1, session, ftp.READ, size=ftp.DATA_MAX))
        other.send(_ftp_req(2, session, ftp.TERMINATE))
        assert other.wait(lambda: len(other.of("FILE_TRANSFER_PROTOCOL")) == 2)
        assert [(_ftp_reply(m)[0], _ftp_reply(m)[4]) for m in other.of("FILE_TRANSFER_PROTOCOL")] == \
            [(ftp.NAK, bytes([ftp.INVALID_SESSION]))] * 2
        got = b""
        while len(got) < size:
            n = len(station.of("FILE_TRANSFER_PROTOCOL"))
            station.send(_ftp_req(3, session, ftp.READ, offset=len(got), size=ftp.DATA_MAX))
            assert station.wait(lambda: len(station.of("FILE_TRANSFER_PROTOCOL")) > n)
            op, _, _, offset, data = _ftp_reply(station.of("FILE_TRANSFER_PROTOCOL")[-1])
            assert op == ftp.ACK and offset == len(got)
            got += data
        assert got == rig.gl.files[metadata.GENERAL_PATH]
        assert rig.gl.rejections == 0 and station.address not in rig.gl.peers
    finally:
        other.close()


# ------------------------------------------------------------------ state in float messages, modes
def test_local_position_ned_carries_entry_speed_in_a_documented_planet_fixed_frame(rig, station):
    # the first fix is the origin: its GPS_GLOBAL_ORIGIN is the navigation's position then
    # (the rig has flown 3 cycles since: within 0.01 deg)
    lat0, lon0 = rig.gl.stream_messages("GLOBAL_POSITION_INT")[0].lat, rig.gl.stream_messages("GLOBAL_POSITION_INT")[0].lon
    nan = float("nan")                                   # unused params, as MAVSDK sends them
    station.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, nan, nan, nan, nan, nan, nan)
    assert station.wait(lambda: station.of("GPS_GLOBAL_ORIGIN"))
    origin = station.of("GPS_GLOBAL_ORIGIN")[0]
    assert abs(origin.latitude - lat0) <= 1e5 and abs(origin.longitude - lon0) <= 1e5 and origin.altitude == 0
    samples = []
    for _ in range(3):
        rig.fly(250)                                                 # 5 s
        lp = rig.gl.stream_messages("LOCAL_POSITION_NED")[0]
        truth = rig.plant.truth()
        samples.append((rig.fsw.t_s, np.array([lp.x, lp.y, lp.z]), np.array([lp.vx, lp.vy, lp.vz]), truth))
    for t, x, v, truth in samples:
        speed = float(np.linalg.norm(v))
        assert speed > 5000.0                                        # an entry speed, not 327.67
        assert speed == pytest.approx(truth["V_rel_mps"], rel=0.01)
        # z: minus the altitude above the origin's tangent plane, so -z < h (curvature)
        assert -x[2] < truth["h_m"] + 1.0
    (t0, x0, v0, _), (t1, x1, v1, _) = samples[0], samples[1]
    # the velocity is the time derivative of the position (a fixed, planet-fixed frame)
    np.testing.assert_allclose((x1 - x0) / (t1 - t0), (v0 + v1) / 2.0, rtol=0.01, atol=30.0)
    # GLOBAL_POSITION_INT still saturates (documented): its vx is pinned at the int16 bound
    gpi = rig.gl.stream_messages("GLOBAL_POSITION_INT")[0]
    assert 32767 in (abs(gpi.vx), abs(gpi.vy), abs(gpi.vz))


def test_modes_have_names_and_the_current_mode_is_told_at_once(rig, station):
    station.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AVAILABLE_MODES, 0)
    assert station.wait(lambda: len(station.of("AVAILABLE_MODES")) == len(Mode))
    names = {m.custom_mode: m.mode_name for m in station.of("AVAILABLE_MODES")}
    assert names == {int(m): m.name for m in Mode} and set(names.values()) == {"STANDBY", "ENTRY", "SAFE"}
    assert [m.mode_index for m in station.of("AVAILABLE_MODES")] == [1, 2, 3]
    assert all(m.number_modes == 3 for m in station.of("AVAILABLE_MODES"))
    station.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_AVAILABLE_MODES, 9)
    assert station.wait(lambda: len(station.of("COMMAND_ACK")) == 2)
    assert [a.result for a in station.of("COMMAND_ACK")] == [mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_DENIED]
    # CURRENT_MODE streams to the ground station, and a mode change is told at the next tick
    assert rig.exchange(lambda: "CURRENT_MODE" in rig.gcs.state.latest)
    assert rig.gcs.state.latest["CURRENT_MODE"].custom_mode == int(rig.fsw.modes.mode)
    rig.gcs.state.latest.pop("CURRENT_MODE", None)
    assert rig.command("mode", "safe") == mav.MAV_RESULT_ACCEPTED   # the link's clock stands still: not the stream
    assert rig.exchange(lambda: "CURRENT_MODE" in rig.gcs.state.latest)
    assert rig.gcs.state.latest["CURRENT_MODE"].custom_mode == int(Mode.SAFE)
