"""Which frame a real-time FSW release flies (ellipsled/sil/frame_timing.py), on scripted
frames and a scripted clock: the phase lock takes the plant's schedule from the earliest of
its first publications, each tick flies its own step, and one frame that comes after its
tick's wait costs that tick only."""
from __future__ import annotations

from ellipsled.sil.frame_timing import PhaseLock, due_step, phase_origin_ns, phase_steady, take_due_frame

MS = 1_000_000
PERIOD = 20 * MS


class ScriptedPlant:
    """Frames published at scripted times; a clock the waiting loop advances by pausing."""

    def __init__(self, arrivals: dict[int, int], pause_ns: int = 20_000):
        self.arrivals = arrivals          # step -> arrival time at the FSW [ns]
        self.now = 0
        self.pause_ns = pause_ns
        self.taken = -1

    def fetch(self) -> int | None:
        """The newest frame arrived since the last call, as the transport's `latest` gives it."""
        come = [k for k, t in self.arrivals.items() if t <= self.now and k > self.taken]
        if not come:
            return None
        self.taken = max(come)
        return self.taken

    def pause(self) -> None:
        self.now += self.pause_ns

    def clock(self) -> int:
        return self.now


def test_the_lock_takes_the_earliest_origin_not_the_first_frames():
    # steps 1 and 2 published 32 and 13 ms late (the plant's first calls), then on time
    origin = 5 * MS
    late = {1: 32 * MS, 2: 13 * MS}
    frames = [(k, origin + k * PERIOD + late.get(k, 0) + (k % 3) * 10_000) for k in range(1, 11)]
    assert phase_origin_ns(frames, PERIOD) == origin                       # steps 3, 6, 9: on time
    assert phase_origin_ns(frames[:1], PERIOD) == origin + 32 * MS + 10_000  # the first alone: late


def test_a_catch_up_burst_is_not_a_schedule_the_frames_after_it_are():
    """A plant stalled about 200 ms publishes its backlog (steps 1-10) at once, then keeps its
    schedule: the burst's frames imply origins a period apart, so no lock on them (the earliest
    of them is 10 ms late: every release would be); once five frames keep one schedule, the
    last ten give the true origin."""
    origin = 5 * MS
    burst = [(k, origin + 210 * MS + k * 1_000) for k in range(1, 11)]     # all at ~t = 215 ms
    assert not phase_steady(burst, PERIOD)
    assert phase_origin_ns(burst, PERIOD) == origin + 10 * MS + 10_000    # a lock here: 10 ms late
    after = burst + [(k, origin + k * PERIOD + (k % 3) * 10_000) for k in range(11, 16)]
    assert phase_steady(after, PERIOD) and not phase_steady(after[:-1], PERIOD)
    assert phase_origin_ns(after[-10:], PERIOD) == origin
    # the usual start (first steps late by their first calls, then on time) is steady at once
    late = {1: 32 * MS, 2: 13 * MS}
    start = [(k, origin + k * PERIOD + late.get(k, 0) + (k % 3) * 10_000) for k in range(1, 11)]
    assert phase_steady(start, PERIOD)


def _lock(lock: PhaseLock, frames, seen):
    """Offer (step, publication) pairs seen at ``seen(k, t_pub)``; (origin, step) of the lock or None."""
    for k, t in frames:
        origin = lock.offer(k, t, seen(k, t))
        if origin is not None:
            return origin, k
    return None


def test_the_lock_waits_out_a_backlog_longer_than_its_wait():
    """A plant stalled 3.3 s at its start (seen under load) publishes 166 steps at once, then keeps
    its schedule. The FSW reads the backlog within milliseconds: however many frames it holds,
    the lock takes the schedule after it (a wait counted in frames, 110 then, locked on the burst
    and every release of that run came 13.4 ms late)."""
    origin = 7 * MS
    # never published before its time on the schedule: the backlog ends where the schedule is
    burst = [(k, max(origin + 3300 * MS + k * 40_000, origin + k * PERIOD)) for k in range(1, 167)]
    after = [(k, origin + k * PERIOD + (k % 3) * 10_000) for k in range(167, 200)]
    lock = PhaseLock(PERIOD, 10, 2000 * MS)
    got = _lock(lock, burst + after, seen=lambda k, t: t + 200_000)
    assert got is not None and got[0] == origin and got[1] > 160     # after the backlog
    # the frame-count wait it replaces: 10 + 2 s of frames, then the burst's origin (a period late)
    assert phase_origin_ns(burst[100:110], PERIOD) - origin > 10 * MS


