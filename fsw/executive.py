"""The executive: rate groups driven by one base tick (docs/fsw/index.md, Executive).

After F Prime's ActiveRateGroup: each rate group is an integer divisor of the base tick
(RG1 every tick = control, RG2 every 0.1 s = 10 Hz, RG3 every 1 s = 1 Hz: divisors 5 and 50
at a 50 Hz base, 20 and 200 at 200 Hz; their periods are parameters in seconds, so a
faster control rate keeps their rates) and calls its tasks in registration order. Two clock sources behind one interface,
``release(k_hint) -> (k, t_release_ns)``:

- ``LockstepClock``: the tick is the arrival of sensor frame k — the caller hands it in;
  the release time is the moment it is handed in (no jitter by definition);
- ``RealTimeClock``: absolute releases t0 + k·period on the monotonic clock (never drift),
  waited for with an absolute clock_nanosleep and an optional final spin; optionally a
  rehearsal shortly before each release (``set_rehearsal``): after a period asleep, the
  interpreter's code and data the control task runs through are out of the caches, and
  running the same code once just before the release brings them back.

Every cycle records its release, its release jitter (start − scheduled release), the
compute time of each task and in total, and whether it finished before its deadline
(release + deadline_ns, by default one period). A late cycle is a cycle slip: counted and
reported as a rate-limited event, never absorbed silently. Statistics live in
preallocated ring buffers; percentiles are computed only when asked (telemetry).
"""
from __future__ import annotations

import heapq
import time
from typing import Callable

import numpy as np

from common.events import EventLog
from common.rt import sleep_until_ns
from interfaces.event_catalogue import EV
from .params import Param

PARAMS = [
    Param("executive.rg2_period_s", 1e-3, 10.0, "s", "RG2 period, a whole number of control periods",
          ground_settable=False),
    Param("executive.rg3_period_s", 1e-3, 100.0, "s", "RG3 period, a whole number of control periods",
          ground_settable=False),
    Param("executive.deadline_frac", 0.05, 1.0, "", "deadline as a fraction of the control period",
          ground_settable=False),
    Param("executive.spin_us", 0.0, 5000.0, "us", "real-time clock: final busy-wait before each release",
          ground_settable=False),
    Param("executive.rehearse_us", 0.0, 5000.0, "us", "real-time clock: the control task rehearsed this long "
          "before each release, then a spin to it (0 = never)", ground_settable=False),
]


def rate_divisor(period_s: float, dt_s: float, name: str = "period") -> int:
    """Control ticks per ``period_s`` at control period ``dt_s``; ValueError unless it is a
    whole number (>= 1) of them."""
    n = period_s / dt_s
    d = int(round(n))
    if d < 1 or abs(n - d) > 1e-6 * max(1.0, n):
        raise ValueError(f"{name} = {period_s:g} s is not a whole number of control periods ({dt_s:g} s)")
    return d


def divisors(params: dict, dt_s: float) -> tuple[int, int, int]:
    """The rate groups' divisors of the base tick (RG1, RG2, RG3) from their periods."""
    return (1, rate_divisor(params["executive.rg2_period_s"], dt_s, "executive.rg2_period_s"),
            rate_divisor(params["executive.rg3_period_s"], dt_s, "executive.rg3_period_s"))


# --------------------------------------------------------------------------- clocks
class LockstepClock:
    """The tick is the arrival of sensor frame k (handed in by the caller)."""

    mode = "lockstep"

    def __init__(self, now_ns: Callable[[], int] = time.monotonic_ns):
        self.now_ns = now_ns
        self.missed = 0
        self._k = -1

    def release(self, k_hint: int | None = None) -> tuple[int, int]:
        k = self._k + 1 if k_hint is None else int(k_hint)
        self._k = k
        return k, self.now_ns()


