"""The ellipsled MAVLink dialect: ids free and in range, bindings up to date, wire layout.

Independent truth: the XML files themselves (parsed here with ElementTree, not mavgen),
the MAVLink serialization rules (fields sorted by type size, CRC_EXTRA from the message
signature) re-implemented below, and the FSW's own health constants.
"""
from __future__ import annotations

import random
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from interfaces.mavlink import dialect as mav
from interfaces.mavlink import generate
from interfaces.mavlink.framing import HEADER_LEN_V2

XML = generate.DIALECT_XML
STOCK = generate.pymavlink_xml_dir()

# MAVLink type -> (struct code, size)
TYPES = {"char": ("c", 1), "uint8_t": ("B", 1), "int8_t": ("b", 1), "uint16_t": ("H", 2),
         "int16_t": ("h", 2), "uint32_t": ("I", 4), "int32_t": ("i", 4), "float": ("f", 4),
         "uint64_t": ("Q", 8), "int64_t": ("q", 8), "double": ("d", 8)}


def _root(path: Path) -> ET.Element:
    return ET.parse(path).getroot()


def _message_ids(root: ET.Element) -> set[int]:
    return {int(m.get("id")) for m in root.iter("message")}


def _cmd_ids(root: ET.Element) -> set[int]:
    return {int(e.get("value")) for en in root.iter("enum") if en.get("name") == "MAV_CMD"
            for e in en.iter("entry")}


def _ours() -> ET.Element:
    return _root(XML)


def test_dialect_includes_common_and_nothing_else():
    assert [i.text.strip() for i in _ours().iter("include")] == ["common.xml"]


# Upstream common.xml messages that pymavlink 2.4.50's common.xml lacks, defined in the
# dialect as upstream defines them; CRC_EXTRA as published in the upstream C headers
# (mavlink/c_library_v2 common: MAVLINK_MSG_ID_PROTOCOL_VERSION_CRC 217,
# MAVLINK_MSG_ID_COMPONENT_METADATA_CRC 182, MAVLINK_MSG_ID_EVENT_CRC 160,
# MAVLINK_MSG_ID_CURRENT_EVENT_SEQUENCE_CRC 106, MAVLINK_MSG_ID_REQUEST_EVENT_CRC 33,
# MAVLINK_MSG_ID_RESPONSE_EVENT_ERROR_CRC 77; AVAILABLE_MODES 134 and CURRENT_MODE 193, as
# pymavlink 2.4.50's own development dialect has them).
UPSTREAM_COMMON = {300: ("PROTOCOL_VERSION", 217), 397: ("COMPONENT_METADATA", 182), 410: ("EVENT", 160),
                   411: ("CURRENT_EVENT_SEQUENCE", 106), 412: ("REQUEST_EVENT", 33), 413: ("RESPONSE_EVENT_ERROR", 77),
                   435: ("AVAILABLE_MODES", 134), 436: ("CURRENT_MODE", 193)}


def test_upstream_common_messages_match_the_published_crc_extra():
    for mid, (name, crc_extra) in UPSTREAM_COMMON.items():
        xml_msg = next(m for m in _ours().iter("message") if m.get("id") == str(mid))
        assert xml_msg.get("name") == name
        assert _crc_extra(name, _fields(xml_msg)) == crc_extra          # independent derivation
        assert mav.mavlink_map[mid].crc_extra == crc_extra


def test_message_ids_are_mavlink2_range_and_unused_by_every_shipped_dialect():
    ours = _message_ids(_ours()) - set(UPSTREAM_COMMON)
    assert ours == {44000, 44001, 44002, 44003, 44004}
    assert all(256 <= i <= 16_777_215 for i in ours)      # > 255 needs MAVLink 2 (24-bit id)
    shipped = [p for p in STOCK.glob("*.xml")]
    assert any(p.name == "common.xml" for p in shipped)
    for p in shipped:
        clash = ours & _message_ids(_root(p))
        assert not clash, f"{p.name} already uses message ids {sorted(clash)}"
        # the upstream ones: where a shipped dialect has the id, it is the same message
        same = {int(m.get("id")): m.get("name") for m in _root(p).iter("message")}
        for mid, (name, _) in UPSTREAM_COMMON.items():
            assert same.get(mid, name) == name, f"{p.name} uses message id {mid} for {same[mid]}"


