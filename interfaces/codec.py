"""Wire format of every Zenoh payload: a fixed 40-byte header + one fixed-layout record.

Header (little-endian, 40 bytes; the payload starts 8-byte aligned so float64 fields can
be viewed in place):

    off size field        meaning
      0    2 magic        b"EL"
      2    2 schema_id    u16, see REGISTRY
      4    2 version      u16, bumped whenever a record layout changes
      6    2 flags        u16, no flag defined yet: any set bit is rejected
      8    4 publisher_id u32, random per process start (detects a second publisher)
     12    4 payload_len  u32, = dtype.itemsize
     16    8 seq          u64, per publisher and topic, strictly increasing
     24    8 t_pub_ns     i64, publisher's clock at publication [ns]
     32    4 layout       u32, CRC-32 of the dtype description: catches two builds whose
                          layouts differ while the version was not bumped
     36    4 crc32        u32, CRC-32 of bytes [0, 36) and of the payload: catches
                          corruption on transports without their own checksum (0.3 us)

Decoding never raises and never passes a bad value on: it returns ``None`` and counts the
reason in ``Codec.rejects`` (docs/interfaces/index.md, "A decoder rejects wrong size, unknown
version and non-finite numbers, counts the rejection and raises an event"). The process
shell turns rejections into events through the ``on_reject`` callback.
"""
from __future__ import annotations

import os
import secrets
import struct
import time
import zlib
from dataclasses import dataclass
from typing import Callable

import numpy as np

from interfaces import keys, records

MAGIC = b"EL"
HEADER = struct.Struct("<2sHHHIIQqII")
HEADER_SIZE = HEADER.size            # 40
_CRC_SPAN = 36                        # header bytes covered by the CRC (all but the CRC)
assert HEADER_SIZE == 40

REJECT_REASONS = ("type", "size", "magic", "schema", "version", "flags", "layout", "crc",
                  "non_finite", "replay_or_out_of_order", "second_publisher", "internal")


def _new_publisher_id() -> int:
    return secrets.randbits(32) | 1   # never 0


PUBLISHER_ID = _new_publisher_id()


def _regenerate_publisher_id() -> None:
    # A forked child is another publisher: it must not reuse its parent's id.
    global PUBLISHER_ID
    PUBLISHER_ID = _new_publisher_id()


os.register_at_fork(after_in_child=_regenerate_publisher_id)


def layout_id(dtype: np.dtype) -> int:
    """CRC-32 of the dtype's field names, types, shapes and offsets."""
    d = np.dtype(dtype)
    return zlib.crc32(repr((d.descr, d.itemsize)).encode())


# --------------------------------------------------------------------------- registry
@dataclass(frozen=True)
class Schema:
    name: str
    schema_id: int
    dtype: np.dtype
    version: int
    key_suffix: str     # topic under the run prefix (interfaces/keys.py)


REGISTRY: dict[str, Schema] = {}


def register(name: str, schema_id: int, dtype: np.dtype, version: int, key_suffix: str) -> Schema:
    """Add a payload type; names, ids and topics are unique."""
    s = Schema(name, int(schema_id), np.dtype(dtype), int(version), key_suffix)
    if not 0 < s.schema_id < 0x10000 or not 0 < s.version < 0x10000:
        raise ValueError(f"schema {name}: id and version must be in 1..65535")
    for other in REGISTRY.values():
        if name == other.name or s.schema_id == other.schema_id or key_suffix == other.key_suffix:
            raise ValueError(f"schema {name}: name, id or key suffix already used by {other.name}")
    REGISTRY[name] = s
    return s


def schema_by_id(schema_id: int) -> Schema | None:
    for s in REGISTRY.values():
        if s.schema_id == schema_id:
            return s
    return None


# One line per payload type.
register("SENSORS", 1, records.SENSORS, 2, keys.SENSORS)
register("JETS", 2, records.JETS, 2, keys.JETS)
register("FAULT", 3, records.FAULT, 1, keys.FAULTS)
register("EVENT", 4, records.EVENT, 1, keys.EVENTS)
register("TRUTH", 5, records.TRUTH, 1, keys.TRUTH)
register("FSW_STATE", 6, records.FSW_STATE, 4, keys.STATE)
register("FAULT_APPLIED", 7, records.FAULT_APPLIED, 1, keys.FAULT_LOG)


