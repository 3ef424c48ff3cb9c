"""interfaces/codec.py: header layout, round trip, every rejection reason, fuzzing."""
from __future__ import annotations

import os
import struct
import zlib

import numpy as np
import pytest

from interfaces import codec as C
from interfaces import keys, records
from interfaces.codec import Codec, SequenceGuard

RNG = np.random.default_rng(20110808)


def random_record(dtype: np.dtype, rng=RNG) -> np.ndarray:
    """A record whose every byte is random, then every float element made finite."""
    rec = records.new(dtype)
    raw = rec.reshape(1).view(np.uint8)
    raw[:] = rng.integers(0, 256, raw.size, dtype=np.uint8)
    for name in dtype.names:
        f = rec[name]
        if f.dtype.kind == "f":
            f[...] = rng.normal(0.0, 1e3, f.shape)
    return rec


def float_offsets(dtype: np.dtype) -> list[tuple[int, int]]:
    """(byte offset, itemsize) of every float element, from dtype.fields (independent walk)."""
    out = []
    for name in dtype.names:
        fdt, off = dtype.fields[name][:2]
        base, shape = (fdt.subdtype if fdt.subdtype else (fdt, ()))
        if base.kind == "f":
            for i in range(int(np.prod(shape))):
                out.append((off + i * base.itemsize, base.itemsize))
    return out


@pytest.mark.parametrize("name", ["SENSORS", "JETS", "FAULT", "EVENT"])
def test_round_trip_is_bit_exact_and_header_fields_are_reported(name):
    enc = Codec.for_schema(name, publisher_id=0xDEADBEEF)
    dec = Codec.for_schema(name)
    for seq in range(1, 30):
        rec = random_record(enc.dtype)
        t_pub = int(RNG.integers(-2**62, 2**62))
        buf = enc.encode(rec, seq, t_pub)
        assert isinstance(buf, bytes) and len(buf) == C.HEADER_SIZE + enc.dtype.itemsize
        got = dec.decode(buf)
        assert got is not None, dec.last_error
        assert got.shape == () and got.dtype == enc.dtype
        assert got.tobytes() == rec.tobytes()
        assert (dec.last_seq, dec.last_t_pub_ns, dec.last_publisher_id) == (seq, t_pub, 0xDEADBEEF)
    assert dec.rejected() == 0 and dec.decoded == 29


def test_header_matches_the_documented_layout_byte_for_byte():
    enc = Codec.for_schema("JETS", publisher_id=0x01020304)
    rec = random_record(records.JETS)
    buf = enc.encode(rec, 0x1122334455667788, -5)
    payload = rec.tobytes()
    # independent construction from the table in the module docstring
    head = (b"EL" + (2).to_bytes(2, "little") + (2).to_bytes(2, "little") + b"\0\0"
            + (0x01020304).to_bytes(4, "little") + len(payload).to_bytes(4, "little")
            + (0x1122334455667788).to_bytes(8, "little") + (-5).to_bytes(8, "little", signed=True)
            + C.layout_id(records.JETS).to_bytes(4, "little"))
    crc = zlib.crc32(head + payload)
    assert buf == head + crc.to_bytes(4, "little") + payload


def test_decoded_view_is_read_only_and_out_gets_a_copy():
    enc, dec = Codec.for_schema("SENSORS"), Codec.for_schema("SENSORS", guard=False)
    rec = random_record(records.SENSORS)
    buf = enc.encode(rec, 1, 0)
    got = dec.decode(buf)
    with pytest.raises(ValueError):
        got["omega_BN_B"][0] = 1.0
    out = records.new(records.SENSORS)
    assert dec.decode(buf, out=out) is out and out.tobytes() == rec.tobytes()
    # the encoder's buffer is reused: an earlier result of encode() stays intact
    enc.encode(random_record(records.SENSORS), 2, 0)
    assert dec.decode(buf).tobytes() == rec.tobytes()


def _frame(name="SENSORS", seq=1, **kw):
    enc = Codec.for_schema(name, **kw)
    return enc, bytearray(enc.encode(random_record(enc.dtype), seq, 123))


def _fix_crc(b: bytearray) -> bytearray:
    struct.pack_into("<I", b, 36, zlib.crc32(bytes(b[:36]) + bytes(b[40:])))
    return b


