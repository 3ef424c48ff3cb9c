"""Verify-first MAVLink 2 signing: key files, every rejection path, the pymavlink lockout
weakness and its absence here, interoperability with stock pymavlink (common.xml only).

Independent truth: stock pymavlink 2.4.50 (``pymavlink.dialects.v20.common``) as the
other end, signatures recomputed by hand from the MAVLink signing rule, and a fixed fake
clock so timestamps are exact.
"""
from __future__ import annotations

import hashlib
import logging
import os
import random
import struct

import pytest
from pymavlink.dialects.v20 import common as stock

from interfaces.mavlink import dialect as mav
from interfaces.mavlink.framing import FrameSplitter, parse_header
from interfaces.mavlink.signing.keys import KEY_ENV, REPO_ROOT, SigningKey, SigningKeyError, stream_state_path
from interfaces.mavlink.signing.link import SignedLink
from interfaces.mavlink.signing.sign import Signer, signing_timestamp
from interfaces.mavlink.signing.verify import Reject

T0 = 1_760_000_000.0            # fake Unix time [s] (2025-10)
TS0 = signing_timestamp(T0)
KEY = SigningKey(bytes(range(32)), "test")
OTHER_KEY = SigningKey(bytes(range(100, 132)), "attacker")
GCS_SYS, GCS_COMP = 255, 190


class Clock:
    def __init__(self, t: float = T0):
        self.t = t

    def __call__(self) -> float:
        return self.t


def vehicle(clock=None, **kw) -> SignedLink:
    return SignedLink(KEY, system_id=1, component_id=1, clock=clock or Clock(), **kw)


def ground(clock=None, key=KEY) -> SignedLink:
    return SignedLink(key, system_id=GCS_SYS, component_id=GCS_COMP, clock=clock or Clock())


def inject_cmd(jet: int = 7) -> mav.MAVLink_command_long_message:
    return mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_INJECT_FAILURE, 0,
                                            mav.FAILURE_UNIT_SYSTEM_MOTOR, mav.FAILURE_TYPE_OFF,
                                            jet, 0, 0, 0, 0)


def heartbeat() -> mav.MAVLink_heartbeat_message:
    return mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)


def stock_mav(key: SigningKey | None, sysid: int, compid: int, ts: int = TS0, link_id: int = 0):
    """A stock pymavlink (common.xml) MAVLink object with its own signing set up."""
    m = stock.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    m.robust_parsing = True
    if key is not None:
        m.signing.secret_key = key.secret
        m.signing.sign_outgoing = True
        m.signing.link_id = link_id
        m.signing.timestamp = ts
    return m


def stock_cmd(m) -> bytes:
    return stock.MAVLink_command_long_message(1, 1, 420, 0, 101, 1, 7, 0, 0, 0, 0).pack(m)


# --------------------------------------------------------------------------- key files


def write(tmp_path, text: str, name: str = "key.hex") -> str:
    p = tmp_path / name
    p.write_text(text)
    os.chmod(p, 0o600)
    return str(p)


def test_key_file_loads_with_surrounding_whitespace(tmp_path):
    hexkey = bytes(range(32)).hex().upper()
    key = SigningKey.from_file(write(tmp_path, f"\n  {hexkey}\t\n"))
    assert key == KEY and key.secret == bytes(range(32))


def test_key_file_from_environment_variable(tmp_path):
    path = write(tmp_path, bytes(range(32)).hex())
    assert SigningKey.from_file(env={KEY_ENV: path}) == KEY
    with pytest.raises(SigningKeyError, match=KEY_ENV):
        SigningKey.from_file(env={})


@pytest.mark.parametrize("content, match", [
    ("ab" * 31, "expected 64 hex characters .* found 62"),
    ("ab" * 33, "found 66"),
    ("zz" * 32, "not hexadecimal"),
    ("ab" * 16 + " " + "ab" * 16, "found 65"),
    ("", "found 0"),
])
def test_bad_key_files_give_clear_errors_without_the_content(tmp_path, content, match):
    path = write(tmp_path, content)
    with pytest.raises(SigningKeyError, match=match) as e:
        SigningKey.from_file(path)
    assert path in str(e.value)
    if len(content) >= 8:
        assert content.strip()[:8] not in str(e.value)