def test_command_ids_fit_command_long_and_are_unused_by_every_shipped_dialect():
    ours = _cmd_ids(_ours())
    assert ours == set(range(44100, 44106))
    # COMMAND_LONG.command is uint16_t; common's own ids are 0-39999 plus a few
    # 42006, 42600, 43000-43003 (checked, not assumed, below).
    assert all(40000 <= c <= 65535 for c in ours)
    common_cmds = _cmd_ids(_root(STOCK / "common.xml"))
    assert {c for c in common_cmds if c >= 40000} == {42006, 42600, 43000, 43001, 43002, 43003}
    for p in STOCK.glob("*.xml"):
        clash = ours & _cmd_ids(_root(p))
        assert not clash, f"{p.name} already uses MAV_CMD ids {sorted(clash)}"


def test_generated_module_exposes_custom_ids_and_inject_failure():
    assert mav.MAVLINK_MSG_ID_ELLIPSLED_ENTRY_STATE == 44000
    assert mav.MAVLINK_MSG_ID_ELLIPSLED_LOOP_TIMING == 44003
    assert mav.ELLIPSLED_CMD_SET_MODE == 44100
    assert mav.ELLIPSLED_CMD_FDIR_SET_DELAY == 44105
    assert mav.MAV_CMD_INJECT_FAILURE == 420
    assert mav.FAILURE_UNIT_SYSTEM_MOTOR == 101
    assert (mav.FAILURE_TYPE_OK, mav.FAILURE_TYPE_OFF, mav.FAILURE_TYPE_STUCK,
            mav.FAILURE_TYPE_WRONG) == (0, 1, 2, 4)
    assert mav.WIRE_PROTOCOL_VERSION == "2.0"


def test_every_field_has_units_or_is_dimensionless_by_design():
    dimensionless = {"mach", "theta_hat", "eta_hat", "health", "pulses", "commanded", "firing",
                     "alloc_solves", "alloc_degraded", "cycle_slips", "rate_group", "mode", "flags", "bank_sign",
                     "density_scale", "cycles", "overruns", "reversals", "last_reversal_rule"}
    for m in _ours().iter("message"):
        if int(m.get("id")) in UPSTREAM_COMMON:       # upstream's text, kept verbatim
            continue
        for f in m.iter("field"):
            assert f.get("units") or f.get("name") in dimensionless, (m.get("name"), f.get("name"))


def test_committed_bindings_equal_a_fresh_generation(tmp_path):
    out = tmp_path / "ellipsled.py"
    assert generate.main(["--out", str(out)]) == 0
    fresh = out.read_text(encoding="utf-8").splitlines()
    committed = generate.GENERATED_PY.read_text(encoding="utf-8").splitlines()
    assert fresh == committed, ("interfaces/mavlink/generated/ellipsled.py is out of date: "
                                "run python -m interfaces.mavlink.generate")
    assert generate.main(["--check", "--out", str(out)]) == 0


def test_check_mode_detects_a_stale_file(tmp_path):
    stale = tmp_path / "ellipsled.py"
    stale.write_text(generate.GENERATED_PY.read_text(encoding="utf-8").replace("44003", "44004"))
    assert generate.main(["--check", "--out", str(stale)]) == 1


# ---- wire layout, re-derived from the XML per the MAVLink serialization rules -------------


