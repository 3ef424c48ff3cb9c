"""Which way a reversal goes (fsw/guidance/shaper.py ``shaper_branch``): through lift up unless
the way through lift down is shorter by more than REVERSAL_LIFT_UP_RAD. Near a 90 deg magnitude
both ways take about the same time; the one through lift down costs range, which the corrector
wins back by turning the reversal round, late. Checked by flying the shaper and watching where
its bank goes (cos < 0: lift down), against the ways' angles worked out by hand."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fsw.guidance import shaper

DT = 0.02
d = math.radians
RATE, ACCEL = d(8.0), d(1.0)


def _reverse(mag_deg: float, t_end_s: float = 120.0):
    """The BankShaper at rest at +mag_deg, commanded -mag_deg. Returns (final angle [deg,
    unwrapped], the largest bank magnitude on the way [deg], time to settle [s])."""
    sh = shaper.BankShaper(d(mag_deg), RATE, ACCEL, DT)
    sh.command(d(-mag_deg))
    deepest, settle = 0.0, math.inf
    for k in range(int(t_end_s / DT)):
        phi, phid, _ = sh.evaluate(k * DT)
        deepest = max(deepest, abs(math.degrees(math.remainder(phi, 2.0 * math.pi))))
        if abs(sh.target - phi) < 1e-3 and abs(phid) < 1e-3:
            settle = k * DT
            break
    return math.degrees(sh.phi), deepest, settle


@pytest.mark.parametrize("mag_deg", [60.0, 91.0, 93.0, 97.0])
def test_a_reversal_near_90_deg_goes_through_lift_up(mag_deg):
    # through lift up 2 m, through lift down 360 - 2 m: the lift-up way is longer by
    # 4 m - 360 (28 deg at 97 deg), within the 30 deg margin
    final, deepest, settle = _reverse(mag_deg)
    assert final == pytest.approx(-mag_deg, abs=0.05)
    assert deepest < mag_deg + 0.5               # never further down than where it set off (the
    # law's braking tail overshoots by a fraction of a degree)
    # from rest to rest at 1 deg/s^2 within 8 deg/s: 2m/8 + 8/1 s (the rate limit is reached),
    # plus the law's braking tail onto the target (under 1 s)
    assert 0.0 <= settle - (2.0 * mag_deg / 8.0 + 8.0) < 1.0


@pytest.mark.parametrize("mag_deg", [98.0, 120.0, 165.0])
def test_a_reversal_well_above_90_deg_goes_through_lift_down(mag_deg):
    # the lift-up way longer by 4 m - 360 > 30 deg (32 deg at 98 deg): the shorter way, round 180
    final, deepest, settle = _reverse(mag_deg)
    assert final == pytest.approx(360.0 - mag_deg, abs=0.05)
    assert deepest == pytest.approx(180.0, abs=0.2)
    lift_down_angle = 360.0 - 2.0 * mag_deg
    t_ref = lift_down_angle / 8.0 + 8.0 if lift_down_angle >= 64.0 else 2.0 * math.sqrt(lift_down_angle)
    assert 0.0 <= settle - t_ref < 1.0


@pytest.mark.parametrize("mag_deg", [60.0, 93.0, 97.0, 98.0, 120.0])
def test_the_reversal_time_is_that_of_the_way_flown(mag_deg):
    # the lateral decision's reversal time (reversal_s) is the flown reversal's
    sh = shaper.BankShaper(0.0, RATE, ACCEL, DT)
    _, _, settle = _reverse(mag_deg)
    # within the law's braking tail (under 1 s); the two ways differ by 3.5 s and more here
    assert 0.0 <= settle - sh.reversal_s(d(mag_deg)) < 1.0


@pytest.mark.parametrize("mag_deg", [93.0, 120.0])
def test_the_predictors_transition_takes_the_same_way(mag_deg):
    sh = shaper.BankShaper(d(mag_deg), RATE, ACCEL, DT)
    tab = np.zeros(shaper.N_TRANSITION)
    n = shaper.shaped_transition(sh.state(d(mag_deg)), d(-mag_deg), 0.0, d(-mag_deg), 0.5, tab)
    final, _, _ = _reverse(mag_deg)
    assert math.degrees(tab[n - 1]) == pytest.approx(final, abs=0.1)


def test_a_reversal_commanded_with_the_reference_on_the_new_side_takes_the_nearest_way():
    # the reference already past lift up onto the negative side (a reversal back commanded late)
    s, turn = shaper.shaper_branch(d(-5.0), 1.0, 0.0, d(-95.0))
    assert (s, turn) == (-1.0, 0.0)


def _under_way(phi0_deg: float, mag_deg: float) -> np.ndarray:
    """The shaper's state (shp) at rest at +phi0_deg with a reversal to -mag_deg commanded."""
    sh = shaper.BankShaper(d(phi0_deg), RATE, ACCEL, DT)
    sh.command(d(-mag_deg))
    return sh.state(d(mag_deg))


def test_a_reversal_set_off_through_lift_up_is_not_turned_round_for_a_few_degrees_less():
    # from 93 deg to -93 deg: through lift up 186 deg, through lift down 174 deg: 12 deg shorter,
    # within the 30 deg the reversal set off with; the corrector is not offered the other way
    assert _under_way(93.0, 93.0)[3] == 0.0            # set off through lift up (no turn)
    assert shaper.reversal_other_way(_under_way(93.0, 93.0), -1.0) is None


def test_a_reversal_through_lift_up_is_offered_lift_down_when_that_is_far_shorter():
    # the magnitude commanded then rises to 150 deg: through lift up 243 deg, through lift down
    # 117 deg (126 deg shorter): the other way, its target at 360 - 150 = 210 deg
    shp = _under_way(93.0, 93.0)
    shp[7] = d(150.0)
    alt = shaper.reversal_other_way(shp, -1.0)
    assert alt is not None
    assert math.degrees(-d(150.0) + alt[3]) == pytest.approx(210.0)


def test_a_reversal_through_lift_down_is_offered_lift_up_when_that_is_shorter():
    # set off from 120 deg through lift down to -120 (240 deg); the magnitude commanded falls to
    # 10 deg: through lift down on 250 deg, back through lift up 130 deg: offered, target -10 deg
    shp = _under_way(120.0, 120.0)
    assert math.degrees(shp[3]) == pytest.approx(360.0)
    shp[7] = d(10.0)
    alt = shaper.reversal_other_way(shp, -1.0)
    assert alt is not None
    assert math.degrees(-d(10.0) + alt[3]) == pytest.approx(-10.0)