def test_non_ascii_key_file_and_missing_file_and_directory(tmp_path):
    p = tmp_path / "bin.key"
    p.write_bytes(bytes(range(200, 232)) * 2)
    with pytest.raises(SigningKeyError, match="not hexadecimal"):
        SigningKey.from_file(p)
    with pytest.raises(SigningKeyError, match="not found"):
        SigningKey.from_file(tmp_path / "nope.key")
    with pytest.raises(SigningKeyError, match="not a regular file"):
        SigningKey.from_file(tmp_path)


@pytest.mark.skipif(REPO_ROOT is None, reason="not running from a source tree")
def test_key_file_inside_the_repository_is_refused():
    with pytest.raises(SigningKeyError, match="inside the repository"):
        SigningKey.from_file(REPO_ROOT / "data" / "some.key")    # refused before reading
    with pytest.raises(SigningKeyError, match="inside the repository"):
        KEY.write_file(REPO_ROOT / "secret.key")
    assert not (REPO_ROOT / "secret.key").exists()


def test_key_never_appears_in_repr_or_logs(tmp_path, caplog):
    path = tmp_path / "k.hex"
    path.write_text(KEY.secret.hex())
    os.chmod(path, 0o644)
    with caplog.at_level(logging.DEBUG):
        key = SigningKey.from_file(path)
    assert "readable by group/others" in caplog.text
    for text in (repr(key), str(key), caplog.text):
        assert KEY.secret.hex() not in text.lower() and KEY.secret.hex()[:16] not in text.lower()
    assert len(key.key_id) == 8 and key.key_id == KEY.key_id != OTHER_KEY.key_id


def test_write_file_creates_0600_and_refuses_overwrite(tmp_path):
    key = SigningKey.generate()
    p = key.write_file(tmp_path / "new.key")
    assert (p.stat().st_mode & 0o777) == 0o600
    assert SigningKey.from_file(p) == key
    with pytest.raises(SigningKeyError, match="already exists"):
        key.write_file(p)


# --------------------------------------------------------------------------- signing


def test_signature_matches_the_mavlink_rule_computed_by_hand():
    s = Signer(KEY, system_id=255, component_id=190, link_id=3, clock=Clock())
    frame = s.pack(inject_cmd())
    hdr = parse_header(frame)
    assert hdr.version == 2 and hdr.signed and len(frame) == hdr.frame_len
    assert frame[-13] == 3
    assert int.from_bytes(frame[-12:-6], "little") == TS0
    assert frame[-6:] == hashlib.sha256(KEY.secret + frame[:-6]).digest()[:6]
    # a second frame in the same instant still gets a strictly larger timestamp
    frame2 = s.pack(inject_cmd())
    assert int.from_bytes(frame2[-12:-6], "little") == TS0 + 1
    assert frame2[4] == (frame[4] + 1) % 256        # sequence number


_INT_RANGES = {"int8_t": (-128, 127), "uint8_t": (0, 255), "int16_t": (-2**15, 2**15 - 1), "uint16_t": (0, 2**16 - 1),
               "int32_t": (-2**31, 2**31 - 1), "uint32_t": (0, 2**32 - 1), "int64_t": (-2**63, 2**63 - 1),
               "uint64_t": (0, 2**64 - 1)}


def _random_message(cls, rng: random.Random):
    """An instance of dialect message ``cls`` with random field values, about half of them
    zero (trailing zeros are what MAVLink 2 truncates)."""
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))

    def value(ftype: str):
        if rng.random() < 0.5:
            return 0
        if ftype in ("float", "double"):
            return rng.uniform(-1e6, 1e6)
        return rng.randint(*_INT_RANGES[ftype])

    args = []
    for name, ftype in zip(cls.fieldnames, cls.fieldtypes):
        n = lengths[name]
        if ftype == "char":
            args.append(bytes(rng.choice(b"abcXYZ_09") for _ in range(rng.randint(0, max(n, 1)))))
        elif n:
            args.append([value(ftype) for _ in range(n)])
        else:
            args.append(value(ftype))
    return cls(*args)


