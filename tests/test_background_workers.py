"""The FSW's background work -- the background-job runner (fsw/jobs.py ``BackgroundJob``), the
controllability LP it runs for the authority supervisor (fsw/authority.py) and the
predictor-corrector's correction (fsw/guidance/npc.py ``EntryGuidance``) -- judged by its
logic, not by the host: each worker's job is injected (held on an Event the test controls,
or made to keep the GIL for a known time with a C call). That no job keeps the loop from
the GIL a control period by computing is judged in the job's own CPU time per C call
(tests/threadtime.py LongestCCall), the same on any host. The four blocked-time tests (what
the loop slept beside a job, BlockedMeter) also see a job that keeps the GIL while it
sleeps; they judge the wall clock (marked ``timing``), with the loop SCHED_FIFO as in the
real-time FSW and the jobs one priority below it, so other load on the machine cannot sit
in the loop's waits (they need root).

The rules proven here:
- the runner: the newest request wins (a request not yet started is replaced, an answer to an
  overtaken request is never handed over; with every answer kept, each is kept by its tag);
  in place the answer is there when ``submit`` returns; awaited, ``take`` at the due step
  waits for it; in real time an answer missing at its due step is one overrun (event) and is
  handed over by the first ``take`` after it arrives; a request while busy can be refused and
  counted; a job that raises is a counted fault and an event, and the runner keeps serving;
  warm-up discards its answer; close ends the thread;
- the loop never waits on a worker: it keeps cycling while a job is held, no C call of a
  job computes for a control period, and the predictor's kernels are built nogil;
- LP (real time): the FSW flies on while it solves, and its answer is applied by the first
  control cycle after it is ready (batch and lockstep: solved in place, on no thread);
- guidance (real time): the answer is applied at its due step (release + apply_delay_s),
  never earlier; not there when due is one overrun (event; the previous answer's profile
  stays); a cycle released while it still computes is skipped (an overrun, its event
  throttled with the overrun's, no new job);
  the late answer is applied by the first control cycle after it arrives, stamped with its
  release time, and its predicted time to deploy is aged from that release, not from the
  cycle it missed;
- guidance (batch and lockstep): the loop waits for the answer at its due step, so a run
  is the same bit for bit however slow the correction is.
"""
from __future__ import annotations

import math
import sys
import threading
import time

import numpy as np
import pytest

from common import rt
from common.events import EventLog
from interfaces.event_catalogue import EV
from common.model import load_scenario
from ellipsled import batch
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware
from fsw.health import JetHealth
from fsw.jobs import AWAITED, EVERY, IN_PLACE, REALTIME, BackgroundJob
from fsw.topology import Topology
from sim.plant import Plant
from tests import threadtime
from tests.threadtime import BlockedMeter, LongestCCall, gil_keeping_burn

PERIOD_NS = 20_000_000                       # the 50 Hz control period
GIL_HOLD_S = 1.5 * PERIOD_NS * 1e-9          # a job that keeps the GIL this long must be caught
SANITY_S = 30.0                              # only against a hang: no outcome depends on it
PACE_S = 0.001                               # wall time a measured flight's step takes: 20x real time


def _until(cond) -> None:
    """Wait for a worker's hand-over (the workers signal nothing the test could wait on)."""
    t_end = time.monotonic() + SANITY_S
    while not cond():
        assert time.monotonic() < t_end, "a worker never answered"
        time.sleep(0.001)


class _Flight:
    """A FlightSoftware built for real time (background workers on, warmed as before the first
    real-time cycle) flown by the plant in this thread through its topology, one tick a step:
    the rate groups as the real-time FSW runs them, with every frame on time."""

    def __init__(self, scenario: str):
        scn = load_scenario(scenario)
        self.plant = Plant(scn, scn.seed)
        self.fsw = FlightSoftware(scn, EventLog(), realtime=True)
        self.topo = Topology(self.fsw, LockstepClock())
        self.frame = self.plant.sensors
        assert self.fsw.warm_background()

    @property
    def t_next(self) -> float:
        """Time of the step the next ``step`` flies [s]."""
        return float(self.frame["t_ns"]) * 1e-9

    def step(self) -> None:
        self.topo.tick(self.frame)
        self.frame = self.plant.step(self.topo.u)

    def close(self) -> None:
        self.fsw.close()


