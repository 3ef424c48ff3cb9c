"""Read-only MAVLink FTP (https://mavlink.io/en/services/ftp.html) over a fixed table of
in-memory files: what the vehicle serves is its component metadata (metadata.py).

Implemented: ResetSessions, TerminateSession, ListDirectory, OpenFileRO, ReadFile,
BurstReadFile, CalcFileCRC32. Every write operation is refused (NAK FileProtected); any
other opcode NAK UnknownCommand. A request that is malformed (a bad session, a size over
the payload, an offset past the end) gets a NAK, never an exception.

Sessions belong to the client that opened them (``handle(..., client=...)``: the link passes
the sender's address): another client's read or terminate of it is NAK InvalidSession, so
a client without the signing key can read (policy.py) without disturbing anyone's session.
When all ``max_sessions`` are open, an open is NAK NoSessionsAvailable (a keyed ground
station's ResetSessions, signed only, closes them all).

Bounds: at most ``max_sessions`` open files; a burst is at most ``burst_packets`` replies
(the last carries burst_complete and the client asks for the next burst), and the link
caps the FTP replies of one tick.
"""
from __future__ import annotations

import struct
from collections import OrderedDict

from .metadata import crc32

PAYLOAD_LEN = 251                      # FILE_TRANSFER_PROTOCOL.payload
HEADER = struct.Struct("<HBBBBBBI")    # seq, session, opcode, size, req_opcode, burst_complete, padding, offset
DATA_MAX = PAYLOAD_LEN - HEADER.size   # 239

# opcodes
NONE, TERMINATE, RESET, LIST, OPEN_RO, READ, CREATE, WRITE, REMOVE, MKDIR, RMDIR, OPEN_WO, TRUNCATE, RENAME, \
    CRC32, BURST = range(16)
ACK, NAK = 128, 129
WRITE_OPS = frozenset({CREATE, WRITE, REMOVE, MKDIR, RMDIR, OPEN_WO, TRUNCATE, RENAME})
# NAK error codes
FAIL, FAIL_ERRNO, INVALID_DATA_SIZE, INVALID_SESSION, NO_SESSIONS, EOF, UNKNOWN_COMMAND, FILE_EXISTS, \
    FILE_PROTECTED, FILE_NOT_FOUND = range(1, 11)


def _norm(path: str) -> str:
    return path.strip("\0").strip().strip("/")


