"""Component metadata over read-only MAVLink FTP: the metadata files say what the parameter
registry declares (every ground-settable parameter, its unit, bounds, default,
description), keys as parameter.schema.json allows; the FTP server answers bad requests
with the right NAK and never raises; a stock pymavlink client (common dialect, its own
MAVFTP, signed) lists and downloads the files from a live ground link.

Independent truth: the registry's describe() rows, zlib's CRC32, json parsing, the key
sets of the upstream schemas (mavlink/component_metadata/*.schema.json) written out here.
"""
# ruff: noqa: F811  (the shared `rig` fixture is imported, then named as a test argument)
from __future__ import annotations

import io
import json
import socket
import struct
import threading
import time
import zlib

import pytest
from pymavlink import mavftp, mavutil

from fsw.groundlink import ftp, metadata
from interfaces.mavlink import dialect as mav

from tests.procs import free_udp
from tests.rig import Rig, rig  # noqa: F401  (the shared fixture)

# parameter.schema.json "additionalProperties": false -> only these keys
PARAM_KEYS = {"name", "type", "shortDesc", "longDesc", "units", "default", "decimalPlaces", "min", "max",
              "increment", "rebootRequired", "group", "category", "volatile", "values", "bitmask", "readOnly"}
GENERAL_KEYS = {"version", "vendorName", "modelName", "firmwareVersion", "hardwareVersion", "metadataTypes"}
TYPE_KEYS = {"type", "uri", "fileCrc", "uriFallback", "fileCrcFallback", "translationUri", "translationUriFallback"}


def req(seq, session, op, offset=0, data=b"", size=None) -> bytes:
    size = len(data) if size is None else size
    return (struct.pack("<HBBBBBBI", seq, session, op, size, 0, 0, 0, offset) + data).ljust(251, b"\0")


def parse(payload: bytes):
    seq, session, op, size, req_op, burst, _, offset = struct.unpack_from("<HBBBBBBI", payload)
    return seq, session, op, size, req_op, burst, offset, payload[12:12 + size]


def test_metadata_files_say_what_the_registry_declares(rig):
    files = metadata.build(rig.fsw.registry, "ellipsled")
    general = json.loads(files[metadata.GENERAL_PATH])
    params = json.loads(files[metadata.PARAMETER_PATH])
    assert set(general) <= GENERAL_KEYS and general["version"] >= 1
    types = {mt["type"]: mt for mt in general["metadataTypes"]}
    assert set(types) == {mav.COMP_METADATA_TYPE_PARAMETER, mav.COMP_METADATA_TYPE_EVENTS}
    for mt, path in ((types[1], metadata.PARAMETER_PATH), (types[4], metadata.EVENTS_PATH)):
        assert set(mt) <= TYPE_KEYS and mt["uri"] == "mftp://" + path and mt["fileCrc"] == zlib.crc32(files[path])
    assert params["version"] >= 3
    rows = {r["param_id"]: r for r in rig.fsw.registry.describe() if r["ground_settable"]}
    got = {p["name"]: p for p in params["parameters"]}
    assert set(got) == set(rows) == set(rig.gl.param_names and [rig.fsw.registry.ids[n] for n in rig.gl.param_names])
    for pid, p in got.items():
        r = rows[pid]
        assert set(p) <= PARAM_KEYS and len(pid) <= 16 and p["type"] == "Float"
        assert (p["min"], p["max"], p["default"]) == (r["min"], r["max"], r["default"])
        assert p["longDesc"] == r["description"] and p["shortDesc"] == r["name"] and p["group"] == r["owner"]
        assert p.get("units", "") == ("" if r["unit"] in ("", "-") else r["unit"])
        assert (p.get("decimalPlaces"), p.get("increment")) == ((0, 1) if r["integer"] else (None, None))


@pytest.fixture
def server():
    return ftp.FtpServer({"metadata/a.json": b"x" * 1000, "metadata/b.json": b"{}", "top.txt": b"hello"},
                         max_sessions=2, burst_packets=4)


