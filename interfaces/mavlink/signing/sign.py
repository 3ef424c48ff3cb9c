"""The sending side of MAVLink 2 signing: the signing timestamp and the ``Signer``, which
packs dialect messages as signed frames (https://mavlink.io/en/guide/message_signing.html)."""
from __future__ import annotations

import hashlib
import struct
import time
from collections.abc import Callable

from ..generated import ellipsled as dialect
from .keys import SigningKey

EPOCH_2015_UNIX_S = 1420070400          # 2015-01-01T00:00:00Z, the signing epoch
TICKS_PER_S = 100_000                   # signing timestamp unit: 10 us
TIMESTAMP_MAX = (1 << 48) - 1
_HEADER_V2 = struct.Struct("<BBBBBBBHB")        # magic, len, incompat, compat, seq, sysid, compid, msgid (24 bits)
_LINK_STAMP = struct.Struct("<BQ")             # link id, timestamp: its first 7 bytes
_IFLAG_SIGNED = 0x01


def signing_timestamp(unix_s: float) -> int:
    """Unix time [s] -> MAVLink signing timestamp [10 us since 2015-01-01], clamped to 48 bits."""
    return min(max(int((unix_s - EPOCH_2015_UNIX_S) * TICKS_PER_S), 0), TIMESTAMP_MAX)


class Signer:
    """Packs dialect messages as signed MAVLink 2 frames from one (system, component, link).

    Timestamps follow the local clock and strictly increase even if the clock stalls or
    steps back (each frame takes max(now, last + 1)).
    """

    def __init__(self, key: SigningKey, *, system_id: int, component_id: int,
                 link_id: int = 0, clock: Callable[[], float] = time.time):
        for name, v in (("system_id", system_id), ("component_id", component_id),
                        ("link_id", link_id)):
            if not (isinstance(v, int) and 0 <= v <= 255):
                raise ValueError(f"{name} must be an integer 0..255, got {v!r}")
        self.clock = clock
        self._mav = dialect.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self._mav.signing.secret_key = key.secret
        self._mav.signing.link_id = link_id
        self._mav.signing.sign_outgoing = True
        self._mav.signing.timestamp = 0

    @property
    def system_id(self) -> int:
        return self._mav.srcSystem

    @property
    def component_id(self) -> int:
        return self._mav.srcComponent

    @property
    def link_id(self) -> int:
        return self._mav.signing.link_id

    @property
    def seq(self) -> int:
        """Sequence number of the next frame (0..255)."""
        return self._mav.seq

    @seq.setter
    def seq(self, value: int) -> None:
        self._mav.seq = int(value) % 256

    @property
    def last_timestamp(self) -> int:
        """Timestamp the next frame will at least carry, minus one."""
        return self._mav.signing.timestamp - 1

    def pack(self, msg: dialect.MAVLink_message, *, signed: bool = True) -> bytes:
        """Encode ``msg`` (from the ``dialect`` module) as one frame; the sequence number
        is shared by signed and unsigned frames. The frame is pymavlink's to the byte (its
        payload encoding, zero truncation, CRC and signature: tests/test_mavlink_signing.py),
        framed here in a few calls instead of its generic per-message path, which a link
        sending tens of frames a tick pays on every one (docs/changelog.md, Benchmarks)."""
        mav = self._mav
        payload = payload_of(msg)
        body = payload.rstrip(b"\0") or payload[:1]          # MAVLink 2 drops trailing zeros, keeps 1 byte
        msgid = msg._header.msgId                            # (an "id" field may shadow the class id)
        iflags = _IFLAG_SIGNED if signed else 0
        frame = _HEADER_V2.pack(0xFD, len(body), iflags, 0, mav.seq, mav.srcSystem, mav.srcComponent,
                                msgid & 0xFFFF, msgid >> 16) + body
        crc = dialect.x25crc(frame[1:])
        crc.accumulate(bytes((msg.crc_extra,)))
        frame += crc.crc.to_bytes(2, "little")
        if signed:
            sg = mav.signing
            stamp = max(sg.timestamp, signing_timestamp(self.clock()))
            frame += _LINK_STAMP.pack(sg.link_id, stamp)[:7]
            frame += hashlib.sha256(sg.secret_key + frame).digest()[:6]
            sg.timestamp = stamp + 1
        # what pymavlink's packing leaves on the message (its header, CRC and frame: a sent
        # message compares equal to the same message received)
        msg._header = dialect.MAVLink_header(msgid, iflags, 0, len(body), mav.seq, mav.srcSystem, mav.srcComponent)
        msg._payload, msg._crc, msg._msgbuf = body, crc.crc, bytearray(frame)
        mav.seq = (mav.seq + 1) % 256
        return frame


def _payload_only(mav, crc_extra: int, payload: bytes, force_mavlink1: bool = False) -> bytes:
    return payload


def payload_of(msg: dialect.MAVLink_message) -> bytes:
    """``msg``'s encoded payload, untruncated, by its own generated ``pack``: every message
    class's pack encodes its fields and hands the payload to ``self._pack``, which this
    instance's attribute replaces for the call."""
    msg._pack = _payload_only
    try:
        return msg.pack(None)
    finally:
        del msg._pack