@pytest.mark.parametrize("mutate, reason", [
    (lambda b: b[:-1], "size"),
    (lambda b: b + b"\0", "size"),
    (lambda b: b[:10], "size"),
    (lambda b: _fix_crc(bytearray(b"XL") + b[2:]), "magic"),
    (lambda b: _fix_crc(b[:2] + (2).to_bytes(2, "little") + b[4:]), "schema"),
    (lambda b: _fix_crc(b[:4] + (0x7FFF).to_bytes(2, "little") + b[6:]), "version"),
    (lambda b: _fix_crc(b[:6] + (1).to_bytes(2, "little") + b[8:]), "flags"),
    (lambda b: _fix_crc(b[:12] + (8).to_bytes(4, "little") + b[16:]), "size"),
    (lambda b: _fix_crc(b[:32] + (12345).to_bytes(4, "little") + b[36:]), "layout"),
    (lambda b: b[:-1] + bytes([b[-1] ^ 0x10]), "crc"),
    (lambda b: b[:20] + bytes([b[20] ^ 0x01]) + b[21:], "crc"),
])
def test_each_malformation_is_rejected_with_its_reason(mutate, reason):
    _, good = _frame()
    dec = Codec.for_schema("SENSORS")
    events = []
    dec.on_reject = lambda r, detail: events.append((r, detail))
    assert dec.decode(bytes(mutate(bytearray(good)))) is None
    assert dec.rejects[reason] == 1 and dec.rejected() == 1
    assert dec.last_error.startswith(reason) and events[0][0] == reason
    # the receiver carries on: the genuine frame still decodes
    assert dec.decode(bytes(good)) is not None


def test_every_float_element_is_checked_for_nan_and_inf_and_integers_are_not():
    enc = Codec.for_schema("SENSORS")
    dec = Codec.for_schema("SENSORS", guard=False)
    offsets = float_offsets(records.SENSORS)
    assert len(offsets) == 15 + 18
    rec = random_record(records.SENSORS)
    raw = rec.reshape(1).view(np.uint8)
    n = 0
    for off, size in offsets:
        for bad in (np.nan, np.inf, -np.inf):
            r = rec.copy()
            r.reshape(1).view(np.uint8)[off:off + 8] = np.frombuffer(np.float64(bad).tobytes(), np.uint8)
            assert dec.decode(enc.encode(r, 1, 0)) is None
            n += 1
    assert dec.rejects["non_finite"] == n
    # integer fields holding NaN bit patterns are integers, not floats: accepted
    r = rec.copy()
    r["k"] = np.frombuffer(np.float64(np.nan).tobytes(), "<i8")[0]
    r["t_ns"] = np.frombuffer(np.float64(np.inf).tobytes(), "<i8")[0]
    assert dec.decode(enc.encode(r, 1, 0)) is not None
    assert raw.size == records.SENSORS.itemsize


@pytest.mark.parametrize("dtype", [
    # unaligned float64 and float32 (byte gather path)
    np.dtype([("a", "u1"), ("x", "<f8", (3,)), ("b", "u1"), ("y", "<f4", (2,))]),
    # aligned but non-contiguous float64 (index gather path), big-endian floats, complex
    np.dtype([("x", "<f8"), ("i", "<i8"), ("y", "<f8", (2,)), ("z", ">f8"), ("c", "<c16")]),
])
def test_non_finite_check_covers_unaligned_and_scattered_layouts(dtype):
    enc = Codec(dtype, 99, 1)
    dec = Codec(dtype, 99, 1, guard=False)
    rec = records.new(dtype)
    assert dec.decode(enc.encode(rec, 1, 0)) is not None
    # enumerate every float scalar slot (complex = two float64 halves) via the names
    slots = []
    for name in dtype.names:
        fdt = dtype.fields[name][0]
        base, shape = fdt.subdtype if fdt.subdtype else (fdt, ())
        for i in range(int(np.prod(shape))):
            if base.kind == "f":
                slots.append((name, i, None))
            elif base.kind == "c":
                slots += [(name, i, "real"), (name, i, "imag")]
    assert len(slots) == (5 if "a" in dtype.names else 6)
    for name, i, part in slots:
        r = rec.copy()
        fld = r[name].reshape(-1)
        if part is None:
            fld[i] = np.inf
        elif part == "real":
            fld[i] = complex(np.nan, 0.0)
        else:
            fld[i] = complex(0.0, np.inf)
        r[name] = fld.reshape(r[name].shape)
        assert dec.decode(enc.encode(r, 1, 0)) is None, (name, i, part)
    assert dec.rejects["non_finite"] == len(slots)


