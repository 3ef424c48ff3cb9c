"""fsw/executive.py: rate-group order and divisors, deterministic cycle slips with a fake
clock, missed releases, drift-free releases, statistics, task errors."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from common.events import EventLog, Severity
from common.rt import sleep_until_ns
from fsw.executive import PARAMS, Executive, LockstepClock, RealTimeClock, own_slips
from fsw.params import load_params

MS = 1_000_000


class FakeTime:
    """A monotonic clock the test drives: tasks 'cost' time by advancing it."""

    def __init__(self, t0: int = 1_000 * MS, per_read_ns: int = 0):
        self.t = t0
        self.per_read_ns = per_read_ns      # time that passes at each read (for spin loops)
        self.sleeps: list[int] = []
        self.off_cpu = 0        # time passed asleep or stalled: not on the thread's CPU

    def now(self) -> int:
        self.t += self.per_read_ns
        return self.t

    def cpu(self) -> int:
        """The thread's CPU time: all time but the time off its CPU."""
        return self.t - self.off_cpu

    def stall(self, ns: int) -> None:
        """Time passes with the thread off its CPU (the host's)."""
        self.t += ns
        self.off_cpu += ns

    def sleep_until(self, t: int) -> None:
        self.sleeps.append(t)
        self.off_cpu += max(0, t - self.t)
        self.t = max(self.t, t)


def test_rate_groups_run_in_registration_order_at_their_divisors():
    ex = Executive(20 * MS, LockstepClock(), (1, 5, 50))
    log = []
    for g, name in [(1, "nav"), (1, "control"), (2, "fdir_slow"), (3, "heartbeat"), (1, "driver")]:
        ex.add(g, name, lambda c, name=name: log.append((c.k, name)))
    assert ex.tasks() == [(1, "nav"), (1, "control"), (1, "driver"), (2, "fdir_slow"), (3, "heartbeat")]
    for _ in range(120):
        ex.tick()
    expected = []                      # enumerated independently of the executive
    for k in range(120):
        expected += [(k, "nav"), (k, "control"), (k, "driver")]
        if k % 5 == 0:
            expected.append((k, "fdir_slow"))
        if k % 50 == 0:
            expected.append((k, "heartbeat"))
    assert log == expected
    assert sum(1 for _, n in log if n == "fdir_slow") == 24 and sum(1 for _, n in log if n == "heartbeat") == 3
    assert ex.slips == 0 and ex.cycles == 120
    with pytest.raises(RuntimeError):
        ex.add(1, "late", lambda c: None)


def test_lockstep_ticks_follow_the_frame_step_index_and_hand_the_frame_to_tasks():
    ex = Executive(20 * MS, LockstepClock(), (1, 5, 50))
    seen = []
    ex.add(1, "control", lambda c: seen.append(("c", c.k, c.frame)))
    ex.add(2, "slow", lambda c: seen.append(("s", c.k, c.frame)))
    for k in (12, 13, 15, 16, 20):            # a frame may be missing (14, 17-19)
        ex.tick(frame=f"frame{k}", k=k)
    assert seen == [("c", 12, "frame12"), ("c", 13, "frame13"), ("c", 15, "frame15"), ("s", 15, "frame15"),
                    ("c", 16, "frame16"), ("c", 20, "frame20"), ("s", 20, "frame20")]