def test_a_host_that_never_keeps_one_schedule_still_gets_a_lock_after_the_wait():
    """Publications a third of a period early and late by turns: never steady, no burst; the
    lock comes once the wait has passed, from the earliest origin of the last frames."""
    origin = 3 * MS
    frames = [(k, origin + k * PERIOD + (PERIOD // 3 if k % 2 else 0)) for k in range(1, 400)]
    lock = PhaseLock(PERIOD, 10, 2000 * MS)
    t_first = frames[0][1]
    origin_got, k = _lock(lock, frames, seen=lambda k, t: t + 100_000)
    assert origin_got == origin
    assert frames[k - 1][1] + 100_000 >= t_first + 100_000 + 2000 * MS > frames[k - 2][1] + 100_000


def test_the_usual_start_locks_on_the_tenth_frame():
    origin = 5 * MS
    late = {1: 32 * MS, 2: 13 * MS}
    frames = [(k, origin + k * PERIOD + late.get(k, 0) + (k % 3) * 10_000) for k in range(1, 30)]
    assert _lock(PhaseLock(PERIOD, 10, 2000 * MS), frames, seen=lambda k, t: t + 300_000) == (origin, 10)


def test_a_release_takes_the_frame_due_when_it_comes_within_the_wait():
    plant = ScriptedPlant({7: 100 * MS, 8: 120 * MS + 500_000})
    plant.now = 120 * MS                                  # release 0.5 ms before step 8's frame
    k = take_due_frame(plant.fetch, due=8, deadline_ns=123 * MS, now_ns=plant.clock, pause=plant.pause)
    assert k == 8 and 120 * MS + 500_000 <= plant.now < 121 * MS


def test_a_release_whose_frame_misses_the_wait_flies_the_newest_it_has():
    plant = ScriptedPlant({7: 100 * MS, 8: 126 * MS})
    plant.now = 120 * MS
    k = take_due_frame(plant.fetch, due=8, deadline_ns=123 * MS, now_ns=plant.clock, pause=plant.pause)
    assert k == 7 and plant.now >= 123 * MS               # waited the whole wait, no longer
    nothing = ScriptedPlant({})
    assert take_due_frame(nothing.fetch, 0, 1 * MS, nothing.clock, nothing.pause) is None


def test_one_late_frame_costs_its_tick_only_while_locked_to_the_plant():
    """Ticks 10..29, frames on time but step 15's after its tick's wait: tick 15 has no new
    frame (no answer), tick 16 flies step 16 (not 15, a period late), and so on for good."""
    wait = 3 * MS
    arrivals = {k: k * PERIOD + 300_000 for k in range(9, 40)}
    arrivals[15] = 15 * PERIOD + wait + 2 * MS            # after tick 15's wait, before tick 16
    plant = ScriptedPlant(arrivals)
    flown, next_k = {}, 10
    for tick in range(10, 30):
        plant.now = max(plant.now, tick * PERIOD)
        due = due_step(next_k, tick, locked_plant=True)
        k = take_due_frame(plant.fetch, due, tick * PERIOD + wait, plant.clock, plant.pause)
        flown[tick] = k
        if k is not None:
            next_k = k + 1
    assert flown[15] is None
    assert all(flown[t] == t for t in range(10, 30) if t != 15), flown
    # the unlocked rule, "the step after the last one flown", would be a period late from tick 16 on
    assert due_step(15, 16, locked_plant=False) == 15


def test_after_a_plant_restart_the_step_after_the_last_one_flown_is_due():
    # a new plant counts from 0: the executive's tick number means nothing to it
    assert due_step(next_k=1, cycle_k=4_000, locked_plant=False) == 1
    assert due_step(next_k=1, cycle_k=4_000, locked_plant=True) == 4_000
