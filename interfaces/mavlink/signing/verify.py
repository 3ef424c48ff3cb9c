"""The receiving side of MAVLink 2 signing, verify-first: ``SigningVerifier`` judges each
raw frame before pymavlink sees it (``Verdict``), counts and reports what it refuses
(``Reject``, ``Rejection``), and keeps the streams' last timestamps, across restarts with a
state file. The policy: interfaces/mavlink/README.md, "Signing: keys, clocks and replay"."""
from __future__ import annotations

import hashlib
import hmac
import json
import logging
import os
import time
from collections.abc import Callable, Collection
from enum import Enum
from pathlib import Path
from typing import NamedTuple

from .. import framing
from ..generated import ellipsled as dialect
from .keys import SigningKey
from .sign import TICKS_PER_S, TIMESTAMP_MAX, signing_timestamp

log = logging.getLogger(__name__)

ALLOW_UNSIGNED_DEFAULT = frozenset({dialect.MAVLINK_MSG_ID_HEARTBEAT})


class Reject(str, Enum):
    """Why a frame (or some received bytes) was not passed on."""
    MALFORMED = "malformed"                 # length field disagrees with the frame size
    BAD_FLAGS = "bad_flags"                 # unknown MAVLink 2 incompat flag set
    UNSIGNED = "unsigned"                   # unsigned and not in the allowed set
    BAD_SIGNATURE = "bad_signature"         # wrong key, tampered byte, forged frame
    REPLAY = "replay"                       # timestamp not newer than the stream's last
    FUTURE_TIMESTAMP = "future_timestamp"   # > max_future_s ahead of the local clock
    STALE_TIMESTAMP = "stale_timestamp"     # > max_age_s behind the local clock, or before the verifier started
    BAD_CRC = "bad_crc"                     # splitter: complete candidate, CRC mismatch
    UNKNOWN_MESSAGE = "unknown_message"     # splitter: message id not in the dialect
    TRUNCATED = "truncated"                 # splitter: datagram ends inside a frame
    GARBAGE = "garbage"                     # splitter: bytes outside any frame; intake: MAVLink 1
    OWN_SYSTEM = "own_system"               # intake: claims the receiver's own system id
    DECODE_ERROR = "decode_error"           # pymavlink could not decode a verified frame


class Rejection(NamedTuple):
    reason: Reject
    sysid: int = -1
    compid: int = -1
    msgid: int = -1
    link_id: int = -1
    detail: str = ""
    count: int = 1          # alike rejections reported together (the first one's fields)

    def text(self) -> str:
        """One line of at most 50 characters (fits a STATUSTEXT); never contains key data."""
        who = f" {self.sysid}/{self.compid}" if self.sysid >= 0 else ""
        what = f" msg {self.msgid}" if self.msgid >= 0 else ""
        n = f" {self.count}x" if self.count > 1 else ""
        return f"link rejected{n} {self.reason.value}{who}{what}"[:50]


class Verdict(NamedTuple):
    accepted: bool
    reason: Reject | None
    signed: bool
    sysid: int = -1
    compid: int = -1
    msgid: int = -1
    link_id: int = -1
    timestamp: int = -1     # signing timestamp [10 us since 2015], -1 if unsigned


RejectHook = Callable[[Rejection], None]