def test_ftp_lists_opens_reads_and_bursts_a_file(server):
    (r,) = server.handle(req(7, 0, ftp.LIST, 0, b"/"))
    seq, _, op, _, req_op, _, _, data = parse(r)
    assert (seq, op, req_op) == (8, ftp.ACK, ftp.LIST)
    assert data.split(b"\0")[:-1] == [b"Dmetadata", b"Ftop.txt\t5"]
    (r,) = server.handle(req(1, 0, ftp.LIST, 1, b"metadata"))
    assert parse(r)[7].split(b"\0")[:-1] == [b"Fb.json\t2"]
    (r,) = server.handle(req(1, 0, ftp.LIST, 2, b"metadata"))
    assert parse(r)[2] == ftp.NAK and parse(r)[7] == bytes([ftp.EOF])
    (r,) = server.handle(req(2, 0, ftp.OPEN_RO, 0, b"/metadata/a.json"))
    _, session, op, _, _, _, _, data = parse(r)
    assert op == ftp.ACK and struct.unpack("<I", data)[0] == 1000
    got = bytearray()
    offset, seq = 0, 10
    while True:
        replies = server.handle(req(seq, session, ftp.BURST, offset, size=239))
        last = parse(replies[-1])
        if last[2] == ftp.NAK:
            assert last[7] == bytes([ftp.EOF])
            break
        assert len(replies) <= 4 and last[5] == 1 and all(parse(x)[5] == 0 for x in replies[:-1])
        assert [parse(x)[0] for x in replies] == [seq + 1 + i for i in range(len(replies))]
        for x in replies:
            assert parse(x)[6] == len(got)
            got += parse(x)[7]
        offset = len(got)
        seq += 10
        if len(got) >= 1000 and parse(replies[-1])[3] < 239:
            break
    assert bytes(got) == b"x" * 1000
    (r,) = server.handle(req(3, session, ftp.READ, 990, size=100))
    assert parse(r)[7] == b"x" * 10
    (r,) = server.handle(req(4, 0, ftp.CRC32, 0, b"top.txt"))
    assert struct.unpack("<I", parse(r)[7])[0] == zlib.crc32(b"hello")
    (r,) = server.handle(req(5, session, ftp.TERMINATE))
    assert parse(r)[2] == ftp.ACK and not server.sessions


@pytest.mark.parametrize("payload, error", [
    (req(1, 0, ftp.READ, 0, size=10), ftp.INVALID_SESSION),                  # no session open
    (req(1, 0, ftp.OPEN_RO, 0, b"nope.json"), ftp.FILE_NOT_FOUND),
    (req(1, 0, ftp.OPEN_RO, 0, b"\xff\xfe"), ftp.FILE_NOT_FOUND),             # not UTF-8
    (req(1, 0, ftp.LIST, 0, b"no/such/dir"), ftp.FILE_NOT_FOUND),
    (req(1, 0, ftp.OPEN_RO, 0, b"top.txt", size=240), ftp.INVALID_DATA_SIZE),  # size over the payload
    (req(1, 0, ftp.CREATE, 0, b"new.txt"), ftp.FILE_PROTECTED),
    (req(1, 0, ftp.WRITE, 0, b"data"), ftp.FILE_PROTECTED),
    (req(1, 0, ftp.REMOVE, 0, b"top.txt"), ftp.FILE_PROTECTED),
    (req(1, 0, ftp.RENAME, 0, b"top.txt\0x"), ftp.FILE_PROTECTED),
    (req(1, 0, 99), ftp.UNKNOWN_COMMAND),
    (req(1, 9, ftp.TERMINATE), ftp.INVALID_SESSION),
])
def test_ftp_bad_requests_get_the_right_nak(server, payload, error):
    (r,) = server.handle(payload)
    assert parse(r)[2] == ftp.NAK and parse(r)[7] == bytes([error])
    assert server.files["top.txt"] == b"hello" and set(server.files) == {"metadata/a.json", "metadata/b.json",
                                                                         "top.txt"}