@pytest.mark.parametrize("signed", [True, False])
def test_every_dialect_message_is_framed_as_pymavlink_frames_it(signed):
    """Signer.pack frames by hand; pymavlink's own packing of the same message, with the
    same key, sequence and timestamp, is the truth: byte for byte, for every message of the
    dialect, several random fillings each (zero fields, all-zero payloads, 24-bit ids)."""
    rng = random.Random(7)
    s = Signer(KEY, system_id=1, component_id=1, link_id=2, clock=Clock())
    ref = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    if signed:
        ref.signing.secret_key, ref.signing.link_id, ref.signing.sign_outgoing = KEY.secret, 2, True
        ref.signing.timestamp = TS0
    n = 0
    for cls in mav.mavlink_map.values():
        for _ in range(4):
            msg = _random_message(cls, rng)
            ref.seq = s.seq
            ours = s.pack(msg, signed=signed)
            left = (msg.get_seq(), msg.get_srcSystem(), msg.get_srcComponent(), msg.get_crc(), msg.get_msgbuf())
            assert ours == msg.pack(ref), cls.__name__
            # and what packing leaves on the message (a sent message equals the same one received)
            assert left == (msg.get_seq(), msg.get_srcSystem(), msg.get_srcComponent(), msg.get_crc(),
                            msg.get_msgbuf()), cls.__name__
            n += 1
    assert n == 4 * len(mav.mavlink_map) > 800


def test_signing_timestamp_epoch_and_units():
    assert signing_timestamp(1420070400.0) == 0
    assert signing_timestamp(1420070400.0 + 1.5) == 150_000
    assert signing_timestamp(0.0) == 0
    assert signing_timestamp(1e12) == (1 << 48) - 1


def test_signed_command_accepted_and_decoded():
    veh, gcs = vehicle(), ground()
    [msg] = veh.receive(gcs.pack(inject_cmd(jet=7)))
    assert msg.get_type() == "COMMAND_LONG" and msg.command == 420 and msg.param3 == 7
    assert msg.get_signed() and msg.get_link_id() == 0
    assert msg.get_srcSystem() == GCS_SYS
    assert veh.verifier.stream_timestamp(GCS_SYS, GCS_COMP, 0) == TS0
    assert veh.verifier.rejected == 0


def test_unsigned_command_rejected():
    veh = vehicle()
    plain = stock_mav(None, GCS_SYS, GCS_COMP)
    assert veh.receive(stock_cmd(plain)) == []
    assert veh.counts[Reject.UNSIGNED] == 1
    # also when sent by our own signer in unsigned mode, and as MAVLink 1
    assert veh.receive(ground().pack(inject_cmd(), signed=False)) == []
    v1 = stock.MAVLink_command_long_message(1, 1, 420, 0, 101, 1, 7, 0, 0, 0, 0).pack(
        plain, force_mavlink1=True)
    assert v1[0] == 0xFE and veh.receive(v1) == []
    assert veh.counts[Reject.UNSIGNED] == 3


def test_unsigned_heartbeat_accepted_but_marked_unsigned():
    veh = vehicle()
    [hb] = veh.receive(ground().pack(heartbeat(), signed=False))
    assert hb.get_type() == "HEARTBEAT" and hb.get_signed() is False
    plain = stock_mav(None, GCS_SYS, GCS_COMP)
    v1 = stock.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(plain, force_mavlink1=True)
    assert [m.get_type() for m in veh.receive(v1)] == ["HEARTBEAT"]
    assert veh.verifier.accepted_unsigned == 2 and veh.verifier.rejected == 0


def test_signed_heartbeat_with_bad_signature_is_rejected_not_downgraded():
    veh = vehicle()
    assert veh.receive(ground(key=OTHER_KEY).pack(heartbeat())) == []
    assert veh.counts[Reject.BAD_SIGNATURE] == 1