def test_an_overrunning_task_is_a_cycle_slip_counted_and_reported_once():
    ft = FakeTime()
    period = 20 * MS
    clock = RealTimeClock(period, now_ns=ft.now, sleep_until=ft.sleep_until, cpu_ns=ft.cpu)
    events = EventLog()
    ex = Executive(period, clock, (1, 5, 50), events=events)
    cost = {"nav": 1 * MS, "control": 4 * MS}

    def task(name):
        def run(c):
            ft.t += cost[name] + (21 * MS if (name == "control" and c.k == 7) else 0)
        return run
    ex.add(1, "nav", task("nav"))
    ex.add(1, "control", task("control"))
    clock.start(ft.t)
    t0 = clock.t0_ns
    for _ in range(12):
        ex.tick()
    st = ex.stats
    assert ex.slips == 1 and ex.last_slip_k == 7 and ex.missed_releases == 0
    np.testing.assert_array_equal(st.slip[:12], np.arange(12) == 7)
    # releases never move: t0 + k * period
    np.testing.assert_array_equal(st.t_release_ns[:12], t0 + np.arange(12) * period)
    # cycle 7 ends at 7p + 26 ms = 8p + 6 ms: cycle 8 starts 6 ms late and still meets its deadline
    expected_jitter = np.zeros(12, np.int64)
    expected_jitter[8] = 6 * MS
    np.testing.assert_array_equal(st.jitter_ns[:12], expected_jitter)
    expected_compute = np.full(12, 5 * MS)
    expected_compute[7] = 26 * MS
    np.testing.assert_array_equal(st.compute_ns[:12], expected_compute)
    assert st.task_percentiles("control")["max"] == 25 * MS and st.task_percentiles("nav")["p50"] == 1 * MS
    slips = [e for e in events.history if e.code == "cycle_slip"]
    assert len(slips) == 1 and slips[0].severity == Severity.WARNING and slips[0].source == "executive"
    assert "k=7" in slips[0].text and "control 25.0" in slips[0].text and len(slips[0].text) <= 50
    tm = ex.telemetry()
    assert tm["slips"] == 1 and tm["compute_max_us"] == 26_000 and tm["jitter_max_us"] == 6_000
    # the late cycle's own record: where its time went
    assert tm["slip_records"] == [{"k": 7, "cause": "overrun", "late_us": 6_000.0, "jitter_us": 0.0,
                                   "tasks_us": {"nav": 1_000.0, "control": 25_000.0},
                                   "release_host_us": 0.0, "compute_off_cpu_us": 0.0}]
    assert tm["host_slips"] == 0 and tm["late_releases"] == {"previous_cycle": 1}


def test_overrun_beyond_a_period_skips_missed_releases_and_keeps_the_phase():
    ft = FakeTime()
    period = 20 * MS
    clock = RealTimeClock(period, now_ns=ft.now, sleep_until=ft.sleep_until)
    events = EventLog()
    ex = Executive(period, clock, (1, 5), events=events)
    ran = []
    ex.add(1, "control", lambda c: (ran.append(c.k), setattr(ft, "t", ft.t + (50 * MS if c.k == 3 else MS))))
    ex.add(2, "slow", lambda c: ran.append(("slow", c.k)))
    clock.start(ft.t)
    for _ in range(5):
        ex.tick()
    # cycle 3 ends at 3p + 50 ms = 5.5p: release 4 is gone, release 5 runs half a period late
    assert [r for r in ran if not isinstance(r, tuple)] == [0, 1, 2, 3, 5]
    assert ("slow", 5) in ran and ("slow", 0) in ran     # RG2 phase tied to time, not to count
    assert ex.missed_releases == 1 and ex.slips == 1
    assert ex.stats.jitter_ns[4] == period // 2
    assert [e.code for e in events.history] == ["cycle_slip", "release_missed"]


def test_a_cycle_released_late_by_the_host_is_a_slip_of_its_own_cause():
    """The loop woke 21 ms after its release (the CPU was elsewhere) and computed 1 ms: a
    slip, recorded as a late release, not as the tasks' overrun."""
    ft = FakeTime()
    period = 20 * MS
    stalls = {3: 21 * MS}

    def sleep_until(t):
        ft.sleep_until(t)
        ft.t += stalls.pop(len(ft.sleeps) - 1, 0)
    clock = RealTimeClock(period, now_ns=ft.now, sleep_until=sleep_until)
    ex = Executive(period, clock, (1,))
    ex.event_time = lambda: 42.0
    ex.add(1, "control", lambda c: setattr(ft, "t", ft.t + MS))
    clock.start(ft.t)
    for _ in range(6):
        ex.tick()
    assert ex.slips == 1
    (rec,) = ex.telemetry()["slip_records"]
    assert rec["cause"] == "late_release" and rec["jitter_us"] == 21_000 and rec["tasks_us"] == {"control": 1_000}
    # its event is stamped by the owner's clock (the FSW's mission time), not the host's
    assert [e.t_s for e in ex.events.history if e.code == "cycle_slip"] == [42.0]


def test_joining_a_running_plant_at_step_k0_misses_nothing_and_keeps_the_phase():
    """The SIL FSW locks onto the plant at its step k0 (after warming up): release k0 is at
    t0 + k0 p, nothing is counted missed, and RG2 still runs on plant steps divisible by 5."""
    ft = FakeTime()
    period = 20 * MS
    clock = RealTimeClock(period, now_ns=ft.now, sleep_until=ft.sleep_until)
    ex = Executive(period, clock, (1, 5))
    ran = []
    ex.add(1, "control", lambda c: ran.append(c.k))
    ex.add(2, "slow", lambda c: ran.append(("slow", c.k)))
    k0 = 7
    clock.start(ft.t - k0 * period + 50_000, k0=k0)     # frame k0 published just now
    for _ in range(4):
        ex.tick()
    assert [r for r in ran if not isinstance(r, tuple)] == [7, 8, 9, 10]
    assert ("slow", 10) in ran and ex.missed_releases == 0 and clock.missed == 0
    assert ft.sleeps[0] == ft.t - 3 * period          # release 7 at t0 + 7 p


