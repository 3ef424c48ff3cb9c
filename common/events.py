"""Events: every detection and action of the FSW (and of the ground tools), with a
severity, rate-limited per code. Severities are MAVLink's (interfaces/vocabulary.py), so
the ground link carries them 1:1.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from interfaces.vocabulary import Severity


@dataclass(frozen=True)
class Event:
    t_s: float
    severity: Severity
    source: str     # module: "fdir", "allocator", "executive", "modes", "link", ...
    code: str       # stable machine-readable id, e.g. "jet_failed_off"
    text: str       # human-readable, <= 50 chars fits one MAVLink STATUSTEXT


class EventLog:
    """Bounded event queue with per-code rate limiting.

    ``emit`` never blocks and never grows memory without bound: beyond ``capacity``
    undelivered events the oldest are dropped and counted (``dropped``). Events of one
    code closer than ``min_interval_s`` are suppressed and counted (``suppressed``);
    the next one that passes says how many were suppressed.
    """

    def __init__(self, capacity: int = 1024, min_interval_s: float = 1.0):
        self.capacity = capacity
        self.min_interval_s = min_interval_s
        self._queue: deque[Event] = deque()
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}
        self.history: list[Event] = []    # every delivered event, for summaries
        self.dropped = 0
        self.suppressed = 0

    def emit(self, t_s: float, severity: Severity, source: str, code: str, text: str,
             rate_limited: bool = False) -> bool:
        if rate_limited:
            last = self._last.get(code)
            if last is not None and t_s - last < self.min_interval_s:
                self._held[code] = self._held.get(code, 0) + 1
                self.suppressed += 1
                return False
            held = self._held.pop(code, 0)
            if held:
                text = f"{text} (+{held} suppressed)"
        self._last[code] = t_s
        ev = Event(t_s, Severity(severity), source, code, text)
        if len(self._queue) >= self.capacity:
            self._queue.popleft()
            self.dropped += 1
        self._queue.append(ev)
        self.history.append(ev)
        return True

    def drain(self) -> list[Event]:
        """Take every queued event (for telemetry / publication)."""
        out = list(self._queue)
        self._queue.clear()
        return out

    def __len__(self) -> int:
        return len(self._queue)


__all__ = ["Event", "EventLog", "Severity"]