class SigningVerifier:
    """Checks one raw frame at a time; stream state changes only on a valid signature.

    Order of checks: framing (length, flags) -> signed? -> signature -> timestamp window
    (not after now + max_future_s, not before now - max_age_s nor before the verifier's
    creation) -> strictly newer than the stream's last accepted timestamp -> record (and
    save, with a ``state_path``) -> accept.
    """

    def __init__(self, key: SigningKey, *,
                 allow_unsigned: Collection[int] = ALLOW_UNSIGNED_DEFAULT,
                 max_future_s: float = 60.0, max_age_s: float | None = 60.0,
                 clock: Callable[[], float] = time.time,
                 on_reject: RejectHook | None = None, state_path: str | os.PathLike[str] | None = None,
                 persist_msgids: Collection[int] | None = None):
        if not isinstance(key, SigningKey):
            raise TypeError("key must be a SigningKey")
        if not max_future_s >= 0.0 or (max_age_s is not None and not max_age_s >= 0.0):
            raise ValueError("max_future_s and max_age_s must be >= 0")
        self._secret = key.secret
        self.allow_unsigned = frozenset(int(m) for m in allow_unsigned)
        self.max_future_ticks = int(max_future_s * TICKS_PER_S)
        self.max_age_ticks = None if max_age_s is None else int(max_age_s * TICKS_PER_S)
        self.clock = clock
        self.on_reject = on_reject
        self.counts: dict[Reject, int] = {r: 0 for r in Reject}
        self.accepted_signed = 0
        self.accepted_unsigned = 0
        self.not_before = signing_timestamp(clock())     # nothing signed before this verifier existed
        self.state_path = None if state_path is None else Path(state_path)
        self.persist_msgids = None if persist_msgids is None else frozenset(int(m) for m in persist_msgids)
        self.persist_errors = 0
        self.persisted = 0
        self._streams: dict[tuple[int, int, int], int] = self._load_streams()

    def _load_streams(self) -> dict[tuple[int, int, int], int]:
        """The streams saved at ``state_path`` (empty if none; a bad file is reported and
        ignored: the start-time rule still refuses every earlier frame)."""
        if self.state_path is None:
            return {}
        try:
            raw = json.loads(self.state_path.read_text(encoding="ascii"))
            out = {}
            for k, ts in raw.items():
                sysid, compid, link_id = (int(x) for x in k.split("/"))
                if not (isinstance(ts, int) and 0 <= ts <= TIMESTAMP_MAX
                        and all(0 <= x <= 255 for x in (sysid, compid, link_id))):
                    raise ValueError(k)
                out[(sysid, compid, link_id)] = ts
            return out
        except FileNotFoundError:
            return {}
        except (OSError, ValueError, AttributeError, UnicodeDecodeError) as e:
            log.warning("signing stream state %s unreadable (%s): ignored", self.state_path, type(e).__name__)
            return {}

    def _save_streams(self) -> None:
        """Write every stream's last timestamp to ``state_path`` atomically."""
        p = self.state_path
        tmp = p.with_name(f"{p.name}.{os.getpid()}.tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w", encoding="ascii") as f:
                json.dump({f"{s}/{c}/{lk}": ts for (s, c, lk), ts in self._streams.items()}, f)
            os.replace(tmp, p)
            self.persisted += 1
        except OSError as e:
            self.persist_errors += 1
            if self.persist_errors == 1:
                log.warning("signing stream state %s cannot be written (%s): replay across restarts is "
                            "refused by the start-time rule only", p, e.strerror or e)

    def stream_timestamp(self, sysid: int, compid: int, link_id: int) -> int | None:
        """Last accepted signing timestamp of a stream, or None if none yet."""
        return self._streams.get((sysid, compid, link_id))

    @property
    def rejected(self) -> int:
        return sum(self.counts.values())

    def reject(self, rej: Rejection) -> None:
        """Count a rejection (``rej.count`` alike) and report it to the hook (a failing hook
        is logged, not raised)."""
        self.counts[rej.reason] += rej.count
        if self.on_reject is not None:
            try:
                self.on_reject(rej)
            except Exception:
                log.exception("signing reject hook failed")

    def _no(self, reason: Reject, signed: bool, sysid=-1, compid=-1, msgid=-1, link_id=-1,
            ts=-1, detail: str = "") -> Verdict:
        self.reject(Rejection(reason, sysid, compid, msgid, link_id, detail))
        return Verdict(False, reason, signed, sysid, compid, msgid, link_id, ts)

    def verify(self, frame: bytes | bytearray) -> Verdict:
        """Verdict on one complete raw frame (as produced by ``framing.FrameSplitter``).
        Never raises on any byte string."""
        try:
            hdr = framing.parse_header(frame)
        except TypeError:
            hdr = None
        if hdr is None or len(frame) != hdr.frame_len:
            return self._no(Reject.MALFORMED, False,
                            detail=f"{len(frame) if hasattr(frame, '__len__') else '?'} bytes")
        sysid, compid, msgid = hdr.sysid, hdr.compid, hdr.msgid
        if hdr.incompat_flags & ~framing.IFLAG_SIGNED:
            return self._no(Reject.BAD_FLAGS, False, sysid, compid, msgid,
                            detail=f"incompat_flags=0x{hdr.incompat_flags:02x}")
        if not hdr.signed:
            if msgid in self.allow_unsigned:
                self.accepted_unsigned += 1
                return Verdict(True, None, False, sysid, compid, msgid)
            return self._no(Reject.UNSIGNED, False, sysid, compid, msgid)

        link_id = frame[-13]
        ts = int.from_bytes(frame[-12:-6], "little")
        expected = hashlib.sha256(self._secret + bytes(frame[:-6])).digest()[:6]
        if not hmac.compare_digest(expected, bytes(frame[-6:])):
            return self._no(Reject.BAD_SIGNATURE, True, sysid, compid, msgid, link_id, ts)

        now = signing_timestamp(self.clock())
        if ts > now + self.max_future_ticks:
            return self._no(Reject.FUTURE_TIMESTAMP, True, sysid, compid, msgid, link_id, ts,
                            f"{(ts - now) / TICKS_PER_S:.1f} s ahead")
        if self.max_age_ticks is not None and ts < now - self.max_age_ticks:
            return self._no(Reject.STALE_TIMESTAMP, True, sysid, compid, msgid, link_id, ts,
                            f"{(now - ts) / TICKS_PER_S:.1f} s behind")
        if ts < self.not_before:
            return self._no(Reject.STALE_TIMESTAMP, True, sysid, compid, msgid, link_id, ts,
                            f"{(self.not_before - ts) / TICKS_PER_S:.1f} s before start")
        stream = (sysid, compid, link_id)
        last = self._streams.get(stream)
        if last is not None and ts <= last:
            return self._no(Reject.REPLAY, True, sysid, compid, msgid, link_id, ts)
        self._streams[stream] = ts          # only now: the signature is valid
        if self.state_path is not None and ts >= now \
                and (self.persist_msgids is None or msgid in self.persist_msgids):
            self._save_streams()            # ahead of this clock: the start-time rule would not cover it
        self.accepted_signed += 1
        return Verdict(True, None, True, sysid, compid, msgid, link_id, ts)