def test_wrong_key_rejected_and_reported_through_the_hook():
    seen = []
    veh = vehicle(on_reject=seen.append)
    assert veh.receive(ground(key=OTHER_KEY).pack(inject_cmd())) == []
    assert veh.counts[Reject.BAD_SIGNATURE] == 1
    [r] = seen
    assert (r.reason, r.sysid, r.compid, r.msgid) == (Reject.BAD_SIGNATURE, GCS_SYS, GCS_COMP, 76)
    assert veh.verifier.stream_timestamp(GCS_SYS, GCS_COMP, 0) is None


def test_every_single_byte_tamper_is_rejected():
    veh = vehicle()
    frame = ground().pack(inject_cmd())
    for i in range(1, len(frame)):
        bad = bytearray(frame)
        bad[i] ^= 0x01
        assert veh.verifier.verify(bytes(bad)).accepted is False, i
        # and through the full receive path (splitter CRC or signature catches it)
        assert veh.receive(bytes(bad)) == [], i
    assert veh.verifier.accepted_signed == 0
    assert veh.counts[Reject.BAD_SIGNATURE] > 0 and veh.counts[Reject.BAD_CRC] > 0
    # tampering with a payload byte AND fixing the CRC is still caught by the signature
    hdr = parse_header(frame)
    bad = bytearray(frame)
    bad[hdr.header_len + 2] ^= 0x40
    end = hdr.header_len + hdr.payload_len
    crc = mav.x25crc(bytes(bad[1:end]))
    crc.accumulate(bytes([mav.MAVLink_command_long_message.crc_extra]))
    bad[end:end + 2] = struct.pack("<H", crc.crc)
    before = veh.counts[Reject.BAD_SIGNATURE]
    assert veh.receive(bytes(bad)) == []
    assert veh.counts[Reject.BAD_SIGNATURE] == before + 1
    assert veh.receive(frame) != []                  # the genuine frame still passes


def test_replay_rejected():
    veh, gcs = vehicle(), ground()
    f1, f2 = gcs.pack(inject_cmd(1)), gcs.pack(inject_cmd(2))
    assert len(veh.receive(f1)) == 1
    assert veh.receive(f1) == []                     # same frame again
    assert len(veh.receive(f2)) == 1
    assert veh.receive(f1) == []                     # older frame after a newer one
    assert veh.counts[Reject.REPLAY] == 2


def test_streams_are_independent_per_link_id():
    veh = vehicle()
    a = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, link_id=1, clock=Clock(T0 + 5))
    b = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, link_id=2, clock=Clock(T0))
    assert len(veh.receive(a.pack(inject_cmd()))) == 1
    assert len(veh.receive(b.pack(inject_cmd()))) == 1     # older timestamp, other stream


def test_future_and_stale_timestamps_rejected_without_touching_stream_state():
    clock = Clock()
    veh = vehicle(clock)
    gcs = ground()
    assert len(veh.receive(gcs.pack(inject_cmd()))) == 1
    ahead = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, clock=Clock(T0 + 61))
    assert veh.receive(ahead.pack(inject_cmd())) == []
    assert veh.counts[Reject.FUTURE_TIMESTAMP] == 1
    assert veh.verifier.stream_timestamp(GCS_SYS, GCS_COMP, 0) == TS0
    within = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, clock=Clock(T0 + 59))
    assert len(veh.receive(within.pack(inject_cmd()))) == 1
    old = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, link_id=9, clock=Clock(T0 - 61))
    assert veh.receive(old.pack(inject_cmd())) == []
    assert veh.counts[Reject.STALE_TIMESTAMP] == 1


def test_bad_incompat_flags_rejected():
    veh = vehicle()
    frame = bytearray(ground().pack(heartbeat(), signed=False))
    frame[2] |= 0x02                                   # unknown incompat flag
    v = veh.verifier.verify(bytes(frame))
    assert not v.accepted and v.reason is Reject.BAD_FLAGS


# --------------------------------------------------------------------------- robustness