class RealTimeClock:
    """Releases at t0 + k·period_ns on the monotonic clock.

    ``release`` sleeps (absolute clock_nanosleep) until ``spin_ns`` before the release and
    busy-waits the rest (spin_ns = 0: sleep only). If the caller is already later than a
    whole period behind, the missed releases are skipped (counted in ``missed``) so that
    tick k stays at time t0 + k·period: rate groups keep their phase with time.
    With a rehearsal (``set_rehearsal(fn, lead_ns)``), ``fn()`` runs once before each release
    at release - lead (- spin_ns if that is longer), when the caller is not already past
    that time, and the rest of the lead is spun, not slept (a sleep, however short, lets the
    caches cool again): the lead costs its length of a core every period. Its time falls
    before the release, so the cycle's compute time does not include it (an overrun shows as
    release jitter). The lead is ``lead_ns`` or, when the rehearsal has run longer lately
    (caches cold from other work, a host busy elsewhere), the second longest of the last
    ``LEAD_WINDOW`` rehearsals' durations times ``LEAD_MARGIN``, grown to no more than
    ``LEAD_CAP`` of the period: a fixed lead that the rehearsal outgrows makes every release
    late by the rest. The second longest, not the longest: one rehearsal preempted for
    milliseconds says nothing of the next, and would hold a long spin for the whole window.
    ``now_ns`` and ``sleep_until`` are injectable (tests use a fake clock).
    """

    mode = "realtime"
    LEAD_WINDOW = 32       # rehearsals whose second longest duration sizes the lead
    LEAD_MARGIN = 1.25     # the lead over that duration (its spread from one period to the next)
    LEAD_CAP = 0.25        # the lead's bound, a fraction of the period (it is spun: a core's time)

    def __init__(self, period_ns: int, *, spin_ns: int = 0,
                 now_ns: Callable[[], int] = time.monotonic_ns,
                 sleep_until: Callable[[int], None] | None = None,
                 cpu_ns: Callable[[], int] = time.thread_time_ns):
        if period_ns <= 0 or spin_ns < 0 or spin_ns >= period_ns:
            raise ValueError(f"RealTimeClock: need period_ns > 0 and 0 <= spin_ns < period_ns, "
                             f"got {period_ns}, {spin_ns}")
        self.period_ns = int(period_ns)
        self.spin_ns = int(spin_ns)
        self.now_ns = now_ns
        self.sleep_until = sleep_until or (lambda t: sleep_until_ns(t, now_ns))
        self.t0_ns: int | None = None
        self.missed = 0
        self._k = -1
        self.rehearse: Callable[[], None] | None = None
        self.rehearse_ns = 0
        self.rehearsals = 0        # rehearsals run
        self.rehearsals_skipped = 0   # releases whose rehearsal time had passed already
        self.rehearsal_ns = [0] * self.LEAD_WINDOW    # the last rehearsals' durations (a ring)
        self.lead_ns = 0                 # the lead the next rehearsal starts at
        self.lead_max_ns = 0             # the longest lead taken since set_rehearsal
        # the last release's flight recorder (plain attributes, overwritten each release: no
        # allocation): when the call began (the previous cycle's end), the rehearsal's planned
        # and actual start, its end, the final sleep's target and its wake-up, the return; and
        # this thread's CPU time at the rehearsal's start and end and at the return, so that
        # a late release says whether the thread was off its CPU (explain_late_release)
        self.cpu_ns = cpu_ns
        self.tr_enter = self.tr_reh_target = self.tr_reh_start = self.tr_reh_end = 0
        self.tr_wake_target = self.tr_woke = self.tr_return = 0
        self.tr_cpu_reh_start = self.tr_cpu_reh_end = self.tr_cpu_woke = self.tr_cpu_return = 0

    def set_rehearsal(self, fn: Callable[[], None] | None, lead_ns: int) -> None:
        """Run ``fn()`` ``lead_ns`` before each release (None or lead_ns 0: no rehearsal)."""
        lead_ns = int(lead_ns)
        if not 0 <= lead_ns < self.period_ns:
            raise ValueError(f"RealTimeClock: need 0 <= rehearsal lead < period_ns ({self.period_ns}), got {lead_ns}")
        if fn is not None and not callable(fn):
            raise TypeError("RealTimeClock.set_rehearsal: fn is not callable")
        self.rehearse = fn if lead_ns > 0 else None
        self.rehearse_ns = lead_ns if fn is not None else 0
        self.rehearsal_ns = [0] * self.LEAD_WINDOW
        self.lead_ns = self.lead_max_ns = self.rehearse_ns

    def _size_lead(self, took_ns: int) -> None:
        """Note a rehearsal's duration; the next lead from the last LEAD_WINDOW of them."""
        ring = self.rehearsal_ns
        ring[self.rehearsals % self.LEAD_WINDOW] = took_ns
        second = heapq.nlargest(2, ring)[1]
        grown = min(int(second * self.LEAD_MARGIN), int(self.period_ns * self.LEAD_CAP))
        self.lead_ns = max(self.rehearse_ns, grown)
        if self.lead_ns > self.lead_max_ns:
            self.lead_max_ns = self.lead_ns

    @classmethod
    def from_params(cls, params: dict, period_ns: int, **kw) -> "RealTimeClock":
        """With the final spin of ``executive.spin_us`` (fsw/params.py load_params(PARAMS))."""
        return cls(period_ns, spin_ns=int(round(params["executive.spin_us"] * 1e3)), **kw)

    def start(self, t0_ns: int | None = None, k0: int = 0) -> None:
        """Release k at ``t0_ns`` + k·period (default t0: one period from now); the first
        release is k0 (joining a running plant at its step k0 counts no missed release)."""
        self.t0_ns = self.now_ns() + self.period_ns if t0_ns is None else int(t0_ns)
        self._k = int(k0) - 1

    def release(self, k_hint: int | None = None) -> tuple[int, int]:
        if self.t0_ns is None:
            self.start()
        k = self._k + 1
        t_rel = self.t0_ns + k * self.period_ns
        now = self.now_ns()
        self.tr_enter = now
        self.tr_reh_target = self.tr_reh_start = self.tr_reh_end = 0
        if now >= t_rel + self.period_ns:
            k_now = (now - self.t0_ns) // self.period_ns
            self.missed += k_now - k
            k, t_rel = k_now, self.t0_ns + k_now * self.period_ns
            self.tr_wake_target = self.tr_woke = now
            self.tr_cpu_woke = self.cpu_ns()
        else:
            wake = t_rel - self.spin_ns
            if self.rehearse is not None:
                t_reh = t_rel - max(self.lead_ns, self.spin_ns)
                if now < t_reh:
                    self.tr_reh_target = t_reh
                    t_reh = self.tr_reh_start = self._sleep_to(t_reh, now)
                    self.tr_cpu_reh_start = self.cpu_ns()
                    self.rehearse()
                    now = wake = self.tr_reh_end = self.now_ns()   # no sleep between the rehearsal and the release: spin
                    self.tr_cpu_reh_end = self.cpu_ns()
                    self._size_lead(now - t_reh)
                    self.rehearsals += 1
                else:
                    self.rehearsals_skipped += 1
            self.tr_wake_target = wake
            now = self.tr_woke = self._sleep_to(wake, now)
            self.tr_cpu_woke = self.cpu_ns()
            while now < t_rel:
                now = self.now_ns()
        self.tr_return = now
        self.tr_cpu_return = self.cpu_ns()
        self._k = k
        return k, t_rel

    def _sleep_to(self, t_ns: int, now: int) -> int:
        """Sleep until ``t_ns`` (loop: a signal may end a sleep early); returns the time then."""
        while now < t_ns:
            self.sleep_until(t_ns)
            now = self.now_ns()
        return now