def test_fuzz_random_bytes_truncations_and_corruptions_never_raise_never_pass():
    rng = np.random.default_rng(7)
    dec = Codec.for_schema("SENSORS", guard=False)
    enc = Codec.for_schema("SENSORS")
    good = enc.encode(random_record(records.SENSORS, rng), 1, 0)
    # random junk of every plausible length, including the exact frame size
    for _ in range(3000):
        n = int(rng.choice([0, 1, 39, 40, 41, len(good), len(good) + 1, rng.integers(0, 700)]))
        junk = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert dec.decode(junk) is None
    # junk behind a valid header prefix (passes magic/schema/version checks)
    for _ in range(500):
        junk = good[:36] + rng.integers(0, 256, len(good) - 36, dtype=np.uint8).tobytes()
        assert dec.decode(junk) is None
    for n in range(len(good)):
        assert dec.decode(good[:n]) is None
    # every single-byte corruption anywhere: CRC-32 catches all of them (or an earlier check)
    for pos in range(len(good)):
        b = bytearray(good)
        b[pos] ^= int(rng.integers(1, 256))
        assert dec.decode(bytes(b)) is None, pos
    # not bytes at all
    for obj in (None, 3, 2.5, "text", [1, 2], object(), np.zeros((3, 3)), np.zeros(5, ">f8")):
        assert dec.decode(obj) is None
    assert dec.rejects["internal"] == 0
    assert dec.decode(good) is not None
    assert dec.decode(bytearray(good)) is not None and dec.decode(memoryview(good)) is not None


def test_sequence_guard_rejects_replay_and_out_of_order_and_counts_gaps():
    enc = Codec.for_schema("JETS", publisher_id=11)
    dec = Codec.for_schema("JETS")
    rec = random_record(records.JETS)
    frames = {s: enc.encode(rec, s, s) for s in (1, 2, 3, 7, 8)}
    assert dec.decode(frames[1]) is not None
    assert dec.decode(frames[2]) is not None
    assert dec.decode(frames[2]) is None                       # replay
    assert dec.decode(frames[1]) is None                       # step back
    assert dec.rejects["replay_or_out_of_order"] == 2
    assert dec.decode(frames[7]) is not None and dec.guard.lost == 4     # 3..6 never seen
    assert dec.decode(frames[3]) is None                       # late arrival
    # a rejected (corrupted) frame with a huge seq does not advance the guard
    big = bytearray(enc.encode(rec, 10**9, 0))
    big[-1] ^= 1
    assert dec.decode(bytes(big)) is None and dec.rejects["crc"] == 1
    assert dec.decode(frames[8]) is not None
    assert dec.guard.accepted == 4 and dec.guard.out_of_order == 3


def test_second_publisher_is_detected_and_a_restart_is_accepted():
    rec = random_record(records.SENSORS)
    a, b = Codec.for_schema("SENSORS", publisher_id=0xA), Codec.for_schema("SENSORS", publisher_id=0xB)
    dec = Codec.for_schema("SENSORS")
    assert dec.decode(a.encode(rec, 1, 0)) is not None
    assert dec.decode(a.encode(rec, 2, 0)) is not None
    # publisher restarts (new id, sequence from 0): taken over, counted
    assert dec.decode(b.encode(rec, 0, 0)) is not None
    assert dec.guard.publisher_changes == 1 and dec.guard.publisher_id == 0xB
    # the old one is still alive: two publishers on one topic
    assert dec.decode(a.encode(rec, 3, 0)) is None
    assert dec.rejects["second_publisher"] == 1 and "0x0000000a" in dec.last_error
    assert dec.decode(b.encode(rec, 1, 0)) is not None

    strict = Codec.for_schema("SENSORS", guard=SequenceGuard(takeover=False))
    assert strict.decode(a.encode(rec, 1, 0)) is not None
    assert strict.decode(b.encode(rec, 5, 0)) is None
    assert strict.rejects["second_publisher"] == 1


