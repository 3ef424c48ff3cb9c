"""The simulated time a SIL process has reached, passed through a file (the launcher's progress bar)."""
from __future__ import annotations

import os
import time


class ProgressFile:
    """How a process tells another its simulated time: one fixed-size line rewritten in
    place (at most every ``every_s`` of wall time, so the hot loop pays a clock read per
    step). The reader may see a torn line: it then gets None and tries again."""
    WIDTH = 16

    def __init__(self, path, every_s: float = 0.2):
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self.every_s = every_s
        self._next = 0.0

    def write(self, t_s: float, force: bool = False) -> None:
        now = time.monotonic()
        if force or now >= self._next:
            self._next = now + self.every_s
            os.pwrite(self._fd, b"%15.3f\n" % t_s, 0)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1

    @staticmethod
    def read(path) -> float | None:
        try:
            with open(path, "rb") as f:
                return float(f.read(ProgressFile.WIDTH))
        except (OSError, ValueError):
            return None