def _worst_blocked(fl: _Flight, done, between=None, job: BackgroundJob | None = None) -> int:
    """The longest time one loop iteration (``between()``, a tick and the plant's step) slept
    [ns], with the flight's GIL switch interval, flying until ``done()``. Every iteration is
    measured, back to back: a wait for the GIL always falls inside one of them.

    The flight is paced at PACE_S of wall time a step, spun on the CPU (a spin holds the GIL as
    the tick does and gives it up when a job asks, so a wait for it still falls inside an
    iteration): unpaced, the loop flies mission time as fast as the host runs it, and a
    correction slower than the rest of the flight on a slow host never lands in it."""
    switch = sys.getswitchinterval()
    sys.setswitchinterval(rt.GIL_SWITCH_S)               # as the real-time FSW runs
    meter = BlockedMeter()
    worst = 0
    t_next = time.perf_counter()
    t_end = time.monotonic() + SANITY_S
    try:
        while not done():
            assert time.monotonic() < t_end, (
                "the workers never answered"
                + ("" if job is None else f" ({job.name}: released {job.released}, skipped {job.skipped}, "
                   f"late {job.late}, faults {job.faults}, busy {job.busy}; mission t {fl.t_next:.1f} s)"))
            t_next += PACE_S
            while time.perf_counter() < t_next:
                pass
            if between is not None:
                between()
            fl.step()
            worst = max(worst, meter.lap())
    finally:
        sys.setswitchinterval(switch)
        meter.close()
    return worst


# ---------------------------------------------------------------- the controllability LP
def _worst_wait_on_the_lp(hold_s: float = 0.0) -> int:
    """A real-time FSW flies with seven jets stuck on while the LP is asked again every 10th
    step it is not busy (as RG3 re-assesses), until four answers asked in the measured flight
    are applied (so every solve ran inside it). Returns the longest time one loop iteration
    slept [ns]. ``hold_s``: each solve first holds the GIL that long, the fault this
    measurement exists to catch."""
    with threadtime.as_the_realtime_loop():
        return _measure_the_loop_beside_the_lp(hold_s)


def _measure_the_loop_beside_the_lp(hold_s: float) -> int:
    fl = _Flight("nominal")
    f = fl.fsw
    f.authority.lp.fn = threadtime.holding_the_gil_first(f.authority.lp.fn, hold_s)
    f.fdir.health_active = JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10])
    f.health_changed()
    assert f.allocator.wait_idle(SANITY_S)               # the tables are not what is measured
    _until(lambda: f.authority.lp.ready)
    fl.step()                                            # the health's answer applied: now measure
    assert f.controllability is not None and not f.authority.lp.busy
    applied = [0, f.controllability]

    def ask_again():
        if f.controllability is not applied[1]:
            applied[0] += 1
            applied[1] = f.controllability
        if fl.plant.k % 10 == 0 and not (f.authority.lp.busy or f.authority.lp.ready):
            f.authority.assess(f.t_s, periodic=True)
    try:
        return _worst_blocked(fl, lambda: applied[0] >= 4, ask_again, f.authority.lp)
    finally:
        fl.close()


@threadtime.loop_timing
def test_the_loop_never_waits_a_control_period_on_the_lp():
    worst = _worst_wait_on_the_lp()
    assert worst < PERIOD_NS, f"the loop waited {worst / 1e6:.2f} ms on the LP"


@threadtime.loop_timing
def test_an_lp_job_that_holds_the_gil_for_a_control_period_is_caught():
    """The check above is not blind: an LP job that keeps the GIL 1.5 periods is measured."""
    worst = _worst_wait_on_the_lp(GIL_HOLD_S)
    assert worst >= PERIOD_NS, f"a 30-ms hold measured as {worst / 1e6:.2f} ms"


def _longest_c_call_of_the_lp(burn=None) -> LongestCCall:
    """The LP asked for three healths (seven stuck on; no authority one way; the campaign's
    four failed and two stuck on) on a real-time FSW, each answer applied by a cycle; every
    job profiled. ``burn()``: called first in each job."""
    fl = _Flight("nominal")
    f = fl.fsw
    meter = LongestCCall()
    solve = f.authority.lp.fn

    def job(*args):
        if burn is not None:
            burn()
        return solve(*args)
    f.authority.lp.fn = meter.wrap(job)
    try:
        for h in (JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10]),
                  JetHealth.of(failed_off=[6, 16], stuck_on=[15], degraded=[(7, .5), (13, .5)]),
                  JetHealth.of(failed_off=[1, 2, 10, 16], stuck_on=[6, 12])):
            before = f.controllability
            f.fdir.health_active = h
            f.health_changed()
            _until(lambda: f.authority.lp.ready)
            fl.step()
            assert f.controllability is not before
    finally:
        fl.close()
    return meter


