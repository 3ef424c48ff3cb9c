"""Telemetry log (.tlog): every MAVLink frame the ground station sends or receives, as
an 8-byte big-endian Unix timestamp [us] followed by the raw frame, one record per frame
(docs/interfaces/index.md, "Telemetry log"). This is the layout pymavlink's ``mavutil``
(``mavlink_connection(path)``) and ``mavlogdump.py`` read. pymavlink's own
``setup_logfile`` writes nothing on UDP links, so records are written here directly and
flushed after each one (a crash loses at most the frame being written).
"""
from __future__ import annotations

import os
import struct
import time
from collections.abc import Iterator
from pathlib import Path

_TS = struct.Struct(">Q")


class TlogWriter:
    """Append-only .tlog writer. ``write(frame)`` stamps with ``clock()`` (Unix seconds)."""

    def __init__(self, path: str | os.PathLike[str], *, clock=time.time, append: bool = False):
        self.path = Path(path)
        self.clock = clock
        try:
            self._f = open(self.path, "ab" if append else "wb", buffering=0)
        except OSError as e:
            raise OSError(f"tlog {self.path}: cannot open for writing: {e.strerror or e}") from None
        self.records = 0
        self.bytes = 0

    def write(self, frame: bytes | bytearray | memoryview, t_unix_s: float | None = None) -> None:
        t = self.clock() if t_unix_s is None else t_unix_s
        rec = _TS.pack(max(0, int(round(t * 1e6)))) + bytes(frame)
        self._f.write(rec)                  # unbuffered: on disk (page cache) immediately
        self.records += 1
        self.bytes += len(rec)

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()

    @property
    def closed(self) -> bool:
        return self._f.closed

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_records(path: str | os.PathLike[str]) -> Iterator[tuple[int, bytes]]:
    """(t_us, frame) records of a .tlog written by TlogWriter (frame length from its
    MAVLink header); stops at a truncated tail. For quick checks; pymavlink reads it too."""
    from interfaces.mavlink.framing import parse_header
    data = Path(path).read_bytes()
    i, n = 0, len(data)
    while i + 8 < n:
        (t_us,) = _TS.unpack_from(data, i)
        hdr = parse_header(data, i + 8)
        if hdr is None or i + 8 + hdr.frame_len > n:
            return
        yield t_us, data[i + 8:i + 8 + hdr.frame_len]
        i += 8 + hdr.frame_len
