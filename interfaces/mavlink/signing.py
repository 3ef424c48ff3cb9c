"""MAVLink 2 signing for the ground link, verify-first (spec 40-interfaces, "Security").

Used by both ends: the vehicle (FSW, system 1) and the ground console (system 255).

Why not pymavlink's own signing: in pymavlink 2.4.50 ``MAVLink.check_signature`` stores
the frame's timestamp as the stream's latest (``self.signing.stream_timestamps[stream_key]
= timestamp``) *before* it compares the signature (``if sig1 != sig2``), so a single
forged frame carrying a far-future timestamp makes every later genuine frame of that
stream look like a replay: the genuine ground station is locked out. Also, its ``decode``
returns unknown message ids before any signature check, and a badly signed frame is
accepted when ``allow_unsigned_callback`` allows that message id. Here every frame is
checked on its raw bytes by ``SigningVerifier`` before pymavlink sees it, and the stream
state changes only after the signature has been found valid; pymavlink then decodes with
signing disabled.

Signature (https://mavlink.io/en/guide/message_signing.html): the signature block is
link_id (1 byte), timestamp (6 bytes little endian, units of 10 us since
2015-01-01T00:00:00Z), and the first 6 bytes of SHA-256(secret_key + frame up to and
including the timestamp). A stream is (system id, component id, link id); its timestamps
must strictly increase.

Accepted without signature: HEARTBEAT only (``ALLOW_UNSIGNED_DEFAULT``). It carries no
command, lets a ground station that has no key yet be seen (and lets the operator be
told that its commands are being refused), and MAVLink's signing guide lists it among
the messages a system may accept unsigned. An unsigned HEARTBEAT is marked as such
(``msg.get_signed() is False``): it must never authorise anything, nor count as proof of
a live authenticated ground link. MAVLink 1 frames cannot be signed and are treated as
unsigned. A *signed* frame with a bad signature is rejected even if its message id may
be sent unsigned (unlike pymavlink's callback, which falls back to "allowed unsigned").

Key files: 64 hexadecimal characters (32 bytes), surrounding whitespace ignored, named
by an explicit path or by the environment variable ELLIPSLED_SIGNING_KEY_FILE. A key
file inside the repository tree is refused (it would end up committed); a key file
readable by group or others is accepted with a warning. Neither the key nor the file's
content ever appears in a log line, ``repr`` or exception message; ``SigningKey.key_id``
is a short one-way fingerprint operators can compare between the two ends.

Clocks: both ends must agree within ``max_future_s`` / ``max_age_s`` (default 60 s);
frames more than that ahead of or behind the receiver's clock are rejected. Every sender
sharing a key needs its own (system id, component id, link id).

Replay across restarts: a verifier accepts nothing signed before it was created (its
clock then: the process start), which refuses in a later run every frame signed before
the receiver's clock at acceptance. What that rule leaves is a frame signed *ahead* of the
receiver's clock (the sender's clock runs fast, up to ``max_future_s``): given a
``state_path`` (the vehicle: the key file's name + ``.streams``, ``stream_state_path``),
the verifier starts from the last timestamps saved there, and saves them, atomically (a
temporary file renamed over it) and before the frame is passed on, whenever it accepts
such a frame (of a message in ``persist_msgids``, if given: the vehicle's commands; a
replayed heartbeat changes nothing). So a frame captured in one run is refused in any
later run with the same key, and the file is written only when a sender's clock is ahead
(a write costs the receiving thread ~0.2 ms, ms on a busy disk). This assumes the
receiver's wall clock does not step back across a restart. A state file that cannot be
read is reported and ignored; one that cannot be written is reported and counted
(``persist_errors``).
"""
from __future__ import annotations

import hashlib
import hmac
import json
import logging
import os
import secrets
import stat
import string
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import NamedTuple

from . import framing
from .generated import ellipsled as dialect

log = logging.getLogger(__name__)