def test_no_lp_solve_keeps_the_gil_for_a_control_period():
    """Host-independent: no C call of the LP's job burns a control period of CPU, so none can
    keep the loop from the GIL that long by computing."""
    m = _longest_c_call_of_the_lp()
    assert 0 < m.worst_ns < PERIOD_NS, f"{m.worst_name} ran {m.worst_ns / 1e6:.2f} ms of CPU in one call"


def test_an_lp_job_that_computes_a_control_period_in_one_c_call_is_seen():
    """The check above is not blind: a job that first burns 1.5 periods in one C call."""
    m = _longest_c_call_of_the_lp(gil_keeping_burn(1.5 * PERIOD_NS))
    assert m.worst_ns >= PERIOD_NS and m.worst_name == "pow"


def test_the_fsw_flies_on_while_the_lp_is_held_and_applies_its_answer_at_the_next_cycle():
    fl = _Flight("nominal")
    f = fl.fsw
    go = threading.Event()
    solve = f.authority.lp.fn

    def held(*args):
        go.wait(SANITY_S)
        return solve(*args)
    f.authority.lp.fn = held
    try:
        f.fdir.health_active = JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10])
        f.health_changed()
        cycles = f.cycles
        for _ in range(100):                             # two seconds of flight with no answer
            fl.step()
            assert f.controllability is None
        assert f.cycles == cycles + 100
        go.set()
        _until(lambda: f.authority.lp.ready)
        assert f.controllability is None                 # ready, but only a cycle applies it
        fl.step()
        assert f.controllability is not None and not (f.authority.lp.busy or f.authority.lp.ready)
        assert any(e.code == "controllability" and e.t_s == f.t_s for e in f.events.history)
    finally:
        go.set()
        fl.close()


class _TaggedJobs:
    """An LP worker's job that returns its tag; a tag starting "held" waits for ``go(tag)``.
    ``started(tag)`` waits until the worker has begun that job."""

    def __init__(self):
        self._go: dict = {}
        self._started: dict = {}
        self.calls: list = []

    def _events(self, tag):
        return (self._go.setdefault(tag, threading.Event()), self._started.setdefault(tag, threading.Event()))

    def __call__(self, tag):
        go, started = self._events(tag)
        self.calls.append(tag)
        started.set()
        if tag.startswith("held"):
            go.wait(SANITY_S)
        return tag

    def go(self, tag) -> None:
        self._events(tag)[0].set()

    def started(self, tag) -> None:
        assert self._events(tag)[1].wait(SANITY_S), f"job {tag} never started"

    def release_all(self) -> None:
        for ev in self._go.values():
            ev.set()


def test_batch_and_lockstep_solve_the_lp_in_place_without_a_thread():
    f = FlightSoftware(load_scenario("nominal"))
    try:
        f.fdir.health_active = JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10])
        f.health_changed()
        assert f.controllability is not None
        assert f.authority.lp.mode == IN_PLACE and not f.authority.lp.alive
    finally:
        f.close()


# ---------------------------------------------------------------- the runner
@pytest.fixture
def jobs():
    """Tagged jobs (``_TaggedJobs``); every one still held is let go at the end."""
    tagged = _TaggedJobs()
    yield tagged
    tagged.release_all()


@pytest.fixture
def runner(jobs):
    """``runner(fn=jobs, mode=REALTIME, **kw)``: a BackgroundJob named "test-job", closed at the end."""
    made = []

    def make(fn=jobs, mode=REALTIME, **kw) -> BackgroundJob:
        made.append(BackgroundJob(fn, "test-job", mode=mode, **kw))
        return made[-1]
    yield make
    jobs.release_all()
    for w in made:
        w.close()


