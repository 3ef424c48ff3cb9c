"""The ``wake`` benchmark section (ellipsled/bench/wake.py): what each condition waits by, on
an injected clock; the child flying the four flights in turns; the table's rows."""
from __future__ import annotations

import math

import pytest

from ellipsled.bench import wake
from fsw.executive import PARAMS, LockstepClock, RealTimeClock
from fsw.params import load_params

PERIOD_NS = 5_000_000


class FakeTime:
    """A monotonic clock that only moves when slept on or read (each read 1 us on)."""

    def __init__(self):
        self.t = 1_000_000_000
        self.sleeps: list[int] = []
        self.reads = 0

    def now_ns(self) -> int:
        self.t += 1_000
        self.reads += 1
        return self.t

    def sleep_until(self, t_ns: int) -> None:
        self.sleeps.append(t_ns)
        self.t = max(self.t, t_ns)


def _released(condition: str, cycle_ns: int = 50_000) -> FakeTime:
    """Three releases of the condition's clock, each after a cycle of ``cycle_ns``."""
    ft = FakeTime()
    clock = wake.clock_for(condition, load_params(PARAMS), PERIOD_NS, now_ns=ft.now_ns, sleep_until=ft.sleep_until)
    clock.start()
    for _ in range(3):
        clock.release()
        ft.t += cycle_ns
    assert clock.missed == 0
    return ft


def test_spun_never_sleeps_and_slept_sleeps_to_its_final_spin():
    spun = _released("spun")
    assert spun.sleeps == []                 # the whole period spun: many reads of the clock
    assert spun.reads > 3 * PERIOD_NS // 1_000 // 2
    slept = _released("slept")
    assert len(slept.sleeps) == 3            # one sleep per release, to the FSW's final spin
    assert slept.sleeps == [slept.sleeps[0] + k * PERIOD_NS for k in range(3)]   # absolute, a period apart


def test_a_turn_restarts_its_clock_one_period_away_whatever_release_it_is_at():
    for k0 in (0, 1, 975):
        ft = FakeTime()
        clock = wake.clock_for("slept", load_params(PARAMS), PERIOD_NS, now_ns=ft.now_ns, sleep_until=ft.sleep_until)
        t_start = ft.t
        wake.restart(clock, k0)
        k, t_rel = clock.release()
        assert k == k0 and clock.missed == 0
        assert 0 < t_rel - t_start <= PERIOD_NS + 10_000        # one period (and the clock's reads) away
        k, t_next = clock.release()
        assert (k, t_next - t_rel) == (k0 + 1, PERIOD_NS)


def test_batch_is_lockstep_and_unknown_conditions_are_refused():
    assert isinstance(wake.clock_for("batch", load_params(PARAMS), PERIOD_NS), LockstepClock)
    assert isinstance(wake.clock_for("rehearsed", load_params(PARAMS), PERIOD_NS), RealTimeClock)
    with pytest.raises(ValueError, match="unknown condition"):
        wake.clock_for("hot", load_params(PARAMS), PERIOD_NS)


@pytest.mark.realtime
def test_child_flies_the_four_conditions_in_turns():
    block, rounds = 4, 2
    r = wake.run_child(5_000, block, rounds, priority=None, cpu=None)
    assert r["block"] == block and r["rounds"] == rounds
    for name in wake.CONDITIONS:
        c = r[name]
        expected = block * rounds - (wake.BATCH_COLD * rounds if name == "batch" else 0)
        assert c["cycles"] == expected, name
        for k in ("p50_us", "p99_us", "max_us"):
            assert math.isfinite(c[k]) and c[k] > 0
        assert c["p50_us"] <= c["p99_us"] <= c["max_us"]
    # only the FSW's own wait rehearses (each release that had its lead left: all, unloaded)
    assert r["rehearsed"]["rehearsals"] > 0
    assert r["slept"]["rehearsals"] == r["spun"]["rehearsals"] == r["batch"]["rehearsals"] == 0


def test_rows_give_each_wait_against_batch_and_nothing_without_a_run():
    def cond(p50, p99):
        return {"cycles": 100, "p50_us": p50, "p99_us": p99, "p99_without_lp": p99 - 1, "max_us": p99 + 5}
    res = {"wake": {"50hz": {"batch": cond(10.0, 20.0), "spun": cond(11.0, 22.0), "slept": cond(100.0, 200.0),
                             "rehearsed": cond(20.0, 40.0)}}}
    R = wake.rows(res)
    assert len(R) == 3
    slept = next(r for r in R if "sleep of one period" in r[0])
    assert slept[1] == "100.0 / 200.0 (199.0)" and slept[3].startswith("10.0x / 10.0x")
    assert wake.rows({}) == [] and wake.rows({"wake": {"50hz": {"error": "x"}}}) == []
