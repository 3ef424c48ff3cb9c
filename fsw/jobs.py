"""Background jobs: a function the control loop asks for, computed off the loop.

The flight software's long computations (the allocator's table builds, the controllability
LP, the guidance correction) take longer than a control period. Each is one
``BackgroundJob``, the flight software's one way to start a thread. The loop hands it requests
(``submit``) and collects answers (``take``); the function never sees a thread, a clock or
the loop.

How an answer lands (``mode``):

- ``IN_PLACE`` (batch and lockstep, for an answer needed in the step that asked): ``submit``
  runs the function on the caller's thread; the answer is there when it returns.
- ``AWAITED`` (batch and lockstep, for an answer due later): a thread computes it while the
  loop runs on; ``take`` at or after the due step waits for it. Every run applies the same
  answer at the same step however long it took: deterministic.
- ``REALTIME``: a thread computes it and the loop never waits. An answer not there at its
  due step is late: counted and reported once, the owner keeps what it had, and the answer
  is handed over by the first ``take`` after it arrives.

The thread runs one SCHED_FIFO priority below the loop (``common.rt.run_below_loop``), so the
loop preempts it at every release. A request supersedes one not yet started; with the
latest answer kept (``keep=LATEST``), it also makes stale an answer still being computed or
not yet taken (the newest request wins). ``keep=EVERY`` keeps every finished answer by its
tag until taken (table builds: each one is worth caching). ``skip_while_busy``: a request
made while the previous one is still computing is refused and counted instead (the owner
keeps its cadence rather than queueing behind a slow job) -- in real time only: ``AWAITED``
lets the previous one finish first and takes the request, so that how fast the thread ran
never decides what a lockstep or batch run flies.

A function that raises never stops the loop or the thread: it is counted (``faults``), and
``take`` reports it as an event and hands the owner no answer (its previous one stands).
"""
from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from common import rt
from common.events import EventLog
from interfaces.event_catalogue import EV, EventDef

OVERRUN_SKIPPED, OVERRUN_LATE = 0, 1       # the catalogue's overrun_t: what a late job did

IN_PLACE, AWAITED, REALTIME = "in place", "awaited", "real time"
LATEST, EVERY = "latest", "every"


@dataclass(frozen=True)
class Answer:
    """What the function gave for one request."""
    value: object                  # its return value (None when it raised)
    error: Exception | None        # what it raised, None when it returned
    tag: object                    # the request's tag, handed back as submitted
    t_s: float                     # the request's mission time [s] (its release)


@dataclass(frozen=True)
class _Request:
    seq: int
    args: tuple
    tag: object
    t_s: float
    wanted: bool = True            # False: a warm-up, its answer discarded