def test_a_request_overtaken_while_computing_is_dropped_and_the_newest_answered(jobs, runner):
    w = runner()
    w.submit("held-old", tag=1.0)
    jobs.started("held-old")
    w.submit("held-new", tag=2.0)                        # a newer request while the old one computes
    jobs.go("held-old")
    jobs.started("held-new")                             # the old one has finished: its answer ...
    assert not w.ready                                   # ... was dropped
    jobs.go("held-new")
    _until(lambda: w.ready)
    ans = w.take()
    assert (ans.tag, ans.value) == (2.0, "held-new")
    assert jobs.calls == ["held-old", "held-new"] and not w.busy and not w.ready


def test_an_answer_not_yet_taken_is_dropped_by_a_newer_request(jobs, runner):
    w = runner()
    w.submit("old", tag=1.0)
    _until(lambda: w.ready)                              # answered, not yet taken ...
    w.submit("held-new", tag=2.0)                        # ... when a newer request comes
    assert not w.ready                                   # the old answer is not there to take
    jobs.go("held-new")
    _until(lambda: w.ready)
    assert w.take().tag == 2.0


def test_a_request_not_yet_started_is_replaced_by_a_newer_one(jobs, runner):
    w = runner()
    w.submit("held-first")
    jobs.started("held-first")
    w.submit("second")                                   # waits behind the first ...
    w.submit("third")                                    # ... and is replaced
    jobs.go("held-first")
    _until(lambda: w.ready)
    assert w.take().value == "third" and jobs.calls == ["held-first", "third"]
    assert w.released == 3


def _a_request_behind_a_held_backlog(jobs, runner) -> BackgroundJob:
    """A runner keeping every answer: computing held-b1 of its backlog (b1, b2), with r submitted."""
    w = runner(keep=EVERY)
    w.queue([("b1", ("held-b1",)), ("b2", ("b2",))])
    jobs.started("held-b1")
    w.submit("r", tag="r")
    return w


def test_every_answer_is_kept_by_its_tag_and_requests_go_before_the_backlog(jobs, runner):
    w = _a_request_behind_a_held_backlog(jobs, runner)
    jobs.go("held-b1")                                   # then r, before the rest of the backlog
    assert w.wait_idle(SANITY_S)
    assert jobs.calls == ["held-b1", "r", "b2"]
    assert w.pop("r").value == "r" and w.pop("r") is None
    assert [(a.tag, a.value) for a in w.pop_all()] == [("b1", "held-b1"), ("b2", "b2")]


def test_cancel_drops_the_waiting_request_and_the_backlog(jobs, runner):
    w = _a_request_behind_a_held_backlog(jobs, runner)
    w.cancel()
    jobs.go("held-b1")                                   # the running one finishes and is kept
    assert w.wait_idle(SANITY_S)
    assert jobs.calls == ["held-b1"] and [a.tag for a in w.pop_all()] == ["b1"]


def test_in_place_the_answer_is_there_when_submit_returns_and_no_thread_runs(runner):
    callers = []

    def job(x):
        callers.append(threading.current_thread())
        return 2 * x
    w = runner(job, mode=IN_PLACE)
    w.submit(21, tag="t", t_s=3.0)
    assert not w.alive and callers == [threading.current_thread()]
    ans = w.take(3.0)
    assert (ans.value, ans.tag, ans.t_s) == (42, "t", 3.0) and w.take(3.0) is None
    assert w.warm(1) and callers == [threading.current_thread()]     # nothing to warm in place


def test_awaited_the_answer_is_not_handed_over_before_its_due_step_and_waited_for_at_it(jobs, runner):
    w = runner(mode=AWAITED)
    w.submit("held", tag=1, t_s=0.0, due_t=0.5)
    jobs.started("held")
    assert w.take(0.48) is None                          # not due: returns at once, not late
    threading.Timer(0.05, jobs.go, ("held",)).start()
    ans = w.take(0.5)                                    # due: waits for it
    assert ans.value == "held" and w.late == 0 and w.due_t == math.inf


