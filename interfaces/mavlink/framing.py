"""MAVLink frame layout and a robust splitter for UDP datagrams and byte streams.

Layout (MAVLink 2; https://mavlink.io/en/guide/serialization.html):

    0xFD len incompat compat seq sysid compid msgid[3, little endian] payload[len] crc[2]
         [signature block, if incompat & 0x01: link_id(1) timestamp(6, LE, 10 us) sig(6)]

MAVLink 1: ``0xFE len seq sysid compid msgid payload[len] crc[2]`` (never signed).
The CRC is CRC-16/MCRF4XX over everything after the magic byte up to the payload end,
followed by the message's ``crc_extra`` byte; a frame whose message id is not in the
``crc_extra`` table cannot be checked and is treated as not a frame.

The splitter never raises on any input: bytes that are not part of a frame with a good
CRC are skipped one at a time (so a false magic byte cannot swallow a real frame that
follows it) and counted.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple

from .generated import ellipsled as _dialect

MAGIC_V2 = 0xFD
MAGIC_V1 = 0xFE
HEADER_LEN_V2 = 10
HEADER_LEN_V1 = 6
CRC_LEN = 2
SIGNATURE_LEN = 13              # link_id(1) + timestamp(6) + signature(6)
IFLAG_SIGNED = 0x01
MAX_FRAME_LEN = HEADER_LEN_V2 + 255 + CRC_LEN + SIGNATURE_LEN     # 280 bytes

_x25crc = _dialect.x25crc


def crc_extra_table() -> dict[int, int]:
    """msgid -> crc_extra for every message of the ellipsled dialect (incl. common)."""
    return {msgid: cls.crc_extra for msgid, cls in _dialect.mavlink_map.items()}


def _escaped(c: str) -> str:
    if " " <= c <= "~" and c != "\\":
        return c
    if c == "\\":
        return "\\\\"
    return f"\\x{ord(c):02x}" if ord(c) < 0x100 else f"\\u{ord(c):04x}"


def printable_text(raw) -> str:
    """A text field from the link (bytes or str) as it may be shown or logged: trailing
    NULs dropped, every character outside printable ASCII (control characters, escape
    sequences, other bytes) and the backslash written as an escape (``\\x1b``, ``\\\\``),
    so what a sender puts in a field cannot act on a terminal."""
    s = (raw.decode("latin-1") if isinstance(raw, (bytes, bytearray)) else str(raw)).rstrip("\x00")
    if s.isascii() and s.isprintable() and "\\" not in s:
        return s
    return "".join(_escaped(c) for c in s)


class FrameHeader(NamedTuple):
    version: int        # 1 or 2
    payload_len: int
    incompat_flags: int
    seq: int
    sysid: int
    compid: int
    msgid: int
    header_len: int
    frame_len: int      # total bytes including CRC and signature block

    @property
    def signed(self) -> bool:
        return bool(self.incompat_flags & IFLAG_SIGNED)


def parse_header(buf: bytes | bytearray | memoryview, i: int = 0) -> FrameHeader | None:
    """Header of the frame starting at ``buf[i]``, or None if there are too few bytes
    for a header or ``buf[i]`` is not a magic byte. Does not check that the whole frame
    is present."""
    n = len(buf)
    if i >= n:
        return None
    magic = buf[i]
    if magic == MAGIC_V2:
        if n - i < HEADER_LEN_V2:
            return None
        plen, iflags = buf[i + 1], buf[i + 2]
        msgid = buf[i + 7] | (buf[i + 8] << 8) | (buf[i + 9] << 16)
        total = HEADER_LEN_V2 + plen + CRC_LEN + (SIGNATURE_LEN if iflags & IFLAG_SIGNED else 0)
        return FrameHeader(2, plen, iflags, buf[i + 4], buf[i + 5], buf[i + 6], msgid,
                           HEADER_LEN_V2, total)
    if magic == MAGIC_V1:
        if n - i < HEADER_LEN_V1:
            return None
        plen = buf[i + 1]
        return FrameHeader(1, plen, 0, buf[i + 2], buf[i + 3], buf[i + 4], buf[i + 5],
                           HEADER_LEN_V1, HEADER_LEN_V1 + plen + CRC_LEN)
    return None


def crc_ok(frame: bytes | bytearray, hdr: FrameHeader, crc_extra: int) -> bool:
    end = hdr.header_len + hdr.payload_len
    crc = _x25crc(bytes(frame[1:end]))
    crc.accumulate(bytes((crc_extra,)))
    return crc.crc == (frame[end] | (frame[end + 1] << 8))


@dataclass
class SplitStats:
    """Counts of what the splitter threw away (cumulative)."""
    frames: int = 0
    garbage_bytes: int = 0      # bytes not belonging to any good frame
    bad_crc: int = 0            # complete candidate frames whose CRC did not match
    unknown_msgid: int = 0      # candidate frames whose message id is not in the table
    truncated: int = 0          # datagrams ending in an incomplete candidate frame

    def as_dict(self) -> dict[str, int]:
        return dict(self.__dict__)


@dataclass
class FrameSplitter:
    """Extract MAVLink 1 and 2 frames from UDP datagrams (``split_datagram``) or from a
    byte stream (``feed``: keeps an incomplete tail, at most one frame long).

    ``crc_extra`` maps msgid -> crc_extra (default: the ellipsled dialect).
    """
    crc_extra: Mapping[int, int] = field(default_factory=crc_extra_table)
    stats: SplitStats = field(default_factory=SplitStats)
    _tail: bytearray = field(default_factory=bytearray, repr=False)

    def split_datagram(self, data: bytes | bytearray | memoryview) -> list[bytes]:
        """All good frames in one datagram; an incomplete frame at the end is dropped."""
        frames, _ = self._scan(bytes(data), final=True)
        return frames

    def feed(self, data: bytes | bytearray | memoryview) -> list[bytes]:
        """Append stream bytes and return the frames completed by them."""
        self._tail += data
        frames, consumed = self._scan(bytes(self._tail), final=False)
        del self._tail[:consumed]
        return frames

    def _scan(self, buf: bytes, final: bool) -> tuple[list[bytes], int]:
        frames: list[bytes] = []
        st = self.stats
        n = len(buf)
        i = 0
        truncated = False
        while i < n:
            b = buf[i]
            if b != MAGIC_V2 and b != MAGIC_V1:
                j2, j1 = buf.find(b"\xfd", i), buf.find(b"\xfe", i)
                j = min(x for x in (j2, j1, n) if x >= 0)
                st.garbage_bytes += j - i
                i = j
                continue
            hdr = parse_header(buf, i)
            if hdr is None or n - i < hdr.frame_len:
                if not final:
                    # A false magic byte claiming a long frame must not hold back good
                    # frames already received after it: if one is complete, resync there.
                    j = self._next_good_frame(buf, i + 1)
                    if j is None:
                        break               # wait for the rest of the frame
                    st.garbage_bytes += j - i
                    i = j
                    continue
                truncated = True
                st.garbage_bytes += 1
                i += 1
                continue
            extra = self.crc_extra.get(hdr.msgid)
            frame = buf[i:i + hdr.frame_len]
            if extra is None:
                st.unknown_msgid += 1
            elif not crc_ok(frame, hdr, extra):
                st.bad_crc += 1
            else:
                frames.append(frame)
                st.frames += 1
                i += hdr.frame_len
                continue
            st.garbage_bytes += 1           # resynchronise one byte later
            i += 1
        if truncated:
            st.truncated += 1
        return frames, i

    def _good_at(self, buf: bytes, i: int) -> FrameHeader | None:
        hdr = parse_header(buf, i)
        if hdr is None or len(buf) - i < hdr.frame_len:
            return None
        extra = self.crc_extra.get(hdr.msgid)
        if extra is None or not crc_ok(buf[i:i + hdr.frame_len], hdr, extra):
            return None
        return hdr

    def _next_good_frame(self, buf: bytes, start: int) -> int | None:
        """Index of the first complete frame with a good CRC at or after ``start``."""
        n = len(buf)
        i = start
        while i < n:
            j2, j1 = buf.find(b"\xfd", i), buf.find(b"\xfe", i)
            cands = [x for x in (j2, j1) if x >= 0]
            if not cands:
                return None
            j = min(cands)
            if self._good_at(buf, j) is not None:
                return j
            i = j + 1
        return None