def test_random_bytes_and_truncations_never_raise_and_never_pass():
    rng = random.Random(1234)
    veh = vehicle()
    good = ground().pack(inject_cmd())
    for n in range(0, 400, 7):
        blob = bytes(rng.getrandbits(8) for _ in range(n))
        assert veh.receive(blob) == []
        assert veh.receive_stream(blob) == []
        assert veh.verifier.verify(blob).accepted is False
    for cut in range(len(good)):
        assert veh.receive(good[:cut]) == []
        assert veh.verifier.verify(good[:cut]).reason is Reject.MALFORMED
    # random bytes seeded with magic bytes, so header parsing is exercised
    for _ in range(300):
        blob = bytearray(rng.getrandbits(8) for _ in range(rng.randrange(1, 300)))
        for _ in range(3):
            blob[rng.randrange(len(blob))] = rng.choice((0xFD, 0xFE))
        assert veh.receive(bytes(blob)) == []
    assert veh.verifier.verify("not bytes").accepted is False   # type: ignore[arg-type]
    assert veh.verifier.accepted_signed == 0
    assert veh.counts[Reject.TRUNCATED] > 0 and veh.counts[Reject.GARBAGE] > 0


def test_frames_recovered_from_garbage_false_magic_and_concatenation():
    veh, gcs = vehicle(), ground()
    f1, f2, f3 = (gcs.pack(inject_cmd(j)) for j in (1, 2, 3))
    # a false 0xFD whose length byte claims a frame running over f2 must not swallow f2
    noise = b"\x01\x02\xfd\xff\x00\x00"
    dgram = b"junk" + f1 + noise + f2 + b"\xfe" + f3 + f1[:17]
    msgs = veh.receive(dgram)
    assert [m.param3 for m in msgs] == [1, 2, 3]
    assert veh.counts[Reject.TRUNCATED] == 1


def test_stream_feed_byte_by_byte():
    veh, gcs = vehicle(), ground()
    data = b"\x00\xfd" + b"".join(gcs.pack(inject_cmd(j)) for j in (4, 5, 6)) + b"\xfe"
    got = []
    for i in range(len(data)):
        got += veh.receive_stream(data[i:i + 1])
    assert [m.param3 for m in got] == [4, 5, 6]


def test_splitter_keeps_at_most_one_frame_of_tail():
    sp = FrameSplitter()
    sp.feed(b"\xfd\xff" + b"\x00" * 100)
    assert len(sp._tail) <= 280
    rng = random.Random(7)
    for _ in range(50):
        sp.feed(bytes(rng.getrandbits(8) for _ in range(97)))
        assert len(sp._tail) <= 280


# --------------------------------------------------------------------------- the lockout


def _forged_and_genuine():
    attacker = stock_mav(OTHER_KEY, GCS_SYS, GCS_COMP, ts=TS0 + 86_400 * 100_000)  # +1 day
    genuine = stock_mav(KEY, GCS_SYS, GCS_COMP, ts=TS0 + 100)                     # +1 ms
    return stock_cmd(attacker), stock_cmd(genuine)


def test_stock_pymavlink_is_locked_out_by_one_forged_future_frame():
    """Documents the library weakness: check_signature stores the timestamp before it
    compares the signature."""
    forged, genuine = _forged_and_genuine()
    # control: without the forged frame the genuine one is accepted by stock pymavlink
    fresh = stock_mav(KEY, 1, 1)
    assert fresh.parse_char(genuine).get_type() == "COMMAND_LONG"

    veh = stock_mav(KEY, 1, 1)                     # stock vehicle with signing on
    m = veh.parse_char(forged)
    assert m.get_type() == "BAD_DATA" and "Invalid signature" in m.reason
    assert veh.signing.badsig_count == 1
    # the forged timestamp became the stream's state although its signature was bad
    assert veh.signing.stream_timestamps[(0, GCS_SYS, GCS_COMP)] == TS0 + 86_400 * 100_000
    m = veh.parse_char(genuine)
    assert m.get_type() == "BAD_DATA" and "Invalid signature" in m.reason   # locked out
    assert veh.signing.goodsig_count == 0


def test_our_verifier_rejects_the_forged_frame_and_accepts_the_genuine_one_after():
    forged, genuine = _forged_and_genuine()
    veh = vehicle()
    assert veh.receive(forged) == []
    assert veh.counts[Reject.BAD_SIGNATURE] == 1
    assert veh.verifier.stream_timestamp(GCS_SYS, GCS_COMP, 0) is None
    [msg] = veh.receive(genuine)
    assert msg.get_type() == "COMMAND_LONG" and msg.get_signed()
    assert veh.verifier.stream_timestamp(GCS_SYS, GCS_COMP, 0) == TS0 + 100