KEY_ENV = "ELLIPSLED_SIGNING_KEY_FILE"
KEY_LEN_BYTES = 32
KEY_HEX_CHARS = 2 * KEY_LEN_BYTES
_KEY_FILE_MAX_BYTES = 4096
EPOCH_2015_UNIX_S = 1420070400          # 2015-01-01T00:00:00Z, the signing epoch
TICKS_PER_S = 100_000                   # signing timestamp unit: 10 us
TIMESTAMP_MAX = (1 << 48) - 1
ALLOW_UNSIGNED_DEFAULT = frozenset({dialect.MAVLINK_MSG_ID_HEARTBEAT})

_SRC_TREE = Path(__file__).resolve().parents[2]
REPO_ROOT: Path | None = (_SRC_TREE if (_SRC_TREE / "pyproject.toml").is_file()
                          or (_SRC_TREE / ".git").exists() else None)


def signing_timestamp(unix_s: float) -> int:
    """Unix time [s] -> MAVLink signing timestamp [10 us since 2015-01-01], clamped to 48 bits."""
    return min(max(int((unix_s - EPOCH_2015_UNIX_S) * TICKS_PER_S), 0), TIMESTAMP_MAX)


# --------------------------------------------------------------------------- key


class SigningKeyError(ValueError):
    """A signing key could not be loaded; the message names the file, never its content."""


class SigningKey:
    """A 32-byte MAVLink signing secret. ``repr`` shows only the source and ``key_id``."""

    __slots__ = ("_secret", "source", "path")

    def __init__(self, secret: bytes, source: str = "<memory>"):
        if not isinstance(secret, (bytes, bytearray)) or len(secret) != KEY_LEN_BYTES:
            raise SigningKeyError(f"signing key from {source}: must be {KEY_LEN_BYTES} bytes")
        self._secret = bytes(secret)
        self.source = source
        self.path: Path | None = None       # the key file it was read from, if any

    @property
    def secret(self) -> bytes:
        return self._secret

    @property
    def key_id(self) -> str:
        """8 hex digits of a domain-separated SHA-256 of the key (cannot reveal it)."""
        return hashlib.sha256(b"ellipsled-signing-key-id\0" + self._secret).hexdigest()[:8]

    def __repr__(self) -> str:
        return f"SigningKey(source={self.source!r}, key_id={self.key_id})"

    __str__ = __repr__

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SigningKey) and hmac.compare_digest(self._secret, other._secret)

    __hash__ = None  # type: ignore[assignment]

    @classmethod
    def generate(cls) -> "SigningKey":
        return cls(secrets.token_bytes(KEY_LEN_BYTES), "<generated>")

    @classmethod
    def from_hex(cls, text: str, source: str = "<memory>") -> "SigningKey":
        s = text.strip()
        if len(s) != KEY_HEX_CHARS:
            raise SigningKeyError(f"signing key from {source}: expected {KEY_HEX_CHARS} hex "
                                  f"characters ({KEY_LEN_BYTES} bytes), found {len(s)} characters")
        if not all(c in string.hexdigits for c in s):
            raise SigningKeyError(f"signing key from {source}: contains characters that are "
                                  f"not hexadecimal digits")
        return cls(bytes.fromhex(s), source)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str] | None = None, *,
                  env: dict[str, str] | os._Environ[str] | None = None) -> "SigningKey":
        """Load from ``path``, else from the file named by $ELLIPSLED_SIGNING_KEY_FILE."""
        if path is None:
            path = (os.environ if env is None else env).get(KEY_ENV) or None
            if path is None:
                raise SigningKeyError(f"no signing key: pass a key file path or set {KEY_ENV}")
        p = Path(path).expanduser()
        _refuse_inside_repo(p)
        try:
            st = p.stat()
            if not stat.S_ISREG(st.st_mode):
                raise SigningKeyError(f"signing key file {p}: not a regular file")
            if st.st_size > _KEY_FILE_MAX_BYTES:
                raise SigningKeyError(f"signing key file {p}: too large ({st.st_size} bytes) "
                                      f"for a {KEY_HEX_CHARS}-character key")
            raw = p.read_bytes()[:_KEY_FILE_MAX_BYTES]
        except FileNotFoundError:
            raise SigningKeyError(f"signing key file not found: {p}") from None
        except PermissionError:
            raise SigningKeyError(f"signing key file {p}: permission denied") from None
        except IsADirectoryError:
            raise SigningKeyError(f"signing key file {p}: is a directory") from None
        except OSError as e:
            raise SigningKeyError(f"signing key file {p}: cannot read ({e.strerror})") from None
        if st.st_mode & 0o077:
            log.warning("signing key file %s is readable by group/others; chmod 600 it", p)
        try:
            text = raw.decode("ascii")
        except UnicodeDecodeError:
            raise SigningKeyError(f"signing key from {p}: contains characters that are not "
                                  f"hexadecimal digits") from None
        key = cls.from_hex(text, str(p))
        key.path = p
        return key

    def write_file(self, path: str | os.PathLike[str]) -> Path:
        """Write as 64 hex characters + newline, mode 0600; refuses to overwrite or to
        write inside the repository."""
        p = Path(path).expanduser()
        _refuse_inside_repo(p)
        try:
            fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:
            raise SigningKeyError(f"signing key file {p}: already exists") from None
        with os.fdopen(fd, "w", encoding="ascii") as f:
            f.write(self._secret.hex() + "\n")
        return p