def test_in_real_time_an_answer_missing_at_its_due_step_is_one_overrun_and_taken_when_it_arrives(jobs, runner):
    events = EventLog()
    w = runner(events=events, overrun_event=EV.GUIDANCE_OVERRUN)
    w.submit("held", tag=-1.0, t_s=1.0, due_t=1.5)
    assert w.take(1.48) is None and w.late == 0
    assert w.take(1.5) is None and w.late == 1 and w.overdue
    assert w.take(1.52) is None and w.late == 1           # counted once
    [ev] = [e for e in events.history if e.code == "guidance_overrun"]
    assert (ev.t_s, ev.text, ev.source) == (1.5, "GUIDANCE CYCLE OVERRUN: COMMAND KEPT", "guidance")
    jobs.go("held")
    _until(lambda: w.ready)
    ans = w.take(1.54)                                   # the first take after it arrived
    assert (ans.value, ans.tag, ans.t_s) == ("held", -1.0, 1.0)
    assert not w.overdue and w.due_t == math.inf and w.late == 1


def test_a_request_while_busy_is_refused_and_counted_when_the_job_keeps_its_cadence(jobs, runner):
    events = EventLog()
    w = runner(skip_while_busy=True, events=events, overrun_event=EV.GUIDANCE_OVERRUN)
    assert w.submit("held", t_s=1.0, due_t=1.5)
    jobs.started("held")
    assert not w.submit("next", t_s=2.0, due_t=2.5)
    assert (w.released, w.skipped, w.due_t) == (1, 1, 1.5)
    [ev] = [e for e in events.history if e.code == "guidance_overrun"]
    assert (ev.t_s, ev.text) == (2.0, "GUIDANCE CYCLE SKIPPED: PREVIOUS STILL RUNNING")
    jobs.go("held")
    _until(lambda: w.ready)
    assert w.take(2.0).value == "held" and jobs.calls == ["held"]


def test_awaited_a_request_while_busy_waits_for_the_previous_one_and_is_taken_however_slow_it_ran(jobs, runner):
    """Batch and lockstep: whether the previous request still computes depends on the host,
    so it must not decide whether this one is refused -- the previous one finishes first."""
    w = runner(mode=AWAITED, skip_while_busy=True)
    assert w.submit("held", t_s=1.0, due_t=1.5)
    jobs.started("held")
    threading.Timer(0.05, jobs.go, ("held",)).start()
    assert w.submit("next", t_s=2.0, due_t=2.5)          # waits for "held", then goes
    assert (w.released, w.skipped) == (2, 0)
    jobs.go("next")
    assert w.take(2.5).value == "next" and jobs.calls == ["held", "next"]


@pytest.mark.parametrize("mode", [IN_PLACE, REALTIME])
def test_a_job_that_raises_is_a_counted_fault_and_an_event_and_the_runner_serves_on(runner, mode):
    def job(x):
        if x == "bad":
            raise ValueError("no answer")
        return x
    events = EventLog()
    w = runner(job, mode=mode, events=events, fault_event=EV.CONTROLLABILITY_FAULT)
    w.submit("bad", t_s=4.0)
    assert w.wait_idle(SANITY_S) and w.faults == 1
    assert w.take(5.0) is None                           # reported, not handed over
    [ev] = [e for e in events.history if e.code == "controllability_fault"]
    assert (ev.t_s, ev.text) == (4.0, "CONTROLLABILITY FAULT: ValueError: no answer")
    w.submit("good", t_s=6.0)
    assert w.wait_idle(SANITY_S) and w.take(6.0).value == "good" and w.faults == 1


def test_warm_up_runs_the_job_on_its_own_thread_and_discards_the_answer(runner):
    threads = []

    def job(x):
        threads.append(threading.current_thread().name)
        return x
    w = runner(job)
    assert w.warm("x", timeout_s=SANITY_S)
    assert threads == ["test-job"] and not w.ready and w.take() is None and w.released == 0
    w.close()
    assert not w.alive


# ---------------------------------------------------------------- the guidance correction
def _guided(job=None) -> _Flight:
    """Guided flight; ``job(correct, *args)`` replaces the correction when given."""
    fl = _Flight("guided-nominal")
    if job is not None:
        correct = fl.fsw.entry.job.fn
        fl.fsw.entry.job.fn = lambda *a: job(correct, *a)
    return fl


def _worst_wait_on_the_guidance(hold_s: float = 0.0) -> int:
    """Real-time flight from the first guidance release until three answers are applied (each
    computed inside the measured flight). Returns the longest time one loop iteration slept
    [ns]. ``hold_s``: each correction first holds the GIL that long."""
    holding_the_gil = threadtime.holding_the_gil_first(lambda correct, *a: correct(*a), hold_s)
    with threadtime.as_the_realtime_loop():
        fl = _guided(holding_the_gil)
        try:
            return _worst_blocked(fl, lambda: fl.fsw.entry.cycles >= 3, job=fl.fsw.entry.job)
        finally:
            fl.close()