# the causes a late release is put down to (explain_late_release): the first two are the loop's
# own work, the others the host's (or a thread above the loop's priority)
OWN_CAUSES = ("previous_cycle", "rehearsal")
HOST_CAUSES = ("late_wakeup", "preempted", "stalled")


def explain_late_release(clock: RealTimeClock, t_rel: int, t_start: int, carried_host_ns: int = 0) -> dict:
    """Where a late release's time went, from the clock's flight recorder of that release
    [us]: ``previous_cycle`` (the call came after the release: the previous cycle, or what ran
    after it, overran into this one), ``late_wakeup`` (a sleep -- to the rehearsal or to the
    release -- ended after its target: the kernel woke the thread late), ``preempted`` (the
    thread was off its CPU while it rehearsed or spun: the host, or a thread above the
    loop's priority), ``stalled`` (the time from the release -- or the thread's wake-up, if
    later -- to the task's start beyond what the thread was seen off its CPU: only clock reads
    run there, so the rest is a stall the guest does not see, e.g. the hypervisor holding
    the virtual CPU while its thread counts as running), ``rehearsal`` (the rehearsal's own
    CPU time beyond the lead it was given: ours). A previous cycle that overran only because
    the host released it late (``carried_host_ns``, the host's share of that release) hands
    that share on as the host's. ``cause`` is the largest; ``own`` whether it is the loop's
    own work."""
    reh = clock.tr_reh_target != 0
    lead = t_rel - clock.tr_reh_target if reh else 0
    reh_wall = clock.tr_reh_end - clock.tr_reh_start if reh else 0
    reh_cpu = clock.tr_cpu_reh_end - clock.tr_cpu_reh_start if reh else 0
    spin_wall = clock.tr_return - clock.tr_woke
    spin_cpu = clock.tr_cpu_return - clock.tr_cpu_woke
    # a sleep's lateness counts only when the call came before its target (else it never slept);
    # the previous cycle's overrun into this release less what the host took from that cycle
    # (``carried_host_ns``: its own release's host share, a cascade from one late wake-up)
    overrun = max(0, clock.tr_enter - t_rel)
    carried = min(overrun, carried_host_ns)
    slept = clock.tr_enter < clock.tr_wake_target
    spin_off = max(0, spin_wall - spin_cpu)
    shares = {
        "previous_cycle": overrun - carried,
        "late_wakeup": (max(0, clock.tr_reh_start - clock.tr_reh_target)
                        + (max(0, clock.tr_woke - clock.tr_wake_target) if slept else 0) + carried),
        "preempted": max(0, reh_wall - reh_cpu) + spin_off,
        "stalled": max(0, t_start - max(t_rel, clock.tr_woke) - spin_off),
        "rehearsal": max(0, reh_cpu - lead),
    }
    cause = max(shares, key=shares.get)
    if shares[cause] == 0:
        cause = "other"
    out = {"jitter_us": (t_start - t_rel) / 1e3, "cause": cause, "own": cause in OWN_CAUSES,
           "enter_us": (clock.tr_enter - t_rel) / 1e3, "lead_us": lead / 1e3,
           "rehearsal_took_us": reh_wall / 1e3, "rehearsal_cpu_us": reh_cpu / 1e3}
    out.update({f"{name}_us": v / 1e3 for name, v in shares.items()})
    return out