def stream_state_path(key: SigningKey) -> Path | None:
    """Where a verifier using ``key`` keeps its streams' last timestamps: beside the key
    file (its name + ``.streams``); None for a key that did not come from a file."""
    return None if key.path is None else key.path.with_name(key.path.name + ".streams")


def _refuse_inside_repo(p: Path) -> None:
    if REPO_ROOT is None:
        return
    resolved = p.resolve()
    if resolved.is_relative_to(REPO_ROOT):
        raise SigningKeyError(f"signing key file {p} is inside the repository tree "
                              f"({REPO_ROOT}); keep keys outside it so they are never committed")


# --------------------------------------------------------------------------- verify


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


# --------------------------------------------------------------------------- sign


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
        self._mav_unsigned = dialect.MAVLink(None, srcSystem=system_id, srcComponent=component_id)

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
        is shared by signed and unsigned frames."""
        if signed:
            mav = self._mav
            mav.signing.timestamp = max(mav.signing.timestamp, signing_timestamp(self.clock()))
            buf = msg.pack(mav)             # pymavlink's sign_packet then does timestamp += 1
        else:
            mav = self._mav_unsigned
            mav.seq = self._mav.seq
            buf = msg.pack(mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return buf


# --------------------------------------------------------------------------- link


@dataclass
class LinkStats:
    datagrams: int = 0
    accepted: int = 0


class SignedLink:
    """Both ends of the ground link: ``pack`` signs outgoing messages; ``receive`` splits a
    datagram (or ``receive_stream`` a byte-stream chunk), verifies every frame on its raw
    bytes, and only then lets pymavlink (signing disabled) decode it.

    Returned messages carry ``get_signed()`` / ``get_link_id()`` as verified here.
    Transport (sockets), tlog recording and command handling belong to the caller.
    """

    def __init__(self, key: SigningKey, *, system_id: int, component_id: int,
                 link_id: int = 0, allow_unsigned: Collection[int] = ALLOW_UNSIGNED_DEFAULT,
                 max_future_s: float = 60.0, max_age_s: float | None = 60.0,
                 clock: Callable[[], float] = time.time, on_reject: RejectHook | None = None,
                 state_path: str | os.PathLike[str] | None = None, persist_msgids: Collection[int] | None = None):
        self.signer = Signer(key, system_id=system_id, component_id=component_id,
                             link_id=link_id, clock=clock)
        self.verifier = SigningVerifier(key, allow_unsigned=allow_unsigned,
                                        max_future_s=max_future_s, max_age_s=max_age_s,
                                        clock=clock, on_reject=on_reject, state_path=state_path,
                                        persist_msgids=persist_msgids)
        self.splitter = framing.FrameSplitter()
        self.stats = LinkStats()
        self._decoder = dialect.MAVLink(None)   # no secret key: pymavlink never checks
        self._decoder.robust_parsing = True

    @property
    def counts(self) -> dict[Reject, int]:
        return self.verifier.counts

    def pack(self, msg: dialect.MAVLink_message, *, signed: bool = True) -> bytes:
        return self.signer.pack(msg, signed=signed)

    def receive(self, datagram: bytes | bytearray | memoryview) -> list[dialect.MAVLink_message]:
        """Accepted, decoded messages of one UDP datagram, in order. Never raises."""
        self.stats.datagrams += 1
        before = self.splitter.stats.as_dict()
        frames = self.splitter.split_datagram(datagram)
        self._count_split(before)
        return self._accept(frames)

    def receive_stream(self, chunk: bytes | bytearray | memoryview) -> list[dialect.MAVLink_message]:
        """Like ``receive`` for a byte stream (serial, TCP): partial frames are kept."""
        before = self.splitter.stats.as_dict()
        frames = self.splitter.feed(chunk)
        self._count_split(before)
        return self._accept(frames)

    def receive_single(self, frame: bytes | bytearray | memoryview) -> list[dialect.MAVLink_message]:
        """Like ``receive`` for a datagram that is exactly one frame (the caller checked its
        length against its header): the signature is checked first, on the raw bytes (one
        HMAC; a valid signature also vouches for the CRC bytes it covers), so a forged frame
        costs no CRC; pymavlink then decodes it, checking the CRC. Never raises."""
        self.stats.datagrams += 1
        return self._accept([bytes(frame)])

    def _count_split(self, before: dict[str, int]) -> None:
        after = self.splitter.stats.as_dict()
        for field, reason in (("bad_crc", Reject.BAD_CRC), ("unknown_msgid", Reject.UNKNOWN_MESSAGE),
                              ("truncated", Reject.TRUNCATED), ("garbage_bytes", Reject.GARBAGE)):
            d = after[field] - before[field]
            if d:
                self.verifier.reject(Rejection(reason, detail=f"{d} {field}"))

    def _accept(self, frames: list[bytes]) -> list[dialect.MAVLink_message]:
        out = []
        for frame in frames:
            v = self.verifier.verify(frame)
            if not v.accepted:
                continue
            try:
                msg = self._decoder.decode(bytearray(frame))
            except Exception as e:          # pymavlink raises MAVError and others
                self.verifier.reject(Rejection(Reject.DECODE_ERROR, v.sysid, v.compid, v.msgid,
                                               v.link_id, type(e).__name__))
                continue
            if isinstance(msg, (dialect.MAVLink_bad_data, dialect.MAVLink_unknown)):
                self.verifier.reject(Rejection(Reject.DECODE_ERROR, v.sysid, v.compid, v.msgid,
                                               v.link_id, msg.get_type()))
                continue
            if v.signed:
                msg._signed = True
                msg._link_id = v.link_id
            out.append(msg)
            self.stats.accepted += 1
        return out


def main(argv: list[str] | None = None) -> int:
    """``python -m interfaces.mavlink.signing new-key PATH``: write a fresh key file (0600)."""
    import argparse
    ap = argparse.ArgumentParser(description="ellipsled MAVLink signing keys")
    sub = ap.add_subparsers(dest="cmd", required=True)
    nk = sub.add_parser("new-key", help="write a new random key file (mode 0600, must not exist)")
    nk.add_argument("path", type=Path)
    ck = sub.add_parser("check-key", help="load a key file and print its key id")
    ck.add_argument("path", type=Path, nargs="?")
    args = ap.parse_args(argv)
    try:
        if args.cmd == "new-key":
            key = SigningKey.generate()
            p = key.write_file(args.path)
            print(f"wrote {p} (key id {key.key_id})")
        else:
            key = SigningKey.from_file(args.path)
            print(f"{key.source}: key id {key.key_id}")
    except SigningKeyError as e:
        print(f"error: {e}")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