# --------------------------------------------------------------------------- sequence guard
class SequenceGuard:
    """Per-topic receiver check of (publisher id, sequence number).

    - the same publisher: the sequence must strictly increase; a repeat or a step back is
      ``replay_or_out_of_order``; a jump forward is accepted and its gap counted in ``lost``;
    - a new publisher id: with ``takeover=True`` (default: a restarted publisher) it becomes
      the current publisher (``publisher_changes`` += 1) and the old id is retired; a frame
      from a retired id afterwards means two publishers are live on one topic:
      ``second_publisher``, rejected and counted. With ``takeover=False`` only the first
      publisher ever seen is accepted. With ``takeover_after_s`` a new publisher takes over
      only once the current one has been silent that long (a restart); before that it is
      a second publisher — so one stray or hostile frame cannot lock out the owner.
    """

    RETIRED_MAX = 16

    def __init__(self, takeover: bool = True, takeover_after_s: float | None = None,
                 now_ns=time.monotonic_ns):
        self.takeover = takeover
        self.takeover_after_ns = None if takeover_after_s is None else int(takeover_after_s * 1e9)
        self._now_ns = now_ns
        self._last_ns = 0
        self.publisher_id: int | None = None
        self.last_seq = -1
        self.accepted = 0
        self.lost = 0
        self.publisher_changes = 0
        self.second_publisher = 0
        self.out_of_order = 0
        self.last_error = ""
        self._retired: list[int] = []

    def reset(self) -> None:
        self.__init__(self.takeover, None if self.takeover_after_ns is None else self.takeover_after_ns / 1e9,
                      self._now_ns)

    def check(self, publisher_id: int, seq: int) -> str | None:
        """None if the frame is acceptable (and recorded), else the rejection reason."""
        if self.publisher_id is None:
            self.publisher_id = publisher_id
        elif publisher_id != self.publisher_id:
            owner_live = (self.takeover_after_ns is not None
                          and self._now_ns() - self._last_ns < self.takeover_after_ns)
            if not self.takeover or publisher_id in self._retired or owner_live:
                self.second_publisher += 1
                self.last_error = (f"second publisher {publisher_id:#010x} on a topic owned by "
                                   f"{self.publisher_id:#010x}")
                return "second_publisher"
            self._retired.append(self.publisher_id)
            del self._retired[:-self.RETIRED_MAX]
            self.publisher_id = publisher_id
            self.publisher_changes += 1
            self.last_seq = -1
        elif seq <= self.last_seq:
            self.out_of_order += 1
            self.last_error = f"seq {seq} after {self.last_seq} (replayed or out of order)"
            return "replay_or_out_of_order"
        if self.last_seq >= 0:
            self.lost += seq - self.last_seq - 1
        self.last_seq = seq
        self.accepted += 1
        if self.takeover_after_ns is not None:
            self._last_ns = self._now_ns()
        return None


