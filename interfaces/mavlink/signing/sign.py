"""The sending side of MAVLink 2 signing: the signing timestamp and the ``Signer``, which
packs dialect messages as signed frames (https://mavlink.io/en/guide/message_signing.html)."""
from __future__ import annotations

import time
from collections.abc import Callable

from ..generated import ellipsled as dialect
from .keys import SigningKey

EPOCH_2015_UNIX_S = 1420070400          # 2015-01-01T00:00:00Z, the signing epoch
TICKS_PER_S = 100_000                   # signing timestamp unit: 10 us
TIMESTAMP_MAX = (1 << 48) - 1


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
