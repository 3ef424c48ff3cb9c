"""When the ground link works: its time budget per tick and the telemetry streams' schedule.

The link's tick is one task of a control cycle (RG2), so its cost comes out of that cycle's
period. ``TickBudget`` bounds it: ``tick_budget_frac`` of the control period (0.15: 0.75 ms at
200 Hz, 3 ms at 50 Hz). Within it, less its end reserve (below), receiving (and answering
what arrived) may take all but the send side's recent cost, and never more than half when
sending wants more (so a flood cannot starve the telemetry, nor heavy telemetry the
commands); when streams are a period overdue (they go first, the most overdue whatever the
budget), receiving also leaves their cost, keeping at least ``RECEIVE_FLOOR``, so sending
them does not carry the tick past its budget; what the tick spent before receiving is taken
from receiving's share (and, link.py, what receiving recently took past the intake's
budget); sending takes what receiving left, in this order:

1. events, each while its recent cost fits (the first of the tick whatever the budget: what
   the flight software reports reaches the ground even in a tick whose budget a flood used
   up; the others wait, counted: ``events_deferred``), at most ``EVENT_SHARE`` frames;
2. the telemetry streams that are due, those a period overdue first, then the
   longest-waiting, while budget is left for each (its ``RecentCost`` and the units' recent
   estimate misses); a stream not sent stays due and goes out at a
   later tick (counted: ``tx_deferred``), so under a short budget every stream still gets
   its turn and none is dropped;
3. answers to requests (parameter lists) and further events, from the reply budget, each
   while its recent cost fits (a list cut short waits, counted: ``params_deferred``);

then, when the intake stopped on its budget (datagrams wait), receiving reads on in what
sending left (link.py).

Work is begun only while its estimate fits short of ``END_RESERVE`` of the budget (receiving
too: its share never reaches into the reserve): what follows the last check (the tick's
bookkeeping) and what items cost beyond their estimates (a cache-cold unit, a frame that
took a page fault) land in the reserve, so the tick's tail, not only its median, stays
inside the budget. Every kind of work that can wait is begun item by item against its
own estimate (``RecentCost``): streams (streams.py), received frames (the intake), events,
parameter-list entries and FTP replies (link.py); what does not fit waits for the next
tick, counted per kind in the link's ``stats`` (``tx_deferred``, ``rx_deferred`` and
``rx_budget_hits``, ``events_deferred``, ``params_deferred``, ``ftp_deferred``).

``StreamSchedule`` keeps when each stream is next due; a stream may go out up to
``DUE_SLACK`` of its period early (tick jitter must not skip a period).
"""
from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterable

import numpy as np

DUE_SLACK = 0.05                 # a stream may go out up to 5 % of its period early
TICK_BUDGET_FRAC = 0.15          # the link's share of a control period
COST_RING = 1024                 # ticks whose cost is kept for the percentiles
RECEIVE_FLOOR = 0.5              # the share of the time to work in receiving keeps whatever the streams owe
END_RESERVE = 0.3                # the budget's share no work is begun in: the tail's room (docs/decisions.md)
COST_SAMPLES = 8                 # recent costs of a piece of work its estimate is taken from


class RecentCost:
    """What one piece of a tick's work is taken to cost [ns]: the second costliest of its
    last COST_SAMPLES costs (a noisy piece is met; one slow time moves nothing, two are
    forgotten within the ring). 0 before the first."""

    __slots__ = ("ring", "ns")

    def __init__(self) -> None:
        self.ring: deque[int] = deque(maxlen=COST_SAMPLES)
        self.ns = 0

    def add(self, ns: int) -> None:
        ring = self.ring
        ring.append(int(ns))
        self.ns = sorted(ring)[-2] if len(ring) > 1 else ring[0]