@threadtime.loop_timing
def test_the_loop_never_waits_a_control_period_on_the_guidance():
    worst = _worst_wait_on_the_guidance()
    assert worst < PERIOD_NS, f"the loop waited {worst / 1e6:.2f} ms on the guidance"


@threadtime.loop_timing
def test_a_guidance_job_that_holds_the_gil_for_a_control_period_is_caught():
    """The check above is not blind: a correction that keeps the GIL 1.5 periods is measured."""
    worst = _worst_wait_on_the_guidance(GIL_HOLD_S)
    assert worst >= PERIOD_NS, f"a 30-ms hold measured as {worst / 1e6:.2f} ms"


def _longest_c_call_of_the_guidance(burn=None) -> LongestCCall:
    """Three corrections of a real-time guided flight, each profiled; ``burn()`` first in each."""
    meter = LongestCCall()

    def job(correct, *a):
        if burn is not None:
            burn()
        return correct(*a)
    fl = _guided(job)
    eg = fl.fsw.entry
    eg.job.fn = meter.wrap(eg.job.fn)
    try:
        t_end = time.monotonic() + SANITY_S
        while eg.cycles < 3:
            assert time.monotonic() < t_end, "the guidance never answered"
            fl.step()
    finally:
        fl.close()
    return meter


def test_no_correction_keeps_the_gil_for_a_control_period():
    """Host-independent: no C call of the correction burns a control period of CPU."""
    m = _longest_c_call_of_the_guidance()
    assert 0 < m.worst_ns < PERIOD_NS, f"{m.worst_name} ran {m.worst_ns / 1e6:.2f} ms of CPU in one call"


def test_a_correction_that_computes_a_control_period_in_one_c_call_is_seen():
    m = _longest_c_call_of_the_guidance(gil_keeping_burn(1.5 * PERIOD_NS))
    assert m.worst_ns >= PERIOD_NS and m.worst_name == "pow"


def test_the_corrections_compiled_kernels_release_the_gil():
    """The module's promise that the loop runs while the predictor computes: every compiled
    kernel of the guidance's predictor and shaper (fsw/guidance/) is built nogil."""
    from numba.core.registry import CPUDispatcher
    from fsw.guidance import predictor, shaper
    kernels = [v for m in (predictor, shaper) for v in vars(m).values() if isinstance(v, CPUDispatcher)]
    assert len(kernels) >= 8
    assert [k.py_func.__name__ for k in kernels if not k.targetoptions.get("nogil")] == []


def test_a_guidance_answer_is_applied_at_its_due_step_not_before():
    fl = _guided()
    eg = fl.fsw.entry
    try:
        fl.step()                                        # t = 0: the first cycle is released
        t_rel, due = eg._t_cycle, eg.job.due_t
        assert due == pytest.approx(t_rel + eg.apply_delay_s)
        assert eg.job.wait_idle(SANITY_S)                   # the answer is there long before it is due
        while fl.t_next < due:
            fl.step()
            assert eg.cycles == 0
        fl.step()
        assert eg.cycles == 1 and eg.t_hist[0] == t_rel and eg.overruns == 0
    finally:
        fl.close()


def _fly_through(fl: _Flight, t_s: float) -> None:
    """Fly up to and including the step at ``t_s``."""
    while fl.t_next < t_s + 0.5 * fl.fsw.dt_s:
        fl.step()


