"""The npc reference's braking limit (fsw/guidance/shaper.py, fsw/authority.py): after a
reconfiguration the shaper sets off at its acceleration limit and brakes at that limit over
1 + guidance.npc_inertia_unc, so a vehicle that brakes more weakly than the reference's limit
(a heavier truth, the weak way of the jets on the braking side) is not carried past the
reference at rest; the predictor flies the same law; the paper's schedules are untouched."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.model import load_scenario
from fsw.flightsoftware import FlightSoftware
from fsw.guidance import shaper
from fsw.guidance.reference import BankProfile
from fsw.health import JetHealth

DT, RATE, ACCEL = 0.02, math.radians(8.0), math.radians(0.6)
START, END = math.radians(60.0), math.radians(-60.0)


def _turn(brake: float, weak_brake: float, t_end_s: float = 60.0):
    """The reversal 60 -> -60 deg (through lift up) flown, governed, by a vehicle modelled as a
    double integrator tracking the reference with feedforward plus PD feedback (poles at
    1 rad/s, as the attitude loop's), its bank acceleration capped at ``weak_brake`` the
    positive way (the way the turn brakes) and at twice the limit the way it sets off.
    Returns (largest overshoot past -60 deg [deg], final vehicle bank [deg])."""
    sh = shaper.BankShaper(START, RATE, ACCEL, DT)
    sh.replan(0.0, RATE, ACCEL, brake)
    sh.command(END)
    phi, phid, over = START, 0.0, 0.0
    for k in range(int(t_end_s / DT)):
        sh.observe(phi)
        r, rd, rdd = sh.evaluate(k * DT)
        over = max(over, END - phi)
        a = max(-2.0 * ACCEL, min(weak_brake, rdd + 2.0 * (rd - phid) + (r - phi)))
        phi += phid * DT + 0.5 * a * DT * DT
        phid += a * DT
    return math.degrees(over), math.degrees(phi)


def test_a_vehicle_braking_weaker_than_the_limit_overshoots_a_reference_braking_at_it():
    """The failure: the jets brake at 85 % of the reference's limit; the governor does not
    ease a braking reference, and the vehicle runs degrees past the target."""
    over, _ = _turn(ACCEL, 0.85 * ACCEL)
    assert over > 3.0


def test_braking_at_the_limit_over_one_point_three_stops_that_vehicle_on_the_target():
    over, end = _turn(ACCEL / 1.3, 0.85 * ACCEL)
    assert over < 0.05
    assert end == pytest.approx(-60.0, abs=0.01)


def test_sets_off_at_the_acceleration_limit_and_brakes_at_the_braking_limit():
    sh = shaper.BankShaper(START, RATE, ACCEL, DT)
    sh.replan(0.0, RATE, ACCEL, ACCEL / 1.3)
    sh.command(END)
    acc = np.array([sh.evaluate(k * DT)[2] for k in range(int(40.0 / DT))])
    assert acc.min() == pytest.approx(-ACCEL)                   # sets off (negative) at the limit
    braking = acc[acc > 1e-9][:-50]
    # brakes at the braking limit (the discrete law tracks the sqrt(2 b |e|) curve to within
    # a few per cent as |e| shrinks; its last second lands on the target by |e|/dt)
    assert len(braking) > 500
    assert np.max(braking) < 1.05 * ACCEL / 1.3
    assert np.median(braking) == pytest.approx(ACCEL / 1.3, rel=0.01)


def test_a_command_behind_a_turning_reference_turns_it_round_at_the_braking_limit():
    """A new target behind the reference while it turns (a reversal commanded mid-turn): it
    slows down at the braking limit, not the acceleration limit, then sets off at the latter;
    without a braking limit it turns round at the acceleration limit (the law unchanged)."""
    for brake in (ACCEL / 1.3, ACCEL):
        sh = shaper.BankShaper(0.0, RATE, ACCEL, DT)
        sh.replan(0.0, RATE, ACCEL, brake)
        sh.command(math.radians(90.0))
        k = 0
        while sh.evaluate(k * DT)[1] < math.radians(4.0):       # turning positive at 4 deg/s
            k += 1
        sh.command(math.radians(-30.0))                          # now behind it
        slowing, speeding = [], []
        for j in range(k + 1, k + int(30.0 / DT)):
            _, rd, rdd = sh.evaluate(j * DT)
            (slowing if rd > 1e-6 else speeding).append(rdd)
        assert max(abs(a) for a in slowing[:-1]) == pytest.approx(brake, rel=1e-9)
        assert min(speeding) == pytest.approx(-ACCEL, rel=1e-9)


@pytest.mark.parametrize("angle_deg", [10.0, 120.0])             # triangular and trapezoidal rate
def test_transition_time_is_the_flown_turn_with_the_braking_limit(angle_deg):
    sh = shaper.BankShaper(0.0, RATE, ACCEL, DT)
    sh.replan(0.0, RATE, ACCEL, ACCEL / 1.3)
    sh.command(math.radians(angle_deg))
    k = 0
    while abs(sh.evaluate(k * DT)[0] - math.radians(angle_deg)) > math.radians(0.01):
        k += 1
    assert k * DT == pytest.approx(sh.transition_s(math.radians(angle_deg)), abs=0.5)
    assert sh.transition_s(math.radians(angle_deg)) > shaper.BankShaper(0.0, RATE, ACCEL, DT).transition_s(
        math.radians(angle_deg))


def test_the_predictor_flies_the_shapers_braking_sample_for_sample():
    """shaped_transition from the shaper's state (its braking limit in it) is the shaper's own
    reference, sample by sample, and differs from the law braking at the acceleration limit."""
    sh = shaper.BankShaper(START, RATE, ACCEL, DT)
    sh.replan(0.0, RATE, ACCEL, ACCEL / 1.3)
    sh.command(END)
    shp = sh.state(abs(END))
    tab = np.empty(shaper.N_TRANSITION)
    n = shaper.shaped_transition(shp, END, 0.0, END, 0.5, tab)
    flown = [sh.evaluate(k * DT)[0] for k in range(int(0.5 * (n - 1) / DT) + 1)]
    assert n > 10
    np.testing.assert_allclose(tab[:n - 1], flown[::25][:n - 1], atol=1e-9)
    old = np.empty(shaper.N_TRANSITION)
    m = shaper.shaped_transition(shp[:8], END, 0.0, END, 0.5, old)      # a state without a braking limit
    assert m < n


def _reconfigure(f: FlightSoftware, health: JetHealth) -> None:
    """FDIR's new health taken by the flight software at 3 s (the LP solved in place)."""
    f.fdir.health_active = health
    f.t_s = 3.0
    f.health_changed()


def test_mode_npc_reconfiguration_brakes_at_the_limit_over_one_plus_the_uncertainty():
    f = FlightSoftware(load_scenario("guided-case2"))
    try:
        _reconfigure(f, JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10]))
        prof = f.guidance.profile
        unc = f.params["guidance.npc_inertia_unc"]
        assert unc == 0.3
        assert prof.accel_limit_radps2 < math.radians(1.0)        # re-planned to the LP
        assert prof.brake_limit_radps2 == pytest.approx(prof.accel_limit_radps2 / (1.0 + unc))
    finally:
        f.close()