# --------------------------------------------------------------------------- statistics
class TimingStats:
    """Ring buffers of the last ``capacity`` cycles (preallocated), totals since start."""

    def __init__(self, capacity: int, task_names: list[str]):
        if capacity < 1:
            raise ValueError("TimingStats: capacity must be >= 1")
        self.capacity = capacity
        self.task_names = list(task_names)
        self.k = np.zeros(capacity, np.int64)
        self.t_release_ns = np.zeros(capacity, np.int64)
        self.jitter_ns = np.zeros(capacity, np.int64)
        self.compute_ns = np.zeros(capacity, np.int64)
        self.slip = np.zeros(capacity, bool)
        self.task_ns = np.full((capacity, len(task_names)), -1, np.int64)   # -1: not run
        self.n = 0           # cycles recorded since start

    def _filled(self, a: np.ndarray) -> np.ndarray:
        return a[: min(self.n, self.capacity)]

    def percentiles(self, field: str, qs=(50, 99)) -> dict[str, float]:
        """p50 / p99 / max of 'jitter_ns' or 'compute_ns' over the ring (NaN when empty)."""
        a = self._filled(getattr(self, field))
        if a.size == 0:
            return {**{f"p{q}": float("nan") for q in qs}, "max": float("nan")}
        out = {f"p{q}": float(np.percentile(a, q)) for q in qs}
        out["max"] = float(a.max())
        return out

    def task_percentiles(self, name: str, qs=(50, 99)) -> dict[str, float]:
        col = self._filled(self.task_ns)[:, self.task_names.index(name)]
        col = col[col >= 0]
        if col.size == 0:
            return {**{f"p{q}": float("nan") for q in qs}, "max": float("nan"), "runs": 0}
        out = {f"p{q}": float(np.percentile(col, q)) for q in qs}
        out.update(max=float(col.max()), runs=int(col.size))
        return out


# --------------------------------------------------------------------------- executive
class Cycle:
    """What a task is given: the base tick k, its release time, and (lockstep) the frame.
    One object, reused every cycle."""

    __slots__ = ("k", "t_release_ns", "t_start_ns", "frame")

    def __init__(self):
        self.k, self.t_release_ns, self.t_start_ns, self.frame = -1, 0, 0, None


