"""A recorded .tlog played back into the ground console (``gse console --replay FILE``).

The replay is a GroundClient without a socket or a key: ``poll`` feeds it the vehicle's
frames whose recorded time has come, at ``speed`` times the recorded pace, and its clock is
the recording's (so event times, link age and message rates read as they did live).
Frames the ground station itself sent are in the log too; the client keeps only the
vehicle's, as it does live. Signatures are not checked (the key is not needed to watch).
"""
from __future__ import annotations

import time
from pathlib import Path

from .client import GroundClient
from .tlog import read_records


class TlogReplay(GroundClient):
    def __init__(self, path: str | Path, *, speed: float = 1.0, monotonic=time.monotonic):
        if not speed > 0:
            raise ValueError(f"replay speed must be > 0, got {speed}")
        self.path = Path(path)
        try:
            self.records = list(read_records(self.path))
        except OSError as e:
            raise OSError(f"replay {self.path}: {e.strerror or e}") from None
        if not self.records:
            raise ValueError(f"replay {self.path}: no MAVLink records in the file")
        self.speed = float(speed)
        self._monotonic = monotonic
        self._t0_us = self.records[0][0]
        self._wall0: float | None = None          # started by the first poll
        self.position = 0                          # next record to feed
        super().__init__(None, listen=None, clock=self._now)

    @property
    def duration_s(self) -> float:
        return (self.records[-1][0] - self._t0_us) * 1e-6

    @property
    def done(self) -> bool:
        return self.position >= len(self.records)

    def _now(self) -> float:
        """Recording time (Unix s) at this point of the replay."""
        if self._wall0 is None:
            return self._t0_us * 1e-6
        elapsed = (self._monotonic() - self._wall0) * self.speed
        return min(self._t0_us * 1e-6 + elapsed, self.records[-1][0] * 1e-6)

    def poll(self, timeout_s: float = 0.0) -> int:
        """Feed every record due by now (the replay starts at the first poll)."""
        if self._wall0 is None:
            self._wall0 = self._monotonic()
        now_us = self._t0_us + (self._monotonic() - self._wall0) * self.speed * 1e6
        n = 0
        while self.position < len(self.records) and self.records[self.position][0] <= now_us:
            t_us, frame = self.records[self.position]
            self.position += 1
            n += self.feed(frame, None, t_us * 1e-6)
        return n

    def play_all(self) -> int:
        """Feed the whole recording at once (scripts, tests)."""
        n = 0
        while self.position < len(self.records):
            t_us, frame = self.records[self.position]
            self.position += 1
            n += self.feed(frame, None, t_us * 1e-6)
        self._wall0 = self._monotonic() - self.duration_s / self.speed
        return n