def test_slip_events_are_rate_limited_but_every_slip_is_counted():
    ft = FakeTime()
    period = 20 * MS
    clock = RealTimeClock(period, now_ns=ft.now, sleep_until=ft.sleep_until)
    events = EventLog(min_interval_s=1.0)
    ex = Executive(period, clock, (1,), events=events, deadline_ns=10 * MS)
    ex.add(1, "slow_control", lambda c: setattr(ft, "t", ft.t + 12 * MS))   # every cycle late
    clock.start(ft.t)
    n = 200                                     # 4 s of releases
    for _ in range(n):
        ex.tick()
    assert ex.slips == n and ex.missed_releases == 0
    delivered = [e for e in events.history if e.code == "cycle_slip"]
    assert 4 <= len(delivered) <= 5
    assert events.suppressed == n - len(delivered)
    assert "suppressed" in delivered[1].text


def test_spin_mode_sleeps_to_release_minus_spin_then_busy_waits():
    ft = FakeTime(per_read_ns=1_000)           # each clock read takes 1 us
    period, spin = 20 * MS, 300_000
    clock = RealTimeClock(period, spin_ns=spin, now_ns=ft.now, sleep_until=ft.sleep_until)
    clock.start(ft.t + period)
    for k in range(3):
        kk, t_rel = clock.release()
        assert kk == k and t_rel == clock.t0_ns + k * period
        assert ft.sleeps[-1] == t_rel - spin
        assert t_rel <= ft.t < t_rel + 2_000     # spun to the release, overshoot <= 2 reads
    with pytest.raises(ValueError):
        RealTimeClock(period, spin_ns=period)


def test_rehearsal_runs_once_lead_before_each_release_then_spins_to_it():
    ft = FakeTime(per_read_ns=1_000)
    period, spin, lead = 20 * MS, 200_000, 800_000
    clock = RealTimeClock(period, spin_ns=spin, now_ns=ft.now, sleep_until=ft.sleep_until)
    ran_at = []
    clock.set_rehearsal(lambda: ran_at.append(ft.t), lead)
    clock.start(ft.t + period)
    for k in range(3):
        _, t_rel = clock.release()
        assert ft.sleeps[-1] == t_rel - lead      # slept to the rehearsal, not to release - spin
        assert t_rel - lead <= ran_at[-1] < t_rel - lead + 3_000
        assert t_rel <= ft.t < t_rel + 2_000     # then spun to the release
    assert clock.rehearsals == len(ran_at) == 3 and clock.rehearsals_skipped == 0
    # a spin longer than the lead: the rehearsal starts when the spin would
    clock.set_rehearsal(lambda: ran_at.append(ft.t), 100_000)
    _, t_rel = clock.release()
    assert ft.sleeps[-1] == t_rel - spin and t_rel - spin <= ran_at[-1] < t_rel - spin + 3_000
    # a caller already inside the lead: no rehearsal (it could not end in time), counted
    ft.t = t_rel + period - 50_000
    n = len(ran_at)
    clock.release()
    assert len(ran_at) == n and clock.rehearsals_skipped == 1
    clock.set_rehearsal(None, 0)
    clock.release()
    assert len(ran_at) == n and clock.rehearse is None
    with pytest.raises(ValueError):
        clock.set_rehearsal(lambda: None, period)
    with pytest.raises(TypeError):
        clock.set_rehearsal(5, lead)