class TickBudget:
    """Time left in one tick of the link, on ``clock_ns`` (tests inject one)."""

    def __init__(self, budget_ns: int, clock_ns: Callable[[], int] = time.perf_counter_ns) -> None:
        if not budget_ns > 0:
            raise ValueError(f"the ground link's tick budget must be > 0 ns, got {budget_ns}")
        self.budget_ns = int(budget_ns)
        self.clock_ns = clock_ns
        self.t0_ns = 0
        self.limit_ns = self.budget_ns
        self.reserve_ns = 0
        self.costs = np.zeros(COST_RING, dtype=np.int64)   # the last ticks' costs [ns], a ring
        self.ticks = 0
        self.over = 0                                    # ticks that cost more than the budget
        self.max_ns = 0                                  # the costliest tick of the run
        self.listens = self.listens_over = self.listen_max_ns = 0   # the same of the listens between ticks

    def start(self, cap_ns: int | None = None) -> None:
        """A tick begins; ``cap_ns``: less time than the budget is left (the cycle's deadline)."""
        self.t0_ns = self.clock_ns()
        self.limit_ns = self.budget_ns if cap_ns is None else max(0, min(self.budget_ns, int(cap_ns)))
        self.reserve_ns = int(END_RESERVE * self.limit_ns)

    def finish(self, listen: bool = False) -> int:
        """The tick ends: its cost [ns], kept (``listen``: a listen between ticks, link.py:
        counted apart, so the ticks' percentiles stay the ticks')."""
        cost = self.elapsed_ns()
        if listen:
            self.listens += 1
            self.listens_over += cost > self.budget_ns
            self.listen_max_ns = max(self.listen_max_ns, cost)
            return cost
        self.costs[self.ticks % COST_RING] = cost
        self.ticks += 1
        self.over += cost > self.budget_ns
        self.max_ns = max(self.max_ns, cost)
        return cost

    def report(self) -> dict:
        """Budget, the kept ticks' cost percentiles and the run's costliest tick [us] (not for
        the cycle: it sorts)."""
        kept = self.costs[:min(self.ticks, COST_RING)]
        p50, p99 = np.percentile(kept, (50, 99)) * 1e-3 if kept.size else (0.0, 0.0)
        return {"budget_us": self.budget_ns * 1e-3, "ticks": self.ticks, "over_budget": self.over,
                "p50_us": float(p50), "p99_us": float(p99), "max_us": self.max_ns * 1e-3,
                "listens": self.listens, "listens_over_budget": self.listens_over,
                "listen_max_us": self.listen_max_ns * 1e-3}

    def elapsed_ns(self) -> int:
        return self.clock_ns() - self.t0_ns

    def fits(self, estimate_ns: int) -> bool:
        """An item of work estimated at ``estimate_ns`` may be begun: it ends short of the
        end reserve."""
        return self.left_ns() >= estimate_ns

    def left_ns(self) -> int:
        """Time left to begin more work: the limit less the end reserve (the tick's
        bookkeeping after its last check: parameter lists, events, the cost ring)."""
        return self.limit_ns - self.reserve_ns - self.elapsed_ns()

    def receive_ns(self, send_ns_recent: int, overdue_ns: int = 0) -> int:
        """What receiving may take of the time work may be begun in (the budget less its
        end reserve: with nothing to send, a flood would otherwise fill the whole budget
        and its tail run past it): all of it but the send side's recent cost, at least
        half; and all but what sending the streams a period overdue costs (they go this
        tick), at least RECEIVE_FLOOR of it; less what the tick has spent already (the
        schedule's own work before receiving is the tick's too)."""
        usable = self.limit_ns - self.reserve_ns
        keep = max(min(int(send_ns_recent), usable // 2),
                   min(max(0, int(overdue_ns)), usable - int(RECEIVE_FLOOR * usable)))
        return max(0, usable - keep - self.elapsed_ns())


class StreamSchedule:
    """Next due time [s] of each telemetry stream at ``rates_hz`` (a stream at 0 Hz is off)."""

    def __init__(self, rates_hz: dict[str, float]) -> None:
        self.rates_hz = rates_hz
        self.next_due = {name: 0.0 for name in rates_hz}

    def waiting(self, name: str, now: float) -> bool:
        """``name`` is due at ``now`` (nothing changes)."""
        hz = self.rates_hz[name]
        return hz > 0.0 and now >= self.next_due[name] - DUE_SLACK / hz

    def take(self, name: str, now: float) -> bool:
        """``name`` is due: True, and it is next due one period later (or a period from now
        when it has fallen behind by more than a period)."""
        if not self.waiting(name, now):
            return False
        period = 1.0 / self.rates_hz[name]
        nxt = self.next_due[name] + period
        self.next_due[name] = nxt if nxt > now else now + period
        return True

    def now(self, name: str) -> None:
        """``name`` is due at the next tick, ahead of every stream waiting (its rate was just
        changed, or it has news to tell)."""
        self.next_due[name] = -math.inf

    def overdue(self, unit: tuple[str, ...], now: float) -> bool:
        """A stream of ``unit`` has waited a whole period past its due time (or was asked
        for at once: ``now``)."""
        return any(self.rates_hz[n] > 0.0 and now >= self.next_due[n] + 1.0 / self.rates_hz[n] for n in unit)

    def due(self, units: Iterable[tuple[str, ...]], now: float) -> list[tuple[float, int, tuple[str, ...], bool, int]]:
        """The units (a stream, or streams sent together) with a stream due at ``now``, in
        one pass over their streams (it runs every tick, twice: its cost is the link's own):
        (when its earliest waiting stream was due, its index in ``units``, the unit, whether
        a stream of it is a period overdue, how many of its streams are due)."""
        out = []
        rates, next_due = self.rates_hz, self.next_due
        for i, unit in enumerate(units):
            first, overdue, n = math.inf, False, 0
            for name in unit:
                hz = rates[name]
                if hz > 0.0:
                    t = next_due[name]
                    if now >= t - DUE_SLACK / hz:
                        n += 1
                        first = min(first, t)
                        overdue = overdue or now >= t + 1.0 / hz
            if n:
                out.append((first, i, unit, overdue, n))
        return out

    def longest_waiting(self, units: Iterable[tuple[str, ...]], now: float) -> list[tuple[str, ...]]:
        """The units with a stream due, the one due earliest first."""
        return [u for _, _, u, _, _ in sorted(self.due(units, now))]

    def sending_order(self, units: Iterable[tuple[str, ...]], now: float) -> list[tuple[tuple[str, ...], bool, int]]:
        """The units with a stream due, in the order a tick sends them: those a period
        overdue first (receiving left their cost for them), then the one due earliest;
        each as (unit, overdue, how many of its streams are due)."""
        return [(u, od, n) for _, _, u, od, n in sorted(self.due(units, now), key=lambda d: (not d[3], d[0], d[1]))]