def test_a_guidance_answer_late_for_its_due_step_is_an_overrun_and_the_previous_command_stays():
    go = threading.Event()
    n_jobs = []

    def second_held(correct, *a):
        n_jobs.append(1)
        if len(n_jobs) == 2:
            go.wait(SANITY_S)
        return correct(*a)
    fl = _guided(second_held)
    eg = fl.fsw.entry
    t_go_seen = []                                       # (t, t_go) handed to the lateral decision
    update = eg.lateral.update

    def lateral_update(t_s, V, dpsi, xr_keep, xr_rev, t_go_s, t_rev_s, *held):
        t_go_seen.append((t_s, t_go_s))
        return update(t_s, V, dpsi, xr_keep, xr_rev, t_go_s, t_rev_s, *held)
    eg.lateral.update = lateral_update
    overruns = lambda: [e for e in fl.fsw.events.history if e.code == "guidance_overrun"]  # noqa: E731
    try:
        fl.step()                                        # t = 0: the first release
        assert eg.job.wait_idle(SANITY_S)                   # its answer in before it is due
        _fly_through(fl, 1.0)                            # applied at 0.5; the second released at 1.0
        assert eg.cycles == 1 and eg.overruns == 0
        t_rel, due = eg._t_cycle, eg.job.due_t
        assert t_rel == pytest.approx(1.0)
        kept = (eg.bank0_cmd, eg._line)
        _fly_through(fl, due)                            # the due step, no answer
        assert eg.overruns == 1 and len(overruns()) == 1
        assert overruns()[0].t_s == fl.fsw.t_s and "COMMAND KEPT" in overruns()[0].text
        assert eg.cycles == 1 and (eg.bank0_cmd, eg._line) == kept
        _fly_through(fl, t_rel + 1.0)                    # the next release, still computing
        # counted; its event ("SKIPPED") throttled with the overrun's (one code, 1 s apart)
        assert eg.overruns == 2 and len(overruns()) == 1 and fl.fsw.events._held["guidance_overrun"][0] == 1
        assert eg.job.released == 2 and len(n_jobs) <= 2  # no new job released
        assert eg.cycles == 1 and (eg.bank0_cmd, eg._line) == kept
        go.set()
        assert eg.job.wait_idle(SANITY_S)
        assert eg.cycles == 1                            # arrived; only a control cycle applies it
        fl.step()
        assert eg.cycles == 2 and eg.t_hist[1] == t_rel  # stamped with its release, not now
        assert (eg.bank0_cmd, eg._line) != kept and eg.overruns == 2
        t_go_answer = eg.t_go_s
        assert math.isfinite(t_go_answer)
        _fly_through(fl, t_rel + 2.0)                    # the next cycle's lateral decision
        t_now, t_go = t_go_seen[-1]
        assert t_now == pytest.approx(t_rel + 2.0)
        assert t_go == pytest.approx(t_go_answer - (t_now - t_rel))   # aged from its release
    finally:
        go.set()
        fl.close()


def _batch(monkeypatch=None, setup=None):
    """guided-nominal in batch for 20 s (20 guidance cycles); ``setup(fsw)`` is applied to
    the flying FlightSoftware before its first cycle when given."""
    if setup is not None:
        def fsw_set_up(*a, **k):
            f = FlightSoftware(*a, **k)
            setup(f)
            return f
        monkeypatch.setattr(batch, "FlightSoftware", fsw_set_up)
    return batch.run("guided-nominal", duration_s=20.0, reference=False)


def _correction_held_to_its_due_step(f: FlightSoftware) -> None:
    """Each correction starts computing only once the loop has reached the step its answer
    is due at: as late as an answer can come."""
    eg = f.entry
    due = threading.Event()
    steer, correct = eg.steer, eg.job.fn

    def steer_noting_the_due_step(nav):
        if nav.t_s >= eg.job.due_t:
            due.set()
        steer(nav)

    def held(*a):
        assert due.wait(SANITY_S)
        due.clear()
        return correct(*a)
    eg.steer, eg.job.fn = steer_noting_the_due_step, held


def test_batch_is_the_same_bit_for_bit_when_every_answer_comes_only_at_its_due_step(monkeypatch):
    """Batch (and lockstep, the same FlightSoftware) waits for the answer at its due step,
    so a run whose every answer comes only then is the undelayed run bit for bit."""
    s_ref, h_ref, f_ref = _batch()
    s, h, f = _batch(monkeypatch, _correction_held_to_its_due_step)
    assert f_ref.entry.cycles == f.entry.cycles == 20
    assert f_ref.entry.overruns == f.entry.overruns == 0 and f.entry.faults == 0
    assert h["k"].shape == h_ref["k"].shape
    for name in h.a:
        if name not in ("compute_us", "alloc_us"):       # wall-clock measurements, not trajectory
            assert np.array_equal(h[name], h_ref[name], equal_nan=True), name
    assert s["guidance"]["bank0_final_deg"] == s_ref["guidance"]["bank0_final_deg"]