def test_the_rehearsal_lead_grows_to_the_rehearsals_own_duration_and_back():
    """Rehearsals that outgrow their fixed lead make the release late; the lead is then
    sized from the rehearsals' measured durations (the second longest of the recent ones
    times the margin: one outlier moves nothing), bounded below the period, and returns to
    the set lead once they are short again."""
    ft = FakeTime(per_read_ns=1_000)
    period, lead = 20 * MS, 800_000
    clock = RealTimeClock(period, now_ns=ft.now, sleep_until=ft.sleep_until)
    cost = {"ns": 1_500_000}                     # each rehearsal takes this long

    def rehearse():
        ft.t += cost["ns"]
    clock.set_rehearsal(rehearse, lead)
    clock.start(ft.t + period)
    late = []
    for _ in range(3):
        _, t_rel = clock.release()
        late.append(ft.t - t_rel)
    # the first two rehearsals, started at the set lead, ended ~0.7 ms after their release
    assert all(700_000 <= d < 710_000 for d in late[:2])
    took = sorted(clock.rehearsal_ns)[-2]
    assert 1_500_000 <= took < 1_510_000
    assert clock.lead_ns == int(took * clock.LEAD_MARGIN) > lead
    assert 0 <= late[2] < 3_000                           # then released on time: spun to it
    assert ft.sleeps[-1] == t_rel - clock.lead_ns        # ... from the grown lead
    # rehearsals short again: the grown lead holds for LEAD_WINDOW of them, then the set lead
    cost["ns"] = 100_000
    for _ in range(clock.LEAD_WINDOW - 2):       # two of the three long ones still in the window
        clock.release()
    assert clock.lead_ns > lead
    clock.release()
    assert clock.lead_ns == lead and clock.lead_max_ns == int(took * clock.LEAD_MARGIN)
    # (short rehearsals never shorten the set lead); one preempted for 9 ms moves nothing
    cost["ns"] = 9 * MS
    clock.release()
    assert clock.lead_ns == lead
    cost["ns"] = 100_000
    clock.release()
    assert clock.lead_ns == lead
    # two such: the lead stops at LEAD_CAP of the period, and a release already inside that
    # lead is not rehearsed (counted)
    cost["ns"] = 9 * MS
    clock.release()
    assert clock.lead_ns == int(period * clock.LEAD_CAP)
    _, t_rel = clock.release()
    ft.t = t_rel + period - clock.lead_ns + 1_000
    n = clock.rehearsals
    clock.release()
    assert clock.rehearsals == n and clock.rehearsals_skipped == 1 and clock.missed == 0


def test_real_clock_releases_are_absolute_and_never_drift():
    period = 2 * MS
    clock = RealTimeClock(period)
    ex = Executive(period, clock, (1,))
    ex.add(1, "work", lambda c: sum(range(200)))
    ex.run(n_cycles=40)
    st = ex.stats
    n = ex.cycles
    ks = st.k[:n]
    np.testing.assert_array_equal(st.t_release_ns[:n], clock.t0_ns + ks * period)
    assert np.all(st.jitter_ns[:n] >= 0)          # never released early
    assert ks[-1] == 39 + ex.missed_releases
    tm = ex.telemetry()
    print(f"\nreal clock 500 Hz, 40 cycles: jitter p50 {tm['jitter_p50_us']:.0f} us, "
          f"max {tm['jitter_max_us']:.0f} us, slips {tm['slips']}")
    # sleep_until_ns itself: wakes at or after the target
    t = time.monotonic_ns() + MS
    sleep_until_ns(t)
    assert time.monotonic_ns() >= t


def test_task_errors_are_caught_counted_reported_and_later_tasks_still_run():
    events = EventLog()
    ex = Executive(20 * MS, LockstepClock(), (1,), events=events)
    after = []

    def bad(c):
        raise ZeroDivisionError("boom")
    ex.add(1, "bad", bad)
    ex.add(1, "after", lambda c: after.append(c.k))
    for _ in range(3):
        ex.tick(t_s=0.02 * len(after))
    assert ex.task_errors == 3 and after == [0, 1, 2]
    errs = [e for e in events.history if e.code == "task_error"]
    assert errs and errs[0].severity == Severity.ERROR and "ZeroDivisionError" in errs[0].text

    strict = Executive(20 * MS, LockstepClock(), (1,), catch_task_errors=False)
    strict.add(1, "bad", bad)
    with pytest.raises(ZeroDivisionError):
        strict.tick()


def test_ring_buffers_keep_the_last_cycles_and_percentiles_are_over_them():
    ft = FakeTime()
    ex = Executive(20 * MS, LockstepClock(now_ns=ft.now), (1, 2), history=8)
    ex.add(1, "work", lambda c: setattr(ft, "t", ft.t + 1_000 * c.k))
    ex.add(2, "half", lambda c: setattr(ft, "t", ft.t + 7))
    for _ in range(20):
        ex.tick()
    st = ex.stats
    last = np.arange(12, 20)
    assert st.percentiles("compute_ns")["max"] == 1_000 * 19 + 7 * (19 % 2 == 0)
    work = st.task_percentiles("work")
    assert work["runs"] == 8 and work["p50"] == np.percentile(1_000 * last, 50)
    assert st.task_percentiles("half")["runs"] == 4 and st.task_percentiles("half")["max"] == 7
    assert np.all(st.jitter_ns[:8] == 0)               # lockstep: released when handed in
    empty = Executive(20 * MS, LockstepClock(), (1,)).telemetry()
    assert empty["cycles"] == 0 and "jitter_p50_us" not in empty


