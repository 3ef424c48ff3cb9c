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
    """Bounded event queue and history with per-code rate limiting.

    ``emit`` never blocks and never grows memory without bound: beyond ``capacity``
    undelivered events the oldest are dropped and counted (``dropped``); the history keeps
    the last ``history_capacity`` events (a ring: ``total`` counts every event ever
    delivered, ``since(seq)`` reads by that count). Events of one code closer than
    ``min_interval_s`` are suppressed and counted (``suppressed``); the next one that
    passes says how many were suppressed, and ``release_held`` tells a code's suppressed
    events once its interval is over even if no other comes (one summary, not one event
    per occurrence). A code may have its own interval (``emit(..., min_interval_s=...)``:
    e.g. the ground link's refusals, told once and then summarised once a minute).
    """

    def __init__(self, capacity: int = 1024, min_interval_s: float = 1.0, history_capacity: int = 4096):
        self.capacity = capacity
        self.min_interval_s = min_interval_s
        self._queue: deque[Event] = deque()
        self._last: dict[str, float] = {}
        self._interval: dict[str, float] = {}  # code -> its own min_interval_s
        self._held: dict[str, list] = {}      # code -> [count, severity, source, text of the last held]
        self._ring: deque[Event] = deque(maxlen=int(history_capacity))
        self.total = 0                        # events delivered so far (the next one's sequence number)
        self.dropped = 0
        self.suppressed = 0

    @property
    def history(self) -> list[Event]:
        """The delivered events still in the ring, oldest first (for summaries)."""
        return list(self._ring)

    @property
    def history_lost(self) -> int:
        """Delivered events the ring no longer holds."""
        return self.total - len(self._ring)

    def since(self, seq: int) -> tuple[int, list[Event]]:
        """Delivered events from sequence number ``seq`` on: (sequence number of the first
        returned, events). The first is above ``seq`` when the ring no longer holds those
        in between (a reader that fell behind learns how many it missed)."""
        first = max(int(seq), self.history_lost)
        n = self.total - first
        if n <= 0:
            return self.total, []
        ring = self._ring
        return first, [ring[i] for i in range(len(ring) - n, len(ring))]

    def emit(self, t_s: float, severity: Severity, source: str, code: str, text: str,
             rate_limited: bool = False, min_interval_s: float | None = None) -> bool:
        if rate_limited:
            if min_interval_s is not None:
                self._interval[code] = float(min_interval_s)
            last = self._last.get(code)
            if last is not None and t_s - last < self._interval.get(code, self.min_interval_s):
                held = self._held.get(code)
                if held is None:
                    self._held[code] = [1, severity, source, text]
                else:
                    held[0] += 1
                    held[1:] = severity, source, text
                self.suppressed += 1
                return False
            held = self._held.pop(code, None)
            if held:
                text = f"{text} (+{held[0]} suppressed)"
        self._deliver(Event(t_s, Severity(severity), source, code, text))
        return True

    def release_held(self, t_s: float) -> int:
        """Deliver, for every code whose suppressed events wait and whose interval is over,
        one event: the last suppressed one, saying how many others were held. Returns how
        many were delivered."""
        n = 0
        for code in [c for c in self._held
                     if t_s - self._last.get(c, t_s) >= self._interval.get(c, self.min_interval_s)]:
            count, severity, source, text = self._held.pop(code)
            self._deliver(Event(t_s, Severity(severity), source, code,
                                f"{text} (+{count - 1} suppressed)" if count > 1 else text))
            n += 1
        return n

    def _deliver(self, ev: Event) -> None:
        self._last[ev.code] = ev.t_s
        if len(self._queue) >= self.capacity:
            self._queue.popleft()
            self.dropped += 1
        self._queue.append(ev)
        self._ring.append(ev)
        self.total += 1

    def drain(self) -> list[Event]:
        """Take every queued event (for telemetry / publication)."""
        out = list(self._queue)
        self._queue.clear()
        return out

    def __len__(self) -> int:
        return len(self._queue)


__all__ = ["Event", "EventLog", "Severity"]
