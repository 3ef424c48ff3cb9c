"""Events: every detection and action of the FSW (and of the ground tools), each an entry
of the event catalogue (interfaces/event_catalogue.py: id, severity, message, throttle),
rate-limited per entry. Severities are MAVLink's (interfaces/vocabulary.py), so the ground
link carries them 1:1.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

from interfaces.event_catalogue import BY_NAME, EventDef
from interfaces.vocabulary import Severity


@dataclass(frozen=True)
class Event:
    t_s: float
    severity: Severity
    source: str     # module: "fdir", "allocator", "executive", "modes", "link", ...
    code: str       # the catalogue entry's name, e.g. "jet_failed_off"
    text: str       # the rendered message, <= 50 chars: one MAVLink STATUSTEXT
    args: tuple[tuple[str, object], ...] | None = None   # the entry's arguments; None: emitted as text

    @property
    def entry(self) -> EventDef | None:
        """The catalogue entry of this event (None for a code the catalogue does not know)."""
        return BY_NAME.get(self.code)


class EventLog:
    """Bounded event queue and history with per-entry rate limiting.

    ``emit(t_s, EV.NAME, **args)`` renders the entry's message with its arguments. It never
    blocks and never grows memory without bound: beyond ``capacity`` undelivered events the
    oldest are dropped and counted (``dropped``); the history keeps the last
    ``history_capacity`` events (a ring: ``total`` counts every event ever delivered,
    ``since(seq)`` reads by that count). Events of an entry with a throttle closer than its
    interval are suppressed and counted (``suppressed``); the next one that passes says how
    many were suppressed, and ``release_held`` tells an entry's suppressed events once its
    interval is over even if no other comes (one summary, not one event per occurrence). A
    log may give an entry its own interval (``set_throttle``: e.g. the ground link's
    refusals, told once and then summarised at the link's own pace).

    The older form ``emit(t_s, severity, source, code, text, rate_limited=False,
    min_interval_s=None)`` (``min_interval_s`` of the log when not given) is still accepted
    for the modules not yet converted to the catalogue.
    """

    def __init__(self, capacity: int = 1024, min_interval_s: float = 1.0, history_capacity: int = 4096):
        self.capacity = capacity
        self.min_interval_s = min_interval_s   # the interval of a rate-limited emit of the older form
        self._queue: deque[Event] = deque()
        self._last: dict[str, float] = {}
        self._interval: dict[str, float] = {}  # code -> this log's own interval for it
        self._held: dict[str, list] = {}      # code -> [count, the last held Event, its interval]
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

    def set_throttle(self, event: EventDef, interval_s: float) -> None:
        """This log tells ``event`` at most once per ``interval_s`` (a summary of the rest)."""
        self._interval[event.name] = float(interval_s)

    def emit(self, t_s: float, event: EventDef, *text_form, **args) -> bool:
        """One occurrence of catalogue entry ``event`` with its arguments; True if delivered
        now, False if held by the entry's throttle."""
        if not isinstance(event, EventDef):
            return self._emit_text(t_s, event, *text_form, **args)
        if text_form:
            raise TypeError(f"event {event.name}: arguments are passed by name")
        _, text = event.render(args)
        interval = self._interval.get(event.name, event.throttle_s)
        return self._offer(Event(t_s, event.severity, event.source, event.name, text, tuple(args.items())), interval)

    def _emit_text(self, t_s: float, severity: Severity, source: str, code: str, text: str,
                   rate_limited: bool = False, min_interval_s: float | None = None) -> bool:
        """The older form (text and severity chosen by the caller)."""
        if rate_limited and min_interval_s is not None:
            self._interval[code] = float(min_interval_s)
        interval = self._interval.get(code, self.min_interval_s) if rate_limited else None
        return self._offer(Event(t_s, Severity(severity), source, code, text), interval)

    def _offer(self, ev: Event, interval: float | None) -> bool:
        if interval is not None:
            last = self._last.get(ev.code)
            if last is not None and ev.t_s - last < interval:
                held = self._held.get(ev.code)
                self._held[ev.code] = [1 if held is None else held[0] + 1, ev, interval]
                self.suppressed += 1
                return False
            held = self._held.pop(ev.code, None)
            if held:
                ev = replace(ev, text=f"{ev.text} (+{held[0]} suppressed)")
        self._deliver(ev)
        return True

    def release_held(self, t_s: float) -> int:
        """Deliver, for every entry whose suppressed events wait and whose interval is over,
        one event: the last suppressed one, saying how many others were held. Returns how
        many were delivered."""
        n = 0
        for code in [c for c, h in self._held.items() if t_s - self._last.get(c, t_s) >= h[2]]:
            count, ev, _ = self._held.pop(code)
            self._deliver(replace(ev, t_s=t_s, text=f"{ev.text} (+{count - 1} suppressed)" if count > 1 else ev.text))
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