def test_parameters_from_the_defaults_file_and_bad_configuration():
    p = load_params(PARAMS)
    ex = Executive.from_params(p, 20 * MS, LockstepClock())
    assert ex.divisors == (1, 5, 50) and ex.deadline_ns == 20 * MS
    assert RealTimeClock.from_params(p, 20 * MS).spin_ns == round(p["executive.spin_us"] * 1e3)
    for bad in [dict(period_ns=0), dict(divisors=(1, 0)), dict(divisors=(1, 2.5)), dict(deadline_ns=-1)]:
        kw = dict(period_ns=20 * MS, clock=LockstepClock())
        kw.update(bad)
        with pytest.raises(ValueError):
            Executive(**kw)
    ex2 = Executive(20 * MS, LockstepClock())
    with pytest.raises(ValueError):
        ex2.add(4, "x", lambda c: None)
    ex2.add(1, "x", lambda c: None)
    with pytest.raises(ValueError):
        ex2.add(2, "x", lambda c: None)
    with pytest.raises(TypeError):
        ex2.add(1, "y", 3)
    with pytest.raises(RuntimeError):
        ex2.run(1)
    assert math.isclose(p["executive.deadline_frac"], 1.0)


def test_own_slips_keeps_overruns_and_heavy_late_releases_up_to_the_plants_last_step():
    recs = [{"k": 10, "cause": "overrun", "tasks_us": {"control": 21000.0}},
            {"k": 11, "cause": "late_release", "tasks_us": {"control": 300.0}},      # the host's
            {"k": 12, "cause": "late_release", "tasks_us": {"control": 10000.0}},    # half a period: own
            {"k": 3015, "cause": "overrun", "tasks_us": {"groundlink": 16700.0}}]    # the plant had gone
    assert [r["k"] for r in own_slips(recs, 20000.0)] == [10, 12, 3015]
    assert [r["k"] for r in own_slips(recs, 20000.0, last_k=3000)] == [10, 12]


def test_own_slips_leaves_the_host_a_slip_its_preemption_or_a_late_frame_explains():
    """5-ms period: a cycle 2 ms late is the host's when the thread was off its CPU for that
    long after taking its frame, or when it waited for its frame that long; the same cycle on
    its CPU throughout, its frame on time, is its own."""
    def rec(k, off=None, wait=100.0, jitter=1.0):
        r = {"k": k, "cause": "overrun", "late_us": 2000.0, "jitter_us": jitter,
             "tasks_us": {"input": wait, "control": 6900.0 - wait}}
        if off is not None:
            r["off_cpu_us"] = off
        return r
    recs = [rec(1, off=2500.0),              # preempted for longer than it was late: the host's
            rec(2, off=500.0),               # preempted, but its work alone was still too long: own
            rec(3, off=0.0, wait=2100.0),    # waited 2.1 ms for the plant's frame: not its work
            rec(4),                          # no CPU figure (batch, older records): judged as before
            rec(5, off=1000.0, jitter=1000.0)]   # late release and preemption together cover it
    assert [r["k"] for r in own_slips(recs, 5000.0)] == [2, 4]


def test_rate_group_periods_are_seconds_whatever_the_control_rate():
    from fsw.executive import divisors, rate_divisor
    p = load_params(PARAMS)
    assert divisors(p, 0.02) == (1, 5, 50)              # 10 Hz and 1 Hz at 50 Hz ...
    assert divisors(p, 0.005) == (1, 20, 200)           # ... and at 200 Hz
    assert divisors(p, 0.01) == (1, 10, 100)
    with pytest.raises(ValueError, match="rg2_period_s = 0.1 s is not a whole number"):
        divisors(p, 0.03)
    with pytest.raises(ValueError, match="not a whole number"):
        rate_divisor(0.001, 0.005)                       # shorter than a control period
    ex = Executive.from_params(p, 5_000_000, LockstepClock())
    assert ex.divisors == (1, 20, 200)
