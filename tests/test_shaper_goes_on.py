"""A reference moving away from its target (fsw/guidance/shaper.py ``shaper_branch_moving``):
with a weak braking limit, turning round costs v^2/2b out and as much back, so a reversal at
the rate limit caught by a reconfiguration, then commanded back to lift up, would brake through
lift down and come all the way back. It goes on by a full turn when that arrives sooner; the
predictor's transition takes the same way; at the nominal limits, at rest, or moving towards
the target, the branch is shaper_branch's."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fsw.guidance import shaper

DT = 0.02
d = math.radians
RATE, ACCEL, WEAK = d(8.0), d(0.4), d(0.31)


def _fly(phi0_deg: float, phid0_dps: float, cmd_deg: float, brake: float, t_end_s: float = 200.0):
    """The BankShaper from a moving state, commanded cmd_deg once. Returns (time to settle on
    the target [s] or inf, time with the reference's bank below the horizon (cos < 0) [s],
    final angle [deg, unwrapped])."""
    sh = shaper.BankShaper(d(phi0_deg), RATE, ACCEL, DT)
    sh.replan(0.0, RATE, ACCEL, brake)
    sh.phid = d(phid0_dps)
    sh._sign = 1.0 if math.sin(sh.phi) >= 0.0 else -1.0
    sh.command(d(cmd_deg))
    settle, down = math.inf, 0.0
    for k in range(int(t_end_s / DT)):
        phi, phid, _ = sh.evaluate(k * DT)
        down += DT if math.cos(phi) < 0.0 else 0.0
        if abs(sh.target - phi) < 1e-3 and abs(phid) < 1e-3:
            settle = k * DT
            break
    return settle, down, math.degrees(sh.phi)


def _arrival_flown(dist_deg: float, speed_dps: float, brake: float) -> float:
    """The law's own time to rest on a fixed target dist_deg ahead (independent of arrival_s)."""
    phi, phid, t = 0.0, d(speed_dps), 0.0
    target = d(dist_deg)
    while not (abs(target - phi) < 1e-4 and abs(phid) < 1e-4):
        a = shaper.shaper_accel_braked(phi, phid, target, RATE, ACCEL, brake, DT)
        phi += phid * DT + 0.5 * a * DT * DT
        phid += a * DT
        t += DT
        assert t < 1000.0
    return t


@pytest.mark.parametrize("dist, speed", [(70.0, -8.0), (290.0, 8.0), (120.0, 0.0), (20.0, 8.0), (200.0, 2.0)])
def test_arrival_time_is_the_laws_own(dist, speed):
    """arrival_s against the law stepped at the control period (moving away, towards at the rate
    limit, from rest, towards too fast to stop, towards slowly): within a few percent (the law
    brakes on its discrete sqrt(2 b |e|) curve and at up to its acceleration limit when the
    target is ahead)."""
    model = shaper.arrival_s(d(dist), d(speed), RATE, ACCEL, WEAK)
    flown = _arrival_flown(dist, speed, WEAK)
    assert model == pytest.approx(flown, rel=0.12, abs=1.0)


def test_moving_fast_away_with_a_weak_brake_it_goes_on():
    """At -80 deg moving -8 deg/s, -10 deg commanded (lift up behind it): turning round at
    0.31 deg/s^2 is 103 deg out and 173 back; going on through lift down to -370 deg is 290 deg
    at the rate limit. At the nominal 1 deg/s^2 turning round (32 deg out) is the sooner."""
    s, turn = shaper.shaper_branch_moving(d(-80.0), d(-8.0), -1.0, 0.0, d(-10.0), RATE, ACCEL, WEAK)
    assert (s, turn) == (-1.0, pytest.approx(-2.0 * math.pi))
    s, turn = shaper.shaper_branch_moving(d(-80.0), d(-8.0), -1.0, 0.0, d(-10.0), RATE, d(1.0), d(1.0))
    assert (s, turn) == (-1.0, 0.0)
    # at rest, or moving towards the target: shaper_branch's answer
    for phid in (0.0, 8.0):
        assert shaper.shaper_branch_moving(d(-80.0), d(phid), -1.0, 0.0, d(-10.0), RATE, ACCEL, WEAK) == \
            shaper.shaper_branch(d(-80.0), -1.0, 0.0, d(-10.0))


def test_going_on_arrives_sooner_and_spends_less_time_below_the_horizon():
    """Flown: the reference that goes on settles on lift up (-370 deg = -10 deg) sooner, and
    spends less time with its lift down, than the one that turns round at the braking limit
    (flown with the branch forced back, the old rule)."""
    settle, down, end = _fly(-80.0, -8.0, -10.0, WEAK)
    assert end == pytest.approx(-370.0, abs=0.1)
    sh = shaper.BankShaper(d(-80.0), RATE, ACCEL, DT)        # the old rule: turn round
    sh.replan(0.0, RATE, ACCEL, WEAK)
    sh.phid, sh._sign, sh.target = d(-8.0), -1.0, d(-10.0)
    settle0, down0 = math.inf, 0.0
    for k in range(int(200.0 / DT)):
        phi, phid, _ = sh.evaluate(k * DT)
        down0 += DT if math.cos(phi) < 0.0 else 0.0
        if abs(sh.target - phi) < 1e-3 and abs(phid) < 1e-3:
            settle0 = k * DT
            break
    assert math.degrees(sh.phi) == pytest.approx(-10.0, abs=0.1)
    assert settle < settle0 - 10.0
    assert down < 0.7 * down0


def test_the_predictor_takes_the_same_way():
    """shaped_transition from the same moving state ends where the shaper goes (-370 deg)."""
    shp = np.array([d(-80.0), d(-8.0), -1.0, 0.0, RATE, ACCEL, DT, d(10.0), WEAK])
    tab = np.empty(shaper.N_TRANSITION)
    n = shaper.shaped_transition(shp, d(-10.0), 0.0, d(-10.0), 0.5, tab)
    assert math.degrees(tab[n - 1]) == pytest.approx(-370.0, abs=0.1)
    assert np.all(np.diff(tab[:n]) <= 1e-9)                        # never turns round