class FtpServer:
    def __init__(self, files: dict[str, bytes], *, max_sessions: int = 4, burst_packets: int = 16):
        self.files = {_norm(p): bytes(b) for p, b in files.items()}
        self.dirs: dict[str, list[str]] = {}
        for p in self.files:                      # each directory's entries, in name order
            parts = p.split("/")
            for i in range(len(parts)):
                parent, name = "/".join(parts[:i]), parts[i]
                entry = ("F" if i == len(parts) - 1 else "D") + name
                lst = self.dirs.setdefault(parent, [])
                if entry not in lst:
                    lst.append(entry)
        for lst in self.dirs.values():
            lst.sort()
        self.max_sessions = int(max_sessions)
        self.burst_packets = int(burst_packets)
        self.sessions: OrderedDict[int, tuple[str, object]] = OrderedDict()  # id -> (path, client)
        self.stats = {"requests": 0, "naks": 0, "bytes_read": 0}

    # ------------------------------------------------------------------ replies
    def _reply(self, seq, session, opcode, req_opcode, offset, data=b"", burst_complete=0) -> bytes:
        head = HEADER.pack((seq + 1) & 0xFFFF, session, opcode, len(data), req_opcode, burst_complete, 0, offset)
        return (head + data).ljust(PAYLOAD_LEN, b"\0")

    def _nak(self, seq, session, req_opcode, offset, error) -> bytes:
        self.stats["naks"] += 1
        return self._reply(seq, session, NAK, req_opcode, offset, bytes([error]))

    # ------------------------------------------------------------------ requests
    def _session(self, session: int, client) -> str | None:
        """The path of ``client``'s open ``session`` (marked recently used), or None."""
        held = self.sessions.get(session)
        if held is None or held[1] != client:
            return None
        self.sessions.move_to_end(session)
        return held[0]

    def handle(self, payload, max_replies: int | None = None, client=None) -> list[bytes]:
        """Reply payloads (each PAYLOAD_LEN bytes) to one request payload of ``client``; a
        burst is cut to ``max_replies`` (its last reply then says burst complete)."""
        self.stats["requests"] += 1
        raw = bytes(payload)
        if len(raw) < HEADER.size:
            return []                              # not even a header: nothing to answer to
        seq, session, op, size, _, _, _, offset = HEADER.unpack_from(raw)
        if size > DATA_MAX or HEADER.size + size > len(raw):
            return [self._nak(seq, session, op, offset, INVALID_DATA_SIZE)]
        data = raw[HEADER.size:HEADER.size + size]
        if op == NONE:
            return []
        if op == RESET:
            self.sessions.clear()
            return [self._reply(seq, session, ACK, op, 0)]
        if op == TERMINATE:
            if self._session(session, client) is None:
                return [self._nak(seq, session, op, offset, INVALID_SESSION)]
            del self.sessions[session]
            return [self._reply(seq, session, ACK, op, 0)]
        if op == LIST:
            return [self._list(seq, session, offset, data)]
        if op == OPEN_RO:
            return [self._open(seq, session, data, client)]
        if op == CRC32:
            content = self.files.get(_norm(data.decode("utf-8", "replace")))
            if content is None:
                return [self._nak(seq, session, op, 0, FILE_NOT_FOUND)]
            return [self._reply(seq, session, ACK, op, 0, struct.pack("<I", crc32(content)))]
        if op in (READ, BURST):
            return self._read(seq, session, op, offset, size, max_replies, client)
        if op in WRITE_OPS:
            return [self._nak(seq, session, op, offset, FILE_PROTECTED)]
        return [self._nak(seq, session, op, offset, UNKNOWN_COMMAND)]

    def _list(self, seq, session, offset, data) -> bytes:
        entries = self.dirs.get(_norm(data.decode("utf-8", "replace")))
        if entries is None:
            return self._nak(seq, session, LIST, offset, FILE_NOT_FOUND)
        if offset >= len(entries):
            return self._nak(seq, session, LIST, offset, EOF)
        out = bytearray()
        for entry in entries[offset:]:
            path = entry[1:]
            if entry[0] == "F":
                full = "/".join(x for x in (_norm(data.decode("utf-8", "replace")), path) if x)
                entry = f"{entry}\t{len(self.files[full])}"
            b = entry.encode("utf-8") + b"\0"
            if len(out) + len(b) > DATA_MAX:
                break
            out += b
        return self._reply(seq, session, ACK, LIST, offset, bytes(out))

    def _open(self, seq, session, data, client) -> bytes:
        path = _norm(data.decode("utf-8", "replace"))
        if path not in self.files:
            return self._nak(seq, session, OPEN_RO, 0, FILE_NOT_FOUND)
        free = [s for s in range(self.max_sessions) if s not in self.sessions]
        if not free:
            return self._nak(seq, session, OPEN_RO, 0, NO_SESSIONS)
        self.sessions[free[0]] = (path, client)
        return self._reply(seq, free[0], ACK, OPEN_RO, 0, struct.pack("<I", len(self.files[path])))

    def _read(self, seq, session, op, offset, size, max_replies=None, client=None) -> list[bytes]:
        path = self._session(session, client)
        if path is None:
            return [self._nak(seq, session, op, offset, INVALID_SESSION)]
        content = self.files[path]
        if offset >= len(content):
            return [self._nak(seq, session, op, offset, EOF)]
        chunk = max(1, min(size or DATA_MAX, DATA_MAX))
        if op == READ:
            part = content[offset:offset + chunk]
            self.stats["bytes_read"] += len(part)
            return [self._reply(seq, session, ACK, op, offset, part)]
        out = []
        n = max(1, min(self.burst_packets, max_replies if max_replies is not None else self.burst_packets))
        for i in range(n):
            part = content[offset:offset + chunk]
            last = offset + len(part) >= len(content) or i == n - 1
            # burst replies carry advancing sequence numbers (request seq + 1, + 2, ...)
            out.append(self._reply((seq + i) & 0xFFFF, session, ACK, op, offset, part, int(last)))
            self.stats["bytes_read"] += len(part)
            offset += len(part)
            if last:
                break
        return out