def own_slips(records: list[dict], period_us: float, last_k: int | None = None) -> list[dict]:
    """The slip records the FSW's own work explains (``slip_is_own``). With ``last_k`` (the
    plant's last step), a slip after it is no one's deadline: the plant had gone (its leaving
    costs Zenoh's threads, one priority above the loop, time the loop cannot use)."""
    return [r for r in records if (last_k is None or r["k"] <= last_k) and slip_is_own(r, period_us)]


def slip_is_own(r: dict, period_us: float) -> bool:
    """Whether a slip record is the FSW's own work rather than the host's.

    The host's when the time the host took covers the cycle's lateness (``_host_explains``):
    released on time, its frame on time and its CPU throughout, the cycle would have met its
    deadline. Otherwise, a record with the release's flight recorder (``release_host_us``: the
    share of its release jitter the host took, a late wake-up or preemption; the rest was the
    loop's own, a rehearsal or the previous cycle running into the release) is the loop's own.
    Without one (older records), a late release is the host's unless the cycle's tasks still
    took half the period or more."""
    if _host_explains(r):
        return False
    if "release_host_us" in r:
        return True
    return r["cause"] != "late_release" or sum(r["tasks_us"].values()) >= 0.5 * period_us


def _host_explains(r: dict) -> bool:
    """The host's time in a slip record covers its lateness: the release jitter the host took
    (``release_host_us``, else all of it), the time the loop's thread was off its CPU after the
    release (``off_cpu_us``, the process shell's from taking the frame; else the executive's
    ``compute_off_cpu_us`` over the tasks) and the input task (the wait for the plant's frame)."""
    off = r.get("off_cpu_us", r.get("compute_off_cpu_us"))
    if off is None or "late_us" not in r:
        return False
    release = r.get("release_host_us", r.get("jitter_us", 0.0))
    return release + off + r["tasks_us"].get("input", 0.0) >= r["late_us"]