def test_stock_pymavlink_passes_unsigned_unknown_ids_that_we_reject():
    """Second library gap: decode() returns unknown message ids before checking signing."""
    veh_stock = stock_mav(KEY, 1, 1)
    frame = ground().pack(mav.MAVLink_ellipsled_loop_timing_message(1, 2, 3, 4, 5, 6, 7, 8, 0),
                          signed=False)
    assert veh_stock.parse_char(frame).get_type() == "UNKNOWN_44003"
    assert vehicle().receive(frame) == []


# --------------------------------------------------------------------------- interop


def _vehicle_telemetry(link: SignedLink) -> list[bytes]:
    return [
        link.pack(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GENERIC, mav.MAV_AUTOPILOT_GENERIC,
                                                0, 0, mav.MAV_STATE_ACTIVE, 3)),
        link.pack(mav.MAVLink_attitude_message(1234, 0.5, -0.25, 1.0, 0.125, 0.0, -0.5)),
        link.pack(mav.MAVLink_statustext_message(mav.MAV_SEVERITY_CRITICAL,
                                                 b"jet 7 failed off", 0, 0)),
        link.pack(mav.MAVLink_ellipsled_entry_state_message(5, *([1.0] * 12))),
    ]


def test_stock_common_client_without_key_parses_our_signed_telemetry():
    frames = _vehicle_telemetry(vehicle())
    client = stock.MAVLink(None)                   # common.xml only, no signing
    msgs = client.parse_buffer(b"".join(frames))
    assert [m.get_type() for m in msgs] == ["HEARTBEAT", "ATTITUDE", "STATUSTEXT", "UNKNOWN_44000"]
    hb, att, txt, _ = msgs
    assert hb.system_status == stock.MAV_STATE_ACTIVE and hb.get_srcSystem() == 1
    assert (att.roll, att.pitch, att.yaw) == (0.5, -0.25, 1.0)
    assert txt.text == "jet 7 failed off" and txt.severity == 2
    # it saw the signatures and ignored them; pymavlink returns unknown ids before counting
    assert client.signing.sig_count == 3


def test_stock_client_with_key_accepts_our_frames_and_we_accept_its_commands():
    client = stock_mav(KEY, GCS_SYS, GCS_COMP, ts=signing_timestamp(T0))
    msgs = client.parse_buffer(b"".join(_vehicle_telemetry(vehicle())))
    assert [m.get_type() for m in msgs][:3] == ["HEARTBEAT", "ATTITUDE", "STATUSTEXT"]
    assert client.signing.goodsig_count == 3 and client.signing.badsig_count == 0
    [cmd] = vehicle().receive(stock_cmd(client))
    assert cmd.command == 420 and cmd.get_signed()


def test_round_trip_of_every_custom_message_over_the_signed_link():
    veh, gcs = vehicle(), ground()
    msgs = [
        mav.MAVLink_ellipsled_entry_state_message(10, 40000.0, 5500.0, -0.25, 1.5, 0.125, -0.375,
                                                  24.5, 2000.0, 0.25, 0.0, 1.0, 1.125),
        mav.MAVLink_ellipsled_jet_status_message(11, 0x3FFFF, 0x5, [0, 1, 2, 3, 4, 0] * 3,
                                                 [0.5] * 18, list(range(18)), [0.25] * 18),
        mav.MAVLink_ellipsled_control_status_message(12, [1.0, 2.0, 3.0], [-1.0, 0.5, 0.0],
                                                     [0.125] * 9, 1000, 350.5, 2),
        mav.MAVLink_ellipsled_loop_timing_message(13, 1.5, 20.0, 80.0, 300.0, 900.0, 1500.0, 3, 0),
    ]
    got = gcs.receive(b"".join(veh.pack(m) for m in msgs))
    assert [g.get_type() for g in got] == [m.get_type() for m in msgs]
    for m, g in zip(msgs, got):
        assert g.to_dict() == m.to_dict() and g.get_signed()