def test_publisher_id_is_random_per_process_and_differs_after_fork():
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.write(w, C.PUBLISHER_ID.to_bytes(4, "little"))
        os._exit(0)
    os.waitpid(pid, 0)
    child = int.from_bytes(os.read(r, 4), "little")
    os.close(r), os.close(w)
    assert child != C.PUBLISHER_ID and child != 0 and C.PUBLISHER_ID != 0


def test_a_raising_reject_callback_does_not_take_the_receiver_down():
    def boom(reason, detail):
        raise RuntimeError("reporting failed")
    dec = Codec.for_schema("SENSORS", on_reject=boom)
    assert dec.decode(b"short") is None
    assert dec.callback_errors == 1 and dec.rejects["size"] == 1


def test_encode_refuses_a_record_of_another_type():
    enc = Codec.for_schema("SENSORS")
    with pytest.raises(TypeError):
        enc.encode(records.new(records.JETS), 1, 0)
    with pytest.raises(ValueError):
        enc.encode(records.new(records.SENSORS), -1, 0)


def test_registry_is_unique_and_adding_a_schema_is_one_call():
    ids = [s.schema_id for s in C.REGISTRY.values()]
    assert len(ids) == len(set(ids))
    assert {s.key_suffix for s in C.REGISTRY.values()} <= {
        keys.SENSORS, keys.JETS, keys.FAULTS, keys.FAULT_LOG, keys.TRUTH, keys.STATE, keys.EVENTS}
    with pytest.raises(ValueError):
        C.register("SENSORS", 77, records.SENSORS, 1, "x/y")
    with pytest.raises(ValueError):
        C.register("OTHER", 1, records.SENSORS, 1, "x/y")
    with pytest.raises(ValueError):
        Codec.for_schema("NOPE")
    dt = np.dtype([("t_ns", "<i8"), ("x", "<f8")])
    try:
        s = C.register("TEST_ONLY", 900, dt, 3, "test/only")
        enc, dec = Codec.for_schema("TEST_ONLY"), Codec.for_schema("TEST_ONLY")
        assert (enc.schema_id, enc.version) == (900, 3) and C.schema_by_id(900) is s
        assert dec.decode(enc.encode(records.new(dt), 1, 0)) is not None
        # a frame of one schema is refused by another schema's decoder
        assert Codec.for_schema("SENSORS").decode(enc.encode(records.new(dt), 1, 0)) is None
    finally:
        C.REGISTRY.pop("TEST_ONLY", None)


def test_event_record_round_trip_and_truncation():
    enc, dec = Codec.for_schema("EVENT"), Codec.for_schema("EVENT")
    text = "jet 7 failed off — déclaré après 3 échantillons consécutifs"   # > 50 bytes UTF-8
    rec = C.event_record(5_000_000_000, 2, "fdir", "jet_failed_off", text)
    got = dec.decode(enc.encode(rec, 1, 0))
    assert got is not None and int(got["severity"]) == 2 and int(got["t_ns"]) == 5_000_000_000
    assert C.record_text(got["source"]) == "fdir" and C.record_text(got["code"]) == "jet_failed_off"
    back = C.record_text(got["text"])
    assert len(text.encode()) > 50 and text.startswith(back.rstrip("\ufffd")) and len(back) > 40


def test_takeover_after_silence_keeps_the_owner_against_a_stray_publisher():
    """A second publisher is refused while the owner is live, and takes over only after the
    owner has been silent for takeover_after_s (a restart)."""
    from interfaces.codec import SequenceGuard
    t = [0]
    g = SequenceGuard(takeover_after_s=1.0, now_ns=lambda: t[0])
    assert g.check(0xA, 0) is None
    t[0] += 10_000_000
    assert g.check(0xB, 0) == "second_publisher"          # owner live: intruder refused
    assert g.check(0xA, 1) is None                          # owner still accepted
    t[0] += 2_000_000_000
    assert g.check(0xB, 5) is None                          # owner silent 2 s: restart takes over
    assert g.publisher_id == 0xB and g.publisher_changes == 1
    assert g.check(0xA, 2) == "second_publisher"          # the old owner is now retired