class Executive:
    """Rate groups over one base tick.

    ``add(group, name, fn)`` registers ``fn(cycle)`` in rate group 1, 2 or 3 (in call
    order); ``tick(frame, k)`` runs one base tick (lockstep: now; real time: at the next
    release); ``run(n_cycles, should_stop)`` loops ticks. Task exceptions are caught,
    counted and reported (rate-limited ERROR event) so one bad task does not stop the
    loop, unless ``catch_task_errors=False``. A late cycle is counted, reported (event naming
    its longest task) and, for the first ``SLIP_RECORDS``, kept in ``slip_records`` with its
    release jitter, every task's time and its cause: "late_release" when the loop started
    late by more than it then computed, else "overrun".
    """

    SLIP_RECORDS = 32
    LATE_RECORDS = 64            # late releases kept with their flight recorder's breakdown
    LATE_RELEASE_NS = 200_000    # a release later than this is explained (explain_late_release)

    def __init__(self, period_ns: int, clock: LockstepClock | RealTimeClock,
                 divisors: tuple[int, ...] = (1, 5, 50), *, events: EventLog | None = None,
                 deadline_ns: int | None = None, history: int = 4096,
                 catch_task_errors: bool = True):
        if period_ns <= 0:
            raise ValueError(f"Executive: period_ns must be > 0, got {period_ns}")
        if not divisors or any(int(d) != d or d < 1 for d in divisors):
            raise ValueError(f"Executive: divisors must be integers >= 1, got {divisors}")
        if deadline_ns is not None and deadline_ns <= 0:
            raise ValueError(f"Executive: deadline_ns must be > 0, got {deadline_ns}")
        self.period_ns = int(period_ns)
        self.clock = clock
        self.divisors = tuple(int(d) for d in divisors)
        self.events = events if events is not None else EventLog()
        self.deadline_ns = int(deadline_ns) if deadline_ns is not None else self.period_ns
        self.history = history
        self.catch_task_errors = catch_task_errors
        self._groups: list[list[tuple[int, str, Callable]]] = [[] for _ in self.divisors]
        self._names: list[str] = []
        self.stats: TimingStats | None = None
        self.cycle = Cycle()
        self.cycles = 0
        self.slips = 0
        self.host_slips = 0      # slips the host's time explains (slip_is_own on the executive's evidence)
        self.task_errors = 0
        self.last_slip_k = -1
        # what each of the first SLIP_RECORDS late cycles spent where (a slip is rare: the
        # dict is built only then): the evidence a user needs to find its cause
        self.slip_records: list[dict] = []
        # releases later than LATE_RELEASE_NS (real time): counts by cause, and the first
        # LATE_RECORDS with their breakdown and what the cycle before them ran
        self.late_releases: dict[str, int] = {}
        self.late_records: list[dict] = []
        self._traced = isinstance(clock, RealTimeClock)
        self._host_ns = 0        # the host's share of the last release's jitter (a cascade's start)
        self.event_time: Callable[[], float] | None = None

    @classmethod
    def from_params(cls, params: dict, period_ns: int, clock, **kw) -> "Executive":
        """From validated parameters (fsw/params.py load_params(PARAMS))."""
        return cls(period_ns, clock, divisors(params, period_ns * 1e-9),
                   deadline_ns=int(round(params["executive.deadline_frac"] * period_ns)), **kw)

    def add(self, group: int, name: str, fn: Callable[[Cycle], object]) -> None:
        if self.stats is not None:
            raise RuntimeError("Executive.add: tasks are registered before the first tick")
        if not 1 <= group <= len(self.divisors):
            raise ValueError(f"Executive.add: group must be 1..{len(self.divisors)}, got {group}")
        if name in self._names:
            raise ValueError(f"Executive.add: task name {name!r} already used")
        if not callable(fn):
            raise TypeError(f"Executive.add: task {name!r} is not callable")
        self._groups[group - 1].append((len(self._names), name, fn))
        self._names.append(name)

    def tasks(self) -> list[tuple[int, str]]:
        """(group, name) in execution order."""
        return [(g + 1, name) for g, grp in enumerate(self._groups) for _, name, _ in grp]

    def tick(self, frame=None, k: int | None = None, t_s: float | None = None) -> bool:
        """One base tick. Lockstep: ``frame`` (and its step index ``k``) handed in, run now.
        Real time: wait for the next release. ``t_s``: time stamp of events raised (default:
        the release time). Returns True if the cycle met its deadline."""
        if self.stats is None:
            self.stats = TimingStats(self.history, self._names)
        now_ns = self.clock.now_ns
        missed_before = self.clock.missed
        k, t_rel = self.clock.release(k)
        t_start = now_ns()
        cyc = self.cycle
        cyc.k, cyc.t_release_ns, cyc.t_start_ns, cyc.frame = k, t_rel, t_start, frame

        st = self.stats
        if self._traced:
            if t_start - t_rel > self.LATE_RELEASE_NS:
                self._note_late(k, t_rel, t_start)
            else:
                self._host_ns = 0
        i = st.n % st.capacity
        task_row = st.task_ns[i]
        task_row[:] = -1
        t = t_start
        for g, grp in enumerate(self._groups):
            if k % self.divisors[g]:
                continue
            for idx, name, fn in grp:
                try:
                    fn(cyc)
                except Exception as e:
                    if not self.catch_task_errors:
                        raise
                    self.task_errors += 1
                    self.events.emit(self._t_s(t_s, t_rel), EV.TASK_ERROR, task=name, error=type(e).__name__)
                t_end = now_ns()
                task_row[idx] = t_end - t
                t = t_end
        t_end = t
        late = t_end > t_rel + self.deadline_ns
        st.k[i], st.t_release_ns[i] = k, t_rel
        st.jitter_ns[i], st.compute_ns[i], st.slip[i] = t_start - t_rel, t_end - t_start, late
        st.n += 1
        self.cycles += 1
        if self.clock.missed != missed_before:
            n = self.clock.missed - missed_before
            self.events.emit(self._t_s(t_s, t_rel), EV.RELEASE_MISSED, count=n, tick=k)
        if late:
            self.slips += 1
            self.last_slip_k = k
            worst = int(np.argmax(task_row))
            # the larger share decides: the loop started late (the CPU was elsewhere: a
            # higher-priority thread, the host) or its own tasks ran long
            cause = "late_release" if t_start - t_rel > t_end - t_start else "overrun"
            rec = {"k": int(k), "cause": cause, "late_us": (t_end - t_rel - self.deadline_ns) / 1e3,
                   "jitter_us": (t_start - t_rel) / 1e3,
                   "tasks_us": {name: task_row[j] / 1e3 for j, name in enumerate(self._names)
                                if task_row[j] >= 0}}
            if self._traced:
                # what of the lateness the host took: its share of the release's jitter (the
                # flight recorder's) and the thread's time off its CPU over the tasks
                clock = self.clock
                rec["release_host_us"] = min(rec["jitter_us"], self._host_ns / 1e3)
                rec["compute_off_cpu_us"] = max(0, (t_end - t_start) - (clock.cpu_ns() - clock.tr_cpu_return)) / 1e3
                if not slip_is_own(rec, self.period_ns / 1e3):
                    self.host_slips += 1
            if len(self.slip_records) < self.SLIP_RECORDS:
                self.slip_records.append(rec)
            self.events.emit(self._t_s(t_s, t_rel), EV.CYCLE_SLIP, tick=k, took_ms=(t_end - t_rel) / 1e6,
                             deadline_ms=self.deadline_ns / 1e6, task=self._names[worst], task_ms=task_row[worst] / 1e6)
        return not late

    def _note_late(self, k: int, t_rel: int, t_start: int) -> None:
        """A late release (rare: the dict is built only then): counted by cause, and the first
        LATE_RECORDS kept with the previous cycle's tasks and the slips' kind of evidence."""
        rec = explain_late_release(self.clock, t_rel, t_start, self._host_ns)
        self._host_ns = int(1e3 * min(rec["jitter_us"], sum(rec[f"{c}_us"] for c in HOST_CAUSES)))
        self.late_releases[rec["cause"]] = self.late_releases.get(rec["cause"], 0) + 1
        if len(self.late_records) < self.LATE_RECORDS:
            st = self.stats
            rec["k"] = int(k)
            if st.n:
                prev = st.task_ns[(st.n - 1) % st.capacity]
                rec["previous_tasks_us"] = {name: prev[j] / 1e3 for j, name in enumerate(self._names) if prev[j] >= 0}
            self.late_records.append(rec)

    def _t_s(self, t_s: float | None, t_rel_ns: int) -> float:
        """The time stamp of an event: the tick's own, else the owner's clock (``event_time``,
        e.g. the FSW's mission time), else the release time."""
        if t_s is not None:
            return t_s
        return self.event_time() if self.event_time is not None else t_rel_ns * 1e-9

    def run(self, n_cycles: int | None = None, should_stop: Callable[[], bool] | None = None,
            on_slack: Callable[[int], None] | None = None) -> int:
        """Real-time loop: tick until ``n_cycles`` or ``should_stop()``; returns cycles run.
        ``on_slack(ns_left)`` runs after each on-time cycle with the time left before the
        next release (e.g. common/rt.py's collect_in_slack)."""
        if isinstance(self.clock, LockstepClock):
            raise RuntimeError("Executive.run: a lockstep executive is ticked by its frames")
        n = 0
        while (n_cycles is None or n < n_cycles) and not (should_stop and should_stop()):
            on_time = self.tick()
            n += 1
            if on_slack is not None and on_time:
                left = self.cycle.t_release_ns + self.period_ns - self.clock.now_ns()
                if left > 0:
                    on_slack(left)
        return n

    @property
    def missed_releases(self) -> int:
        return self.clock.missed

    def telemetry(self) -> dict:
        """Loop timing for telemetry: counts, and p50/p99/max of jitter and compute [us]."""
        st = self.stats
        out = {"cycles": self.cycles, "slips": self.slips, "host_slips": self.host_slips,
               "missed_releases": self.clock.missed,
               "task_errors": self.task_errors, "mode": self.clock.mode}
        if self.slip_records:
            out["slip_records"] = self.slip_records
        if self._traced:
            out["late_releases"] = dict(self.late_releases)
            out["late_release_us"] = self.LATE_RELEASE_NS / 1e3
            if self.late_records:
                out["late_records"] = self.late_records
        if st is None:
            return out
        for field in ("jitter_ns", "compute_ns"):
            for q, v in st.percentiles(field).items():
                out[f"{field[:-3]}_{q}_us"] = v / 1e3
        return out
