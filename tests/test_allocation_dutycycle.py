"""The duty-cycle realisation (fsw/allocation/dutycycle.py) against independent truths:
- its LP optimum against scipy's interior-point solver on the epigraph form of the same problem,
  and against every single jet pattern (each is a point of the relaxation: none may beat it);
- the sigma-delta's mean over N cycles against the LP's duty cycles (within one pulse per jet)
  and its mean torque against b + C d;
- the paper's sign box and demands one pattern nearly delivers are flown as the exact allocator's.
Healths: campaign 2026 run 82 (1, 7, 8 failed off; 14, 15 stuck on) and run 190."""
import itertools
import math

import numpy as np
import pytest
from scipy.optimize import linprog

from common.model import load_vehicle
from fsw.allocation import Allocator
from fsw.allocation.dutycycle import DutyCycleRealiser
from fsw.controllability import jet_columns, velocity_dir_B
from fsw.health import JetHealth
from fsw.params import load_params

VEH = load_vehicle("ellipsled")
T, THRUST = VEH.torque_matrix_Nm, VEH.thrust_N
AXIS = velocity_dir_B(VEH.aero.alpha_trim_rad)
PARAMS = load_params(Allocator.PARAMS)


RUN82 = JetHealth.of(failed_off=(1, 7, 8), stuck_on=(14, 15))
RUN190 = JetHealth.of(failed_off=(4, 10, 18), stuck_on=(2, 7), degraded=((9, 0.8381), (13, 0.3271)))
# a small health (6 usable jets) whose 2^6 patterns are enumerated below
SMALL = JetHealth.of(failed_off=(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12), stuck_on=(14,), degraded=((16, 0.6),))


def _objective(w, c, u, tau, d):
    return float(w @ np.abs(u - tau) + c @ d)


def _truth_lp(C, b, w, c, u):
    """min w.t + c.d  s.t. -t <= u - b - C d <= t, 0 <= d <= 1 (scipy, interior point)."""
    p = C.shape[1]
    cost = np.concatenate([c, w])
    A = np.block([[-C, -np.eye(3)], [C, -np.eye(3)]])
    rhs = np.concatenate([-(u - b), u - b])
    r = linprog(cost, A_ub=A, b_ub=rhs, bounds=[(0, 1)] * p + [(0, None)] * 3, method="highs-ipm")
    assert r.status == 0
    return r.fun


def _setup(health, params=PARAMS):
    al = Allocator(T, THRUST, params)
    al.set_health(health)
    return al, DutyCycleRealiser(AXIS, T, THRUST)


DEMANDS = [200.0 * AXIS, -300.0 * AXIS, np.array([-4000.0, 0.0, 0.0]), np.array([-150.0, -300.0, 200.0]),
           np.array([30.0, 5.0, -40.0]), np.array([-800.0, 600.0, -250.0])]


@pytest.mark.parametrize("health", [RUN82, RUN190, SMALL], ids=["run82", "run190", "small"])
def test_lp_optimum_equals_an_independent_solve_and_beats_every_pattern(health):
    al, dc = _setup(health)
    C, b = jet_columns(T, health)
    usable = health.usable()
    w = al.w
    c = al.penalty_per_N * THRUST[usable]
    for u in DEMANDS:
        d = dc.duty_cycles(al, u)
        assert np.all((d >= 0.0) & (d <= 1.0)) and np.all(d[~usable] == 0.0)
        np.testing.assert_allclose(dc.avg_B, b + C @ d[usable], atol=1e-9)
        got = _objective(w, c, u, dc.avg_B, d[usable])
        assert got == pytest.approx(_truth_lp(C, b, w, c, u), abs=1e-5 * (1.0 + w @ np.abs(u)))
        if health is SMALL:     # every single pattern is a point of the relaxation
            p = C.shape[1]
            for bits in itertools.product((0.0, 1.0), repeat=p):
                x = np.array(bits)
                assert got <= _objective(w, c, u, b + C @ x, x) + 1e-6