def test_rejection_text_fits_statustext():
    seen = []
    veh = vehicle(on_reject=seen.append)
    veh.receive(ground(key=OTHER_KEY).pack(inject_cmd()))
    veh.receive(b"\x00" * 40)
    assert seen[0].text() == "link rejected bad_signature 255/190 msg 76"
    assert seen[1].text() == "link rejected garbage"
    assert all(len(r.text()) <= 50 for r in seen)


def test_key_cli_writes_and_checks_a_key(tmp_path, capsys):
    from interfaces.mavlink import signing
    path = tmp_path / "gcs.key"
    assert signing.main(["new-key", str(path)]) == 0
    key = SigningKey.from_file(path)
    assert signing.main(["check-key", str(path)]) == 0
    assert signing.main(["new-key", str(path)]) == 1          # refuses to overwrite
    out = capsys.readouterr().out
    assert key.key_id in out and key.secret.hex() not in out


# --------------------------------------------------------------------------- replay across restarts


def test_nothing_signed_before_the_verifier_started_is_accepted():
    veh = vehicle(Clock(T0))
    earlier = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, link_id=3, clock=Clock(T0 - 5))
    assert veh.receive(earlier.pack(inject_cmd())) == []            # within max_age_s, but before start
    assert veh.counts[Reject.STALE_TIMESTAMP] == 1
    assert len(veh.receive(ground().pack(inject_cmd()))) == 1       # signed at the start: accepted


def test_stream_timestamps_survive_a_restart_beside_the_key_file(tmp_path):
    path = tmp_path / "ground.key"
    KEY.write_file(path)
    key = SigningKey.from_file(path)
    state = stream_state_path(key)
    assert state == tmp_path / "ground.key.streams"
    ahead = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, link_id=2, clock=Clock(T0 + 30))
    frame = ahead.pack(inject_cmd())
    run_a = vehicle(Clock(T0), state_path=state)
    assert len(run_a.receive(frame)) == 1
    assert (state.stat().st_mode & 0o777) == 0o600 and not list(tmp_path.glob("*.tmp"))
    run_b = vehicle(Clock(T0 + 1), state_path=state)                   # restarted, same key
    assert run_b.receive(frame) == [] and run_b.counts[Reject.REPLAY] == 1
    assert len(run_b.receive(ahead.pack(inject_cmd()))) == 1          # the ground's next frame


def test_frames_signed_behind_the_receivers_clock_cost_no_write_and_are_refused_after_a_restart(tmp_path):
    """The start-time rule covers them: the state file is written only for frames signed
    ahead of the receiver's clock, of the messages it is asked to persist."""
    state = tmp_path / "k.streams"
    behind = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, clock=Clock(T0 - 0.5))
    frame = behind.pack(inject_cmd())
    ahead = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, link_id=1, clock=Clock(T0 + 5))
    run_a = vehicle(Clock(T0 - 1), state_path=state, persist_msgids={mav.MAVLINK_MSG_ID_COMMAND_LONG})
    run_a.verifier.clock = Clock(T0)                                  # the flight goes on
    assert len(run_a.receive(frame)) == 1 and not state.exists()
    assert len(run_a.receive(ahead.pack(heartbeat()))) == 1 and not state.exists()     # not a command
    run_b = vehicle(Clock(T0 + 1), state_path=state)
    assert run_b.receive(frame) == [] and run_b.counts[Reject.STALE_TIMESTAMP] == 1


def test_an_unreadable_stream_state_is_reported_and_the_start_time_rule_still_holds(tmp_path, caplog):
    state = tmp_path / "k.streams"
    state.write_text("{not json")
    with caplog.at_level(logging.WARNING):
        veh = vehicle(Clock(T0), state_path=state)
    assert "unreadable" in caplog.text
    old = Signer(KEY, system_id=GCS_SYS, component_id=GCS_COMP, clock=Clock(T0 - 1))
    assert veh.receive(old.pack(inject_cmd())) == [] and veh.counts[Reject.STALE_TIMESTAMP] == 1
