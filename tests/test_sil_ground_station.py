"""A stock ground station against a real-time SIL: pymavlink with only the common dialect
(its own MAVFTP client, MAVLink 2 signing with the run's key) on loopback, doing what
ground stations do at connect, while the nominal entry flies as processes.

Checked against the run itself: position, speed, climb and altitude in GLOBAL_POSITION_INT,
VFR_HUD and ALTITUDE against the plant's truth history at the message's time (within the
navigation noise); the capability handshake (AUTOPILOT_VERSION, PROTOCOL_VERSION, decoded
by hand: pymavlink 2.4.50's common.xml lacks it); MISSION_COUNT 0; SET_MESSAGE_INTERVAL
changing the rate measured at the ground; bad requests DENIED; the component metadata
(COMPONENT_METADATA, decoded by hand as well) read over FTP, valid JSON that lists every
parameter the parameter protocol lists.
"""
from __future__ import annotations

import json
import math
import struct
import time
import zlib

import numpy as np
import pytest
from pymavlink import mavftp, mavutil

from ellipsled.sil.history import History
from tests.procs import start_ground_sil, stop

pytestmark = [pytest.mark.slow, pytest.mark.realtime]
MSG_PROTOCOL_VERSION, MSG_COMPONENT_METADATA = 300, 397
COMP_METADATA_TYPE_PARAMETER = 1          # upstream common.xml (not in the stock client's dialect)


def _recv(conn, types, timeout_s: float, cond=lambda m: True):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        m = conn.recv_match(type=types, blocking=True, timeout=0.2)
        if m is not None and m.get_srcSystem() == 1 and cond(m):
            return m
    return None


def _command(conn, command: int, *p, timeout_s: float = 3.0, tries: int = 3):
    """COMMAND_LONG, retried as ground stations do; the COMMAND_ACK's result."""
    p = list(p) + [0.0] * (7 - len(p))
    for i in range(tries):
        conn.mav.command_long_send(1, 1, command, i, *p)
        ack = _recv(conn, "COMMAND_ACK", timeout_s, lambda m: m.command == command)
        if ack is not None:
            return ack.result
    return None