class BackgroundJob:
    """``fn(*args)`` computed for the newest request (module docstring).

    ``fn`` is public: tests replace it to inject delays or faults. ``name`` names the
    thread. With ``events``, lateness and skipped requests are reported as ``overrun_event``
    and faults as ``fault_event`` (catalogue entries); without, they are only counted."""

    def __init__(self, fn: Callable, name: str, *, mode: str = REALTIME, keep: str = LATEST,
                 skip_while_busy: bool = False, events: EventLog | None = None,
                 overrun_event: EventDef | None = None, fault_event: EventDef | None = None) -> None:
        if mode not in (IN_PLACE, AWAITED, REALTIME) or keep not in (LATEST, EVERY):
            raise ValueError(f"{name}: mode {mode!r}, keep {keep!r}")
        self.fn = fn
        self.name = name
        self.mode = mode
        self.keep = keep
        self.skip_while_busy = skip_while_busy
        self.events, self.overrun_event, self.fault_event = events, overrun_event, fault_event
        self.released = 0                 # requests accepted
        self.skipped = 0                  # requests refused while busy (skip_while_busy)
        self.late = 0                     # answers not there at their due step
        self.faults = 0                   # requests whose function raised
        self.due_t = math.inf             # mission time [s] the wanted answer is due at (inf: none)
        self.overdue = False              # past due_t and still not there
        self._deadline = False            # the wanted answer's lateness counts
        self._cv = threading.Condition()
        self._request: _Request | None = None      # newest, not yet started
        self._backlog: deque[_Request] = deque()   # served when no request waits
        self._running: _Request | None = None
        self._seq = 0
        self._wanted = 0                  # keep=LATEST: seq of the request whose answer is kept
        self._answer: Answer | None = None     # keep=LATEST: that answer, not yet taken
        self._answers: dict = {}          # keep=EVERY: tag -> Answer, not yet taken
        self._gate = threading.Event()    # cleared by hold(): requests wait before they start
        self._gate.set()
        self._stop = False
        self._thread: threading.Thread | None = None
        if mode != IN_PLACE:
            self._thread = threading.Thread(target=self._run, name=name, daemon=True)
            self._thread.start()

    # ------------------------------------------------------------------ requests
    def submit(self, *args, tag=None, t_s: float = math.nan, due_t: float | None = None) -> bool:
        """Ask for ``fn(*args)``. ``tag`` comes back with the answer; ``t_s``: the mission
        time of the request; ``due_t``: the mission time its answer is due at (None: no
        deadline, taken whenever it is there). False when refused (``skip_while_busy``:
        counted, reported at ``t_s``)."""
        with self._cv:
            if self.skip_while_busy and self.mode == AWAITED:
                # the thread's progress must not decide (lockstep and batch are deterministic):
                # the previous request is let finish, as if it had been quick, then this one goes
                self._cv.wait_for(lambda: not self._busy() or self._stop)
            refused = self.skip_while_busy and self._busy()
            if refused:
                self.skipped += 1
            else:
                req = self._new(args, tag, t_s)
                self._request = req
                if self.keep == LATEST:
                    self._wanted = req.seq
                    self._answer = None
                self.released += 1
                self._cv.notify()
        if refused:
            self._report(t_s, self.overrun_event, what=OVERRUN_SKIPPED)
            return False
        self._deadline = due_t is not None
        self.due_t = -math.inf if due_t is None else due_t
        self.overdue = False
        if self.mode == IN_PLACE:
            self._serve_here()
        return True

    def queue(self, requests: Iterable[tuple[object, tuple]]) -> None:
        """(tag, args) pairs served in order whenever no submitted request waits."""
        with self._cv:
            self._backlog.extend(self._new(args, tag, math.nan) for tag, args in requests)
            self._cv.notify()
        if self.mode == IN_PLACE:
            self._serve_here()

    def cancel(self) -> None:
        """Drop the request not yet started and the backlog (a running one finishes)."""
        with self._cv:
            self._request = None
            self._backlog.clear()

    # ------------------------------------------------------------------ answers
    def take(self, t_s: float = math.inf) -> Answer | None:
        """keep=LATEST: the wanted answer once it is due at mission time ``t_s``, else None.
        At or after the due step ``AWAITED`` waits for it; ``REALTIME`` counts and reports a
        missing one as late, once. An answer whose function raised is reported and not
        handed over (None)."""
        if t_s < self.due_t:
            return None
        if self.mode == AWAITED:
            with self._cv:
                self._cv.wait_for(lambda: not self._busy() or self._stop)
        with self._cv:
            ans, self._answer = self._answer, None
        if ans is None:
            if self._deadline and not self.overdue:
                self.overdue = True
                self.late += 1
                self._report(t_s, self.overrun_event, what=OVERRUN_LATE)
            return None
        self.due_t, self.overdue = math.inf, False
        if ans.error is not None:
            self._report(ans.t_s, self.fault_event, error=f"{type(ans.error).__name__}: {ans.error}")
            return None
        return ans

    def pop(self, tag) -> Answer | None:
        """keep=EVERY: the finished answer for ``tag`` (its ``error`` set if it raised)."""
        with self._cv:
            return self._answers.pop(tag, None)

    def pop_all(self) -> list[Answer]:
        """keep=EVERY: every finished answer, oldest first."""
        with self._cv:
            out = list(self._answers.values())
            self._answers.clear()
        return out

    @property
    def ready(self) -> bool:
        """An answer waits to be taken."""
        return self._answer is not None or bool(self._answers)

    @property
    def busy(self) -> bool:
        """A request waits or is being computed."""
        return self._busy()

    def _busy(self) -> bool:
        return self._request is not None or self._running is not None or bool(self._backlog)

    # ------------------------------------------------------------------ life cycle
    def warm(self, *args, timeout_s: float = 10.0) -> bool:
        """Before the first cycle: run the function once on its thread and discard the answer,
        so what it sets up per thread (a solver's first call) is not paid in flight. True if
        it finished within ``timeout_s``. Nothing to do in place (the caller's thread)."""
        if self.mode == IN_PLACE:
            return True
        with self._cv:
            self._request = self._new(args, None, math.nan, wanted=False)
            self._cv.notify()
        return self.wait_idle(timeout_s)

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait (never in the cycle) until no request waits or computes; True if in time."""
        with self._cv:
            return self._cv.wait_for(lambda: not self._busy(), timeout_s)

    def hold(self) -> None:
        """Requests not yet started wait until ``resume`` (tests: a deterministic interim)."""
        self._gate.clear()

    def resume(self) -> None:
        self._gate.set()

    def close(self, timeout_s: float = 5.0) -> None:
        """Drop what waits, end the thread (a running request is left to finish, unanswered)."""
        with self._cv:
            self._stop = True
            self._request = None
            self._backlog.clear()
            self._cv.notify_all()
        self._gate.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout_s)

    @property
    def alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # ------------------------------------------------------------------ the work
    def _new(self, args: tuple, tag, t_s: float, wanted: bool = True) -> _Request:
        self._seq += 1
        return _Request(self._seq, args, tag, t_s, wanted)

    def _next(self) -> _Request | None:
        if self._request is not None:
            req, self._request = self._request, None
        elif self._backlog:
            req = self._backlog.popleft()
        else:
            return None
        self._running = req
        return req

    def _compute(self, req: _Request) -> Answer:
        try:
            return Answer(self.fn(*req.args), None, req.tag, req.t_s)
        except Exception as e:      # noqa: BLE001 -- a faulty job must not stop the loop or the thread
            return Answer(None, e, req.tag, req.t_s)

    def _finish(self, req: _Request, ans: Answer) -> None:
        """Under the lock: file the answer the request is still wanted for."""
        self._running = None
        if ans.error is not None:
            self.faults += 1
        if req.wanted and self.keep == EVERY:
            self._answers[req.tag] = ans
        elif req.wanted and req.seq == self._wanted:
            self._answer = ans
        self._cv.notify_all()

    def _serve_here(self) -> None:
        while True:
            with self._cv:
                req = self._next()
            if req is None:
                return
            ans = self._compute(req)
            with self._cv:
                self._finish(req, ans)

    def _run(self) -> None:
        rt.run_below_loop()
        while True:
            with self._cv:
                while not self._stop and self._request is None and not self._backlog:
                    self._cv.wait()
                if self._stop:
                    return
                req = self._next()
            self._gate.wait()
            if self._stop:
                return
            ans = self._compute(req)
            with self._cv:
                self._finish(req, ans)

    def _report(self, t_s: float, event: EventDef | None, **args) -> None:
        if self.events is not None and event is not None:
            self.events.emit(t_s, event, **args)