@pytest.mark.parametrize("health", [RUN82, RUN190], ids=["run82", "run190"])
def test_sigma_delta_mean_is_the_duty_cycles_within_one_pulse_per_jet(health):
    al, dc = _setup(health)
    C, b = jet_columns(T, health)
    usable = health.usable()
    u = -300.0 * AXIS if health is RUN82 else 100.0 * AXIS
    N = 400
    fired = np.zeros(len(THRUST))
    tau = np.zeros(3)
    dsum = np.zeros(len(THRUST))
    for _ in range(N):
        jets = dc.solve(al, u)
        assert dc.modulated
        assert not np.any(jets[~usable])          # failed, stuck (modelled as bias) never fired
        fired += jets
        tau += dc.tau_B
        dsum += dc.d
        np.testing.assert_allclose(dc.tau_B, b + C @ jets[usable].astype(float), atol=1e-9)
    assert np.all(np.abs(fired - dsum) <= 1.0 + 1e-9)          # |acc| <= 1/2 at both ends
    bound = np.abs(C).sum(axis=1) / N
    assert np.all(np.abs(tau / N - (b + C @ (dsum[usable] / N))) <= bound + 1e-9)
    # and that average reaches the demand's bank torque far better than the single-cycle optimum
    al.solve(u)
    plain = AXIS @ al.tau_B
    assert abs(AXIS @ (tau / N) - AXIS @ u) < abs(plain - AXIS @ u)


def test_run82_weak_way_average_carries_the_asked_spill():
    """Run 82's weak way: a roll demand with the pitch/yaw a trim holds. The single-cycle optimum
    repeats one pattern; the modulated average comes closer on the allocator's own objective."""
    al, dc = _setup(RUN82)
    u = np.array([-600.0, -150.0, -120.0])
    N = 500
    tau = np.zeros(3)
    for _ in range(N):
        dc.solve(al, u)
        tau += dc.tau_B
    al.solve(u)
    w = al.w
    assert w @ np.abs(u - tau / N) < w @ np.abs(u - al.tau_B)
    assert w @ np.abs(u - tau / N) <= w @ np.abs(u - dc.avg_B) + np.abs(T).sum() * w.sum() / N


def test_sign_box_and_delivered_demands_fly_the_exact_answer():
    # the paper's sign box: never modulated
    al, dc = _setup(RUN82, {**PARAMS, "allocator.spill_jets": 0.0})
    for u in DEMANDS:
        jets = dc.solve(al, u).copy()
        ref = al.solve(u)
        assert not dc.modulated and np.array_equal(jets, ref) and np.array_equal(dc.tau_B, al.tau_B)
    # nominal jets, a demand one pattern delivers (jets 3 + 13 + 16): the allocator's answer
    al, dc = _setup(JetHealth())
    u = T[:, 2] + T[:, 12] + T[:, 15]
    jets = dc.solve(al, u).copy()
    assert not dc.modulated and np.array_equal(dc.tau_B, u) and np.array_equal(jets, al.solve(u))


def test_a_delivered_or_rejected_demand_clears_the_accumulators_and_health_changes_rebuild():
    al, dc = _setup(RUN190)
    dc.solve(al, 100.0 * AXIS)
    assert dc.modulated and np.any(dc.acc != 0.0)
    dc.solve(al, np.array([math.nan, 0.0, 0.0]))
    assert al.rejected and not dc.modulated and np.array_equal(dc.acc, np.zeros(len(THRUST)))
    dc.solve(al, 100.0 * AXIS)
    al.set_health(RUN82)                          # new tables: the LP is rebuilt for them
    for _ in range(50):
        jets = dc.solve(al, -300.0 * AXIS)
        assert dc.modulated and not np.any(jets[~RUN82.usable()])


def test_the_fsws_gate_leaves_small_or_mostly_delivered_demands_to_the_exact_answer():
    """As FlightSoftware sets it: modulated only for a bank demand above two of the largest
    bank-axis jet increments that the exact answer delivers less than half of."""
    al, dc = _setup(RUN190)
    dc.short_min_Nm = 2.0 * float(np.max(np.abs(AXIS @ T)))
    dc.short_frac = 0.5
    for u in (20.0 * AXIS, 0.9 * dc.short_min_Nm * AXIS):
        jets = dc.solve(al, u).copy()
        assert not dc.modulated and np.array_equal(jets, al.solve(u))
    u = 3.0 * dc.short_min_Nm * AXIS
    al.solve(u)
    assert abs(AXIS @ al.tau_B) < 0.5 * abs(AXIS @ u)     # the exact answer: short by the rule
    dc.solve(al, u)
    assert dc.modulated