def _unknown_payload(conn, msgid: int, timeout_s: float) -> bytes | None:
    """The payload of a frame whose id the common dialect does not know (pymavlink hands it
    over as UNKNOWN_<id> with the whole frame), zero-extended (MAVLink 2 trims trailing zeros)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        m = conn.recv_match(type=f"UNKNOWN_{msgid}", blocking=True, timeout=0.2)
        if m is None:
            continue
        d = bytes(m.data)                  # the frame: header, payload, CRC, signature
        if d[0] == 0xFD and d[5] == 1 and (d[7] | d[8] << 8 | d[9] << 16) == msgid:
            return d[10:10 + d[1]].ljust(255, b"\0")
    return None


def _rate(conn, name: str, seconds: float) -> float:
    n, end = 0, time.monotonic() + seconds
    while time.monotonic() < end:
        if conn.recv_match(type=name, blocking=True, timeout=0.1) is not None:
            n += 1
    return n / seconds


def test_a_stock_ground_station_sees_position_identity_rates_and_parameter_metadata(tmp_path, monkeypatch):
    monkeypatch.setenv("MAVLINK20", "1")                 # a MAVLink 2 ground station (v1 is refused)
    sil = start_ground_sil(tmp_path, duration_s=45.0)
    run, key, gcs, out, log_text = sil.run, sil.key, sil.gcs, sil.out, sil.log
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{gcs}", dialect="common", source_system=255,
                                      source_component=190)
    conn.setup_signing(key.secret, sign_outgoing=True)
    seen: list = []
    try:
        hb = _recv(conn, "HEARTBEAT", 120)
        assert hb is not None, log_text()
        assert (hb.get_srcComponent(), hb.type, hb.autopilot) == (1, mavutil.mavlink.MAV_TYPE_GENERIC,
                                                                  mavutil.mavlink.MAV_AUTOPILOT_GENERIC)
        conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)

        # --- where it is: position messages, kept for the truth comparison after the run
        t_end = time.monotonic() + 3.0
        while time.monotonic() < t_end:
            m = conn.recv_match(type=["GLOBAL_POSITION_INT", "VFR_HUD", "ALTITUDE", "SYSTEM_TIME", "ATTITUDE"],
                                blocking=True, timeout=0.2)
            if m is not None:
                seen.append(m)
        kinds = {m.get_type() for m in seen}
        assert {"GLOBAL_POSITION_INT", "VFR_HUD", "ALTITUDE", "SYSTEM_TIME"} <= kinds, kinds
        st = next(m for m in seen if m.get_type() == "SYSTEM_TIME")
        assert abs(st.time_unix_usec * 1e-6 - time.time()) < 5.0

        # --- what it is: the capability handshake
        A = mavutil.mavlink
        assert _command(conn, A.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1) == A.MAV_RESULT_ACCEPTED
        av = _recv(conn, "AUTOPILOT_VERSION", 3)
        assert av is not None
        want = (A.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | A.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | A.MAV_PROTOCOL_CAPABILITY_FTP
                | A.MAV_PROTOCOL_CAPABILITY_MISSION_INT)             # the empty mission list, in its INT form
        assert av.capabilities & want == want
        assert not av.capabilities & (A.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | A.MAV_PROTOCOL_CAPABILITY_TERRAIN)
        assert _command(conn, A.MAV_CMD_REQUEST_MESSAGE, MSG_PROTOCOL_VERSION) == A.MAV_RESULT_ACCEPTED
        pv = _unknown_payload(conn, MSG_PROTOCOL_VERSION, 3)
        assert pv is not None and struct.unpack_from("<HHH", pv) == (200, 200, 200)

        # --- missions: none, said at once
        conn.mav.mission_request_list_send(1, 1, A.MAV_MISSION_TYPE_MISSION)
        mc = _recv(conn, "MISSION_COUNT", 3)
        assert mc is not None and mc.count == 0

        # --- rates: the interval command changes what arrives
        gp = A.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
        r_default = _rate(conn, "GLOBAL_POSITION_INT", 3.0)
        assert _command(conn, A.MAV_CMD_SET_MESSAGE_INTERVAL, gp, 100_000) == A.MAV_RESULT_ACCEPTED
        _rate(conn, "GLOBAL_POSITION_INT", 0.5)
        r_fast = _rate(conn, "GLOBAL_POSITION_INT", 3.0)
        assert _command(conn, A.MAV_CMD_SET_MESSAGE_INTERVAL, gp, 1_000_000) == A.MAV_RESULT_ACCEPTED
        _rate(conn, "GLOBAL_POSITION_INT", 1.0)
        r_slow = _rate(conn, "GLOBAL_POSITION_INT", 4.0)
        assert 3.5 <= r_default <= 6.5 and 7.0 <= r_fast <= 11.0 and 0.5 <= r_slow <= 1.5, (r_default, r_fast, r_slow)
        for bad in ((gp, 1_000), (gp, float("nan")), (99_999, 100_000)):
            assert _command(conn, A.MAV_CMD_SET_MESSAGE_INTERVAL, *bad) == A.MAV_RESULT_DENIED, bad
        assert _command(conn, A.MAV_CMD_REQUEST_MESSAGE, 9_999) == A.MAV_RESULT_DENIED

        # --- what its parameters mean: the list, then the metadata over FTP
        conn.mav.param_request_list_send(1, 1)
        params, count = {}, None
        end = time.monotonic() + 10
        while time.monotonic() < end and (count is None or len(params) < count):
            m = _recv(conn, "PARAM_VALUE", 1.0)
            if m is not None:
                params[m.param_id if isinstance(m.param_id, str) else m.param_id.decode()] = m.param_value
                count = m.param_count
        assert count and len(params) == count
        assert _command(conn, A.MAV_CMD_REQUEST_MESSAGE, MSG_COMPONENT_METADATA) == A.MAV_RESULT_ACCEPTED
        cm = _unknown_payload(conn, MSG_COMPONENT_METADATA, 3)
        assert cm is not None
        _, file_crc = struct.unpack_from("<II", cm)
        uri = cm[8:108].split(b"\0")[0].decode()
        assert uri.startswith("mftp://")
        ftp = mavftp.MAVFTP(conn, target_system=1, target_component=1)
        got = {}

        def download(path):
            def keep(fh):
                got[path] = fh.read() if fh is not None else None
            assert ftp.cmd_get([path], callback=keep).error_code == mavftp.FtpError.Success
            assert ftp.process_ftp_reply("OpenFileRO", timeout=30).error_code == mavftp.FtpError.Success, path
            return got[path]
        general_bytes = download(uri[len("mftp://"):])
        assert zlib.crc32(general_bytes) == file_crc
        general = json.loads(general_bytes)
        ptype = next(t for t in general["metadataTypes"] if t["type"] == COMP_METADATA_TYPE_PARAMETER)
        param_bytes = download(ptype["uri"][len("mftp://"):])
        assert zlib.crc32(param_bytes) == ptype["fileCrc"]
        meta = {p["name"]: p for p in json.loads(param_bytes)["parameters"]}
        assert set(meta) == set(params)
        for pid, value in params.items():
            p = meta[pid]
            assert p["min"] <= value <= p["max"] and p["longDesc"], pid

        assert run.wait(120) == 0, log_text()
    finally:
        conn.close()
        stop(run)

    # --- position against the plant's truth at the message's time (VFR_HUD carries no
    # time: it leaves in the same tick as the GLOBAL_POSITION_INT just before it)
    h = History.load(out / "history.npz")
    t = np.asarray(h["t_s"])
    lon_unwrapped = np.unwrap(np.asarray(h["lon_rad"]))
    checked, ts = 0, None
    for m in seen:
        kind = m.get_type()
        if kind == "GLOBAL_POSITION_INT":
            ts = m.time_boot_ms * 1e-3
        if kind not in ("GLOBAL_POSITION_INT", "VFR_HUD") or ts is None or not t[0] <= ts <= t[-1]:
            continue
        at = {k: float(np.interp(ts, t, np.asarray(h[k]))) for k in ("h_m", "lat_rad", "V_rel_mps", "gamma_rad")}
        if kind == "GLOBAL_POSITION_INT":
            assert m.lat * 1e-7 == pytest.approx(math.degrees(at["lat_rad"]), abs=0.01)
            lon = float(np.interp(ts, t, lon_unwrapped))
            assert abs(math.remainder(math.radians(m.lon * 1e-7) - lon, 2 * math.pi)) < math.radians(0.01)
            assert m.alt * 1e-3 == pytest.approx(at["h_m"], abs=500.0)
        else:
            assert m.airspeed == pytest.approx(at["V_rel_mps"], abs=20.0)
            assert m.climb == pytest.approx(at["V_rel_mps"] * math.sin(at["gamma_rad"]), abs=20.0)
            assert m.alt == pytest.approx(at["h_m"], abs=500.0)
        checked += 1
    assert checked >= 10
