"""Both ends of a signed ground link over one key: ``SignedLink`` signs what it packs and
verifies every received frame on its raw bytes before pymavlink decodes it."""
from __future__ import annotations

import os
import time
from collections.abc import Callable, Collection
from dataclasses import dataclass

from .. import framing
from ..generated import ellipsled as dialect
from .keys import SigningKey
from .sign import Signer
from .verify import ALLOW_UNSIGNED_DEFAULT, Reject, RejectHook, Rejection, SigningVerifier


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