def _fields(msg: ET.Element):
    out = []
    for f in msg:
        if f.tag == "extensions":         # extension fields are not part of CRC_EXTRA or the sort
            break
        if f.tag != "field":
            continue
        t = f.get("type")
        n = 1
        if "[" in t:
            t, n = t[:-1].split("[")
            n = int(n)
        out.append((f.get("name"), t, n))
    return out


def _wire_order(fields):
    # MAVLink sorts fields by base-type size, largest first, stable (no extensions here).
    return sorted(fields, key=lambda f: -TYPES[f[1]][1])


def _crc_x25(data: bytes, crc: int = 0xFFFF) -> int:
    for b in data:
        tmp = b ^ (crc & 0xFF)
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


def _crc_extra(name: str, fields) -> int:
    crc = _crc_x25((name + " ").encode())
    for fname, t, n in _wire_order(fields):
        crc = _crc_x25((t + " ").encode(), crc)
        crc = _crc_x25((fname + " ").encode(), crc)
        if n > 1:
            crc = _crc_x25(bytes([n]), crc)
    return (crc & 0xFF) ^ (crc >> 8)


def _f32(rng: random.Random) -> float:
    return struct.unpack("<f", struct.pack("<f", rng.uniform(-1e4, 1e4)))[0]


def _value(rng: random.Random, t: str):
    if t == "float":
        return _f32(rng)
    if t in ("uint8_t", "int8_t"):
        return rng.randrange(1, 5)          # valid ELLIPSLED_JET_HEALTH / rate group / sign
    if t == "uint16_t":
        return rng.randrange(1, 2**16)
    if t == "uint32_t":
        return rng.randrange(1, 2**32)
    raise AssertionError(t)


@pytest.mark.parametrize("msg_name", ["ELLIPSLED_ENTRY_STATE", "ELLIPSLED_JET_STATUS",
                                      "ELLIPSLED_CONTROL_STATUS", "ELLIPSLED_LOOP_TIMING",
                                      "ELLIPSLED_GUIDANCE_STATUS"])
def test_custom_message_round_trip_and_independent_wire_layout(msg_name):
    xml_msg = next(m for m in _ours().iter("message") if m.get("name") == msg_name)
    fields = _fields(xml_msg)
    cls = mav.mavlink_map[int(xml_msg.get("id"))]
    assert cls.msgname == msg_name
    assert cls.crc_extra == _crc_extra(msg_name, fields)
    payload_len = sum(TYPES[t][1] * n for _, t, n in fields)
    assert payload_len <= 255

    rng = random.Random(msg_name)
    values = {name: (_value(rng, t) if n == 1 else [_value(rng, t) for _ in range(n)])
              for name, t, n in fields}
    enc = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    frame = cls(**values).pack(enc)

    # independent decode: header, then payload in wire order (zero-padded: MAVLink 2
    # strips trailing zero bytes), then the CRC with the independently derived CRC_EXTRA
    assert frame[0] == 0xFD
    plen = frame[1]
    msgid = frame[7] | frame[8] << 8 | frame[9] << 16
    assert msgid == int(xml_msg.get("id"))
    payload = frame[HEADER_LEN_V2:HEADER_LEN_V2 + plen].ljust(payload_len, b"\0")
    fmt = "<" + "".join(f"{n}{TYPES[t][0]}" for _, t, n in _wire_order(fields))
    flat = list(struct.unpack(fmt, payload))
    got = {}
    for name, t, n in _wire_order(fields):
        got[name] = flat[0] if n == 1 else flat[:n]
        del flat[:n]
    assert got == values
    crc = _crc_x25(bytes([_crc_extra(msg_name, fields)]),
                   _crc_x25(frame[1:HEADER_LEN_V2 + plen]))
    assert frame[HEADER_LEN_V2 + plen:HEADER_LEN_V2 + plen + 2] == struct.pack("<H", crc)

    # pymavlink decode of the same bytes gives the same values back
    dec = mav.MAVLink(None).decode(bytearray(frame))
    assert dec.get_type() == msg_name
    assert {name: getattr(dec, name) for name in values} == values