def test_mode_npc_reconfiguration_keeping_the_scenarios_limit_brakes_all_the_same():
    """Four jets failed off (the paper's case 1): 0.75 of the weaker way is above the
    scenario's 1 deg/s^2, which stays the acceleration limit (no re-shape announced); the
    reference brakes at it over 1 + guidance.npc_inertia_unc all the same."""
    scn = load_scenario("guided-case2")
    f = FlightSoftware(scn)
    try:
        prof = f.guidance.profile
        assert prof.brake_limit_radps2 == prof.accel_limit_radps2 == scn.bank_accel_limit_radps2
        _reconfigure(f, JetHealth.of(failed_off=[1, 2, 17, 18]))
        assert prof.accel_limit_radps2 == scn.bank_accel_limit_radps2
        assert not any(e.code == "reference_reshaped" for e in f.events.history)
        assert prof.brake_limit_radps2 == pytest.approx(scn.bank_accel_limit_radps2 / 1.3)
    finally:
        f.close()


def test_mode_profile_reconfiguration_keeps_the_minimum_jerk_profile():
    f = FlightSoftware(load_scenario("case2"))
    try:
        _reconfigure(f, JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10]))
        assert isinstance(f.guidance.profile, BankProfile)
        assert not hasattr(f.guidance.profile, "brake_limit_radps2")
        assert f.authority._brake_limit(0.01) == ()
    finally:
        f.close()