# --------------------------------------------------------------------------- codec
def _float_layout(dtype: np.dtype, base: int = 0) -> list[tuple[np.dtype, int]]:
    """(scalar float dtype, byte offset) of every floating-point element of ``dtype``."""
    out: list[tuple[np.dtype, int]] = []
    if dtype.names is not None:
        for name in dtype.names:
            fdt, off = dtype.fields[name][:2]
            out += _float_layout(fdt, base + off)
        return out
    if dtype.subdtype is not None:
        sub, shape = dtype.subdtype
        for i in range(int(np.prod(shape))):
            out += _float_layout(sub, base + i * sub.itemsize)
        return out
    if dtype.kind == "f":
        out.append((dtype, base))
    elif dtype.kind == "c":
        half = np.dtype(f"{dtype.byteorder if dtype.byteorder in '<>' else '='}f{dtype.itemsize // 2}")
        out += [(half, base), (half, base + dtype.itemsize // 2)]
    elif dtype.kind in "OV" or dtype.hasobject:
        raise ValueError(f"codec: field type {dtype} has no fixed binary layout")
    return out


class _FloatCheck:
    """Vectorised non-finite test of every float element of one scalar float type.

    Aligned elements are viewed in place (a slice when they are contiguous, else a
    gather through a precomputed index); unaligned ones are gathered byte-wise into an
    aligned scratch buffer first. Scratch arrays are preallocated.
    """

    def __init__(self, fdt: np.dtype, offsets: list[int], payload_len: int):
        self.fdt = fdt
        size = fdt.itemsize
        offs = np.asarray(offsets, dtype=np.intp)
        self.n = len(offsets)
        self.ok = np.empty(self.n, dtype=bool)
        self.aligned = bool(np.all(offs % size == 0)) and HEADER_SIZE % size == 0
        if self.aligned:
            idx = offs // size
            self.count = payload_len // size
            self.contiguous = bool(np.all(np.diff(idx) == 1))
            self.sl = slice(int(idx[0]), int(idx[-1]) + 1)
            self.idx = idx
            self.scratch = np.empty(self.n, dtype=fdt)
        else:
            self.byte_idx = (offs[:, None] + np.arange(size)[None, :]).ravel()
            self.scratch_u8 = np.empty(self.n * size, dtype=np.uint8)

    def all_finite(self, buf) -> bool:
        if self.aligned:
            v = np.frombuffer(buf, self.fdt, self.count, HEADER_SIZE)
            x = v[self.sl] if self.contiguous else np.take(v, self.idx, out=self.scratch)
        else:
            u8 = np.frombuffer(buf, np.uint8, -1, HEADER_SIZE)
            np.take(u8, self.byte_idx, out=self.scratch_u8)
            x = self.scratch_u8.view(self.fdt)
        np.isfinite(x, out=self.ok)
        return np.count_nonzero(self.ok) == self.n


class Codec:
    """Encoder/decoder of one record type.

    ``encode`` writes header + record into one preallocated buffer and returns it as
    ``bytes``; ``decode`` checks a received buffer completely and returns a read-only 0-d
    record that is a view into it (no copy), or ``None`` with the reason counted in
    ``rejects`` and described in ``last_error``; ``on_reject(reason, detail)`` is called
    for each rejection (the process shell raises a rate-limited event there).
    """

    def __init__(self, dtype: np.dtype, schema_id: int, version: int, *,
                 publisher_id: int | None = None,
                 guard: SequenceGuard | bool = True,
                 on_reject: Callable[[str, str], None] | None = None):
        self.dtype = np.dtype(dtype)
        if self.dtype.names is None:
            raise ValueError("codec: dtype must be a structured record dtype")
        if not 0 <= schema_id < 0x10000 or not 0 <= version < 0x10000:
            raise ValueError("codec: schema_id and version must fit in u16")
        self.schema_id = int(schema_id)
        self.version = int(version)
        self.layout = layout_id(self.dtype)
        self.payload_len = self.dtype.itemsize
        self.size = HEADER_SIZE + self.payload_len
        self._publisher_id = publisher_id
        self.guard = SequenceGuard() if guard is True else (guard or None)
        self.on_reject = on_reject
        self.rejects: dict[str, int] = {r: 0 for r in REJECT_REASONS}
        self.last_error = ""
        self.decoded = 0
        self.callback_errors = 0
        # header fields of the last accepted frame
        self.last_seq = -1
        self.last_t_pub_ns = 0
        self.last_publisher_id = 0

        groups: dict[np.dtype, list[int]] = {}
        for fdt, off in _float_layout(self.dtype):
            groups.setdefault(fdt, []).append(off)
        self._float_checks = [_FloatCheck(fdt, offs, self.payload_len) for fdt, offs in groups.items()]

        self._buf = bytearray(self.size)
        self._mv = memoryview(self._buf)
        self._mv_crc_head = self._mv[:_CRC_SPAN]
        self._mv_payload = self._mv[HEADER_SIZE:]
        self._out = np.frombuffer(self._buf, np.uint8, self.payload_len, HEADER_SIZE) \
            .view(self.dtype).reshape(())

    @classmethod
    def for_schema(cls, name: str, **kwargs) -> "Codec":
        s = REGISTRY.get(name)
        if s is None:
            raise ValueError(f"codec: unknown schema {name!r} (known: {', '.join(REGISTRY)})")
        return cls(s.dtype, s.schema_id, s.version, **kwargs)

    @property
    def publisher_id(self) -> int:
        return self._publisher_id if self._publisher_id is not None else PUBLISHER_ID

    # ----------------------------------------------------------------- encode
    def encode_view(self, rec: np.ndarray, seq: int, t_pub_ns: int) -> memoryview:
        """Encode into the codec's own buffer and return a view of it: valid until the next
        encode. ``rec``: a record of this codec's dtype (0-d array or np.void)."""
        if getattr(rec, "dtype", None) != self.dtype:
            raise TypeError(f"codec {self.schema_id}: record dtype {getattr(rec, 'dtype', type(rec))} "
                            f"is not the codec's dtype")
        if not 0 <= seq < 1 << 64:
            raise ValueError(f"codec: seq {seq} outside u64")
        self._out[()] = rec
        HEADER.pack_into(self._buf, 0, MAGIC, self.schema_id, self.version, 0, self.publisher_id,
                         self.payload_len, seq, t_pub_ns, self.layout, 0)
        crc = zlib.crc32(self._mv_payload, zlib.crc32(self._mv_crc_head))
        struct.pack_into("<I", self._buf, _CRC_SPAN, crc)
        return self._mv

    def encode(self, rec: np.ndarray, seq: int, t_pub_ns: int) -> bytes:
        """Header + record as bytes (one copy of the preallocated buffer)."""
        return bytes(self.encode_view(rec, seq, t_pub_ns))

    # ----------------------------------------------------------------- decode
    def _reject(self, reason: str, detail: str) -> None:
        self.rejects[reason] = self.rejects.get(reason, 0) + 1
        self.last_error = f"{reason}: {detail}"
        if self.on_reject is not None:
            try:
                self.on_reject(reason, detail)
            except Exception:       # the receiver must survive its own reporting
                self.callback_errors += 1

    def decode(self, buf, out: np.ndarray | None = None) -> np.ndarray | None:
        """The record in ``buf`` (bytes-like or zenoh.ZBytes), or None (reason counted).

        Returns a read-only 0-d view into ``buf`` (``buf`` stays referenced), or ``out``
        filled with a copy when a preallocated record is given. Never raises.
        """
        try:
            if type(buf) is not bytes:
                if hasattr(buf, "to_bytes"):
                    buf = buf.to_bytes()
                else:
                    try:
                        mv = memoryview(buf)
                    except TypeError:
                        self._reject("type", f"not a bytes-like object: {type(buf).__name__}")
                        return None
                    if not mv.contiguous:
                        self._reject("type", "non-contiguous buffer")
                        return None
                    buf = mv.cast("B") if mv.format != "B" or mv.ndim != 1 else mv
            n = len(buf)
            if n < HEADER_SIZE:
                self._reject("size", f"{n} bytes, shorter than the {HEADER_SIZE}-byte header")
                return None
            magic, schema_id, version, flags, pub, plen, seq, t_pub, layout, crc = \
                HEADER.unpack_from(buf, 0)
            if magic != MAGIC:
                self._reject("magic", f"magic {bytes(magic)!r}")
                return None
            if schema_id != self.schema_id:
                self._reject("schema", f"schema id {schema_id}, expected {self.schema_id}")
                return None
            if version != self.version:
                self._reject("version", f"version {version}, expected {self.version}")
                return None
            if flags:
                self._reject("flags", f"unknown flags {flags:#06x}")
                return None
            if plen != self.payload_len or n != self.size:
                self._reject("size", f"{n} bytes with payload_len {plen}, expected {self.size} "
                                     f"and {self.payload_len}")
                return None
            if layout != self.layout:
                self._reject("layout", f"layout {layout:#010x}, expected {self.layout:#010x} "
                                       f"(record definitions differ: version not bumped?)")
                return None
            mv = memoryview(buf)
            if zlib.crc32(mv[HEADER_SIZE:], zlib.crc32(mv[:_CRC_SPAN])) != crc:
                self._reject("crc", "checksum mismatch (corrupted frame)")
                return None
            for chk in self._float_checks:
                if not chk.all_finite(buf):
                    self._reject("non_finite", "NaN or Inf in a float field")
                    return None
            if self.guard is not None:
                why = self.guard.check(pub, seq)
                if why is not None:
                    self._reject(why, self.guard.last_error)
                    return None
            rec = np.frombuffer(buf, self.dtype, 1, HEADER_SIZE).reshape(())
            self.last_seq, self.last_t_pub_ns, self.last_publisher_id = seq, t_pub, pub
            self.decoded += 1
            if out is not None:
                out[()] = rec
                return out
            return rec
        except Exception as e:     # defensive: arbitrary input must never take a receiver down
            self._reject("internal", f"{type(e).__name__}: {e}")
            return None

    def rejected(self) -> int:
        return sum(self.rejects.values())


# --------------------------------------------------------------------------- helpers
def event_record(t_ns: int, severity: int, source: str, code: str, text: str,
                 out: np.ndarray | None = None) -> np.ndarray:
    """An EVENT record (common/events.py Event fields); strings UTF-8, truncated to their width."""
    rec = records.new(records.EVENT) if out is None else out
    rec["t_ns"] = t_ns
    rec["severity"] = int(severity)
    for name, s in (("source", source), ("code", code), ("text", text)):
        width = records.EVENT.fields[name][0].itemsize
        rec[name] = s.encode("utf-8", "replace")[:width]
    return rec


def record_text(value: bytes | np.bytes_) -> str:
    """A fixed-width string field back to text (invalid UTF-8 replaced, never raises)."""
    return bytes(value).rstrip(b"\0").decode("utf-8", "replace")