def test_ftp_sessions_are_bounded_and_garbage_is_ignored(server):
    for _ in range(2):
        assert parse(server.handle(req(1, 0, ftp.OPEN_RO, 0, b"top.txt"))[0])[2] == ftp.ACK
    (r,) = server.handle(req(1, 0, ftp.OPEN_RO, 0, b"top.txt"))
    assert parse(r)[7] == bytes([ftp.NO_SESSIONS])
    (r,) = server.handle(req(1, 1, ftp.READ, 5, size=10))
    assert parse(r)[7] == bytes([ftp.EOF])
    assert server.handle(b"\x01\x02") == [] and server.handle(b"") == []
    assert server.handle(req(1, 0, ftp.NONE)) == []
    (r,) = server.handle(req(1, 0, ftp.RESET))
    assert parse(r)[2] == ftp.ACK and not server.sessions


def test_component_metadata_names_the_general_file_and_its_crc(rig):
    assert rig.raw_command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_COMPONENT_METADATA) == mav.MAV_RESULT_ACCEPTED
    assert rig.exchange(lambda: "COMPONENT_METADATA" in rig.gcs.state.latest, 1.0)
    cm = rig.gcs.state.latest["COMPONENT_METADATA"]
    uri = cm.uri.decode() if isinstance(cm.uri, bytes) else cm.uri
    assert uri == "mftp://" + metadata.GENERAL_PATH
    assert cm.file_crc == zlib.crc32(rig.gl.files[metadata.GENERAL_PATH])
    assert rig.raw_command(mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1) == mav.MAV_RESULT_ACCEPTED
    assert rig.exchange(lambda: "AUTOPILOT_VERSION" in rig.gcs.state.latest, 1.0)
    assert rig.gcs.state.latest["AUTOPILOT_VERSION"].capabilities & mav.MAV_PROTOCOL_CAPABILITY_FTP


def test_a_stock_pymavlink_client_downloads_the_metadata_over_signed_ftp(tmp_path, monkeypatch):
    """pymavlink's own MAVFTP (common dialect, signed with the shared key) against a live
    ground link ticked at 10 Hz on its own thread, as the FSW's RG2 does."""
    monkeypatch.setenv("MAVLINK20", "1")         # mavutil speaks MAVLink 1 unless told (the vehicle refuses v1)
    port = free_udp()
    r = Rig(tmp_path)
    stop = threading.Event()
    conn = None
    try:
        r.fly(10)
        conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{r.gl.address[1]}", dialect="common",
                                          source_system=255, source_component=190)
        conn.setup_signing(r.key.secret, sign_outgoing=True)
        r.gl.gcs = ("127.0.0.1", port)            # telemetry elsewhere: the client sees its answers

        def ticking():
            while not stop.is_set():
                r.gl.tick(r.frame)
                time.sleep(0.1)
        th = threading.Thread(target=ticking, daemon=True)
        th.start()
        conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        client = mavftp.MAVFTP(conn, target_system=1, target_component=1)
        assert client.cmd_list(["metadata"]).error_code == mavftp.FtpError.Success
        names = {e.name for e in client.list_result}
        assert {"general.json", "parameters.json", "events.json"} <= names
        got = {}
        for path in (metadata.GENERAL_PATH, metadata.PARAMETER_PATH, metadata.EVENTS_PATH):
            def keep(fh, path=path):
                got[path] = fh.read()
            client.cmd_get([path], callback=keep)
            ret = client.process_ftp_reply("OpenFileRO", timeout=20)
            assert ret.error_code == mavftp.FtpError.Success, path
        assert got == r.gl.files
        params = json.loads(got[metadata.PARAMETER_PATH])
        assert {p["name"] for p in params["parameters"]} == {r.fsw.registry.ids[n] for n in r.gl.param_names}
        assert r.gl.ftp.stats["bytes_read"] >= len(got[metadata.PARAMETER_PATH])
    finally:
        stop.set()
        if conn is not None:
            conn.close()
        r.close()


def test_an_unsigned_ftp_request_is_refused(rig):
    raw = mav.MAVLink(io.BytesIO(), srcSystem=255, srcComponent=190)
    frame = mav.MAVLink_file_transfer_protocol_message(0, 1, 1, list(req(1, 0, ftp.RESET))).pack(raw)
    before = rig.gl.rejections
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(frame, rig.gl.address)
    rig.exchange(lambda: rig.gl.rejections > before, 1.0)
    assert rig.gl.rejections > before and rig.gl.ftp.stats["requests"] == 0
