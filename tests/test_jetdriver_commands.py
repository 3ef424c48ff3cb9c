"""Jet driver: gating (arming, inhibit mask, mode) and bookkeeping against hand counts."""
from __future__ import annotations

import numpy as np
import pytest

from common.events import EventLog
from fsw.jetdriver import JetDriver

DT = 0.02
THRUST = np.array([14.0] * 12 + [95.0] * 6)
ISP, G0 = 220.0, 9.80665


def driver(armed=True):
    d = JetDriver(THRUST, ISP, G0, DT, EventLog())
    d.arm(0.0, armed)
    return d


def u_of(*jets):
    u = np.zeros(18, dtype=np.uint8)
    for j in jets:
        u[j - 1] = 1
    return u


def test_bookkeeping_matches_a_hand_count():
    d = driver()
    # jet 1: on, on, off, on        -> 2 pulses, 3 periods
    # jet 13: on, on, on, on        -> 1 pulse, 4 periods
    # jet 7: off, on, off, off      -> 1 pulse, 1 period
    for u in (u_of(1, 13), u_of(1, 13, 7), u_of(13), u_of(1, 13)):
        d.command(u, True)
    expect_pulses = np.zeros(18, dtype=int)
    expect_pulses[[0, 12, 6]] = [2, 1, 1]
    assert np.array_equal(d.pulses, expect_pulses)
    assert d.on_time_s[0] == pytest.approx(0.06) and d.on_time_s[12] == pytest.approx(0.08)
    assert d.on_time_s[6] == pytest.approx(0.02) and d.on_time_s.sum() == pytest.approx(0.16)
    # (0.06 s * 14 N + 0.02 s * 14 N + 0.08 s * 95 N) / (220 s * 9.80665 m/s^2) = 8.72 / 2157.463 kg
    assert d.propellant_kg == pytest.approx(8.72 / 2157.463, rel=1e-9)
    assert d.seq == 4


def test_returns_the_held_command_buffer_as_uint8():
    d = driver()
    out = d.command(u_of(3, 18), True)
    assert out is d.last_command and out.dtype == np.uint8 and out.shape == (18,)
    assert np.array_equal(out, u_of(3, 18))
    out2 = d.command(np.zeros(18), True)
    assert out2 is out and not out.any()                   # reused, overwritten


@pytest.mark.parametrize("armed,enabled", [(False, True), (True, False), (False, False)])
def test_disarmed_or_standby_sends_zeros_and_counts_nothing(armed, enabled):
    d = driver(armed)
    out = d.command(np.ones(18), enabled)
    assert not out.any() and d.pulses.sum() == 0 and d.propellant_kg == 0.0 and d.on_time_s.sum() == 0.0


def test_inhibited_jets_stay_off_and_rearming_makes_a_new_pulse():
    ev = EventLog()
    d = JetDriver(THRUST, ISP, G0, DT, ev)
    d.arm(0.0, True)
    d.set_inhibit(0.0, 5, True)
    out = d.command(np.ones(18), True)
    assert out[4] == 0 and out.sum() == 17
    d.set_inhibit(0.0, 5, False)
    d.set_inhibit(0.0, 0, True)
    assert not d.command(np.ones(18), True).any()
    d.set_inhibit(0.0, 0, False)
    d.command(u_of(2), True)                 # on again after an off period: 2nd pulse of jet 2
    d.arm(0.1, False)
    d.command(u_of(2), True)
    d.arm(0.2, True)
    d.command(u_of(2), True)                 # 3rd pulse
    assert d.pulses[1] == 3
    texts = [e.text for e in ev.history]
    assert texts.count("JETS ARMED") == 2 and "JETS DISARMED" in texts
    assert "JET 5 INHIBITED" in texts and "ALL JETS INHIBITED" in texts and "JET 5 INHIBIT CLEARED" in texts


def test_bad_values_never_fire_a_jet():
    d = driver()
    u = np.full(18, np.nan)
    u[0] = 1.0
    u[1] = np.inf                            # > 0.5: a clear on
    u[2] = -np.inf
    out = d.command(u, True)
    assert np.array_equal(out, u_of(1, 2))
    with pytest.raises(ValueError):
        d.command(np.zeros(17), True)
    for bad in (19, -1, True, 2.5):
        with pytest.raises(ValueError):
            d.set_inhibit(0.0, bad, True)


def test_bad_construction_raises():
    with pytest.raises(ValueError, match="isp_s"):
        JetDriver(THRUST, 0.0, G0, DT, EventLog())
    with pytest.raises(ValueError, match="thrust_N"):
        JetDriver(np.array([14.0, np.nan]), ISP, G0, DT, EventLog())
    with pytest.raises(ValueError, match="dt_s"):
        JetDriver(THRUST, ISP, G0, float("nan"), EventLog())
