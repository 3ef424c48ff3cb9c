"""The duty-cycle LP's compiled solver (fsw/allocation/dutylp.py) against independent truths:
- HiGHS (the solver it replaces in the cycle) on the same LP: optimum value within 1e-9 relative;
- LP duality: the kernel's answer is primal feasible (A x = u - b, bounds) and its duals y satisfy
  |y_i| <= w_i, so y.(u - b) + sum_k min(0, c_k - y.C_k) is a lower bound on every feasible point
  (weak duality); the bound equals the answer's cost, which proves it optimal without any solver;
- on LPs recorded in flight (tests/data/dutylp-recorded.npz: the realiser's model and u - b at each
  modulated cycle of data/scenarios/mc/default-2026-run082 / -run190 / default-20110808-run054 /
  -run009 and data/scenarios/nominal, flown in batch), in their flown order (warm starts);
- random healths, weights and demand sequences; and the edge cases: no usable jet, zero demand, a
  demand one pattern delivers exactly (primal degenerate), duplicated jets (a non-unique optimum), a
  zero weight, demands beyond every jet's authority; warm starts from another demand's basis.
The realiser flies the kernel, not HiGHS (highspy unavailable: same answers, no fallback), and a
failed kernel falls back to HiGHS, counted, with the LP's optimum all the same."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from common.model import load_vehicle
from fsw.allocation import Allocator
from fsw.allocation import dutycycle as dutycycle_module
from fsw.allocation.dutycycle import DutyCycleRealiser
from fsw.allocation.dutylp import BASIC, ITERATION_LIMIT, solve_duty_lp
from fsw.controllability import velocity_dir_B
from fsw.health import JetHealth
from fsw.params import load_params

VEH = load_vehicle("ellipsled")
T, THRUST = VEH.torque_matrix_Nm, VEH.thrust_N
AXIS = velocity_dir_B(VEH.aero.alpha_trim_rad)
RECORDED = Path(__file__).parent / "data" / "dutylp-recorded.npz"
REL = 1e-9


class Lp:
    """One LP model [C, -I, I] with the kernel's work arrays, solved for successive right-hand sides."""

    def __init__(self, C, c, w):
        p = C.shape[1]
        self.p = p
        self.A = np.hstack([C, -np.eye(3), np.eye(3)])
        self.cost = np.concatenate([c, w, w])
        self.w = np.asarray(w, dtype=float)
        self.upper = np.concatenate([np.ones(p), np.full(6, np.inf)])
        n = p + 6
        self.basis, self.state = np.zeros(3, dtype=np.int64), np.zeros(n, dtype=np.int8)
        self.x, self.dj, self.alpha = np.zeros(n), np.zeros(n), np.zeros(n)
        self.Binv, self.y, self.work = np.zeros((3, 3)), np.zeros(3), np.zeros((3, 6))
        self.cold = True

    def solve(self, rhs):
        pivots = solve_duty_lp(np.asarray(rhs, dtype=float), self.A, self.cost, self.upper, self.basis,
                               self.state, self.x, self.Binv, self.y, self.dj, self.alpha, self.work, self.cold)
        self.cold = False
        return pivots


def _highs_value(lp: Lp, rhs) -> float:
    r = linprog(lp.cost, A_eq=lp.A, b_eq=rhs, bounds=[(0.0, 1.0)] * lp.p + [(0.0, None)] * 6, method="highs")
    assert r.status == 0
    return float(r.fun)


def _check_optimal(lp: Lp, rhs, value_truth=None) -> float:
    """Asserts the kernel's last answer feasible and proven optimal by its duals; returns its cost."""
    x = lp.x
    scale = 1.0 + float(np.abs(rhs).sum())
    assert np.all(x >= -1e-9) and np.all(x <= lp.upper + 1e-9)
    np.testing.assert_allclose(lp.A @ x, rhs, rtol=0.0, atol=1e-9 * scale)
    value = float(lp.cost @ x)
    # weak duality: any y with |y_i| <= w_i bounds the optimum from below
    y = lp.y
    assert np.all(np.abs(y) <= lp.w + 1e-9)
    C, c = lp.A[:, :lp.p], lp.cost[:lp.p]
    dual = float(y @ rhs + np.minimum(0.0, c - y @ C).sum())
    assert value == pytest.approx(dual, rel=REL, abs=REL)
    if value_truth is not None:
        assert value == pytest.approx(value_truth, rel=REL, abs=REL)
    return value


def _recorded():
    z = np.load(RECORDED)
    return {k.split("/")[0]: (z[k.split("/")[0] + "/A"], z[k.split("/")[0] + "/cost"], z[k.split("/")[0] + "/rhs"])
            for k in z.files}


@pytest.mark.parametrize("name", ["run082", "run190", "run054", "run009", "nominal"])
def test_recorded_flight_lps_in_flown_order_reach_the_highs_optimum(name):
    A, cost, rhs_seq = _recorded()[name]
    p = A.shape[1] - 6
    lp = Lp(A[:, :p], cost[:p], cost[p:p + 3])
    assert np.array_equal(lp.A, A) and np.array_equal(lp.cost, cost)
    assert len(rhs_seq) >= 20
    for rhs in rhs_seq:
        assert lp.solve(rhs) >= 0
        _check_optimal(lp, rhs, _highs_value(lp, rhs))


def _random_lp(rng):
    usable = rng.random(18) < rng.uniform(0.1, 1.0)
    eta = np.where(rng.random(18) < 0.2, rng.uniform(0.2, 1.0, 18), 1.0)
    w = rng.choice([1.0, 3.0, 5.0], 3)
    return Lp((T * eta)[:, usable], rng.uniform(0.0, 0.02) * THRUST[usable], w)


def test_random_healths_and_demand_sequences_reach_the_highs_optimum():
    rng = np.random.default_rng(20261127)
    for _ in range(150):
        lp = _random_lp(rng)
        rhs = rng.normal(0.0, 500.0, 3)
        for k in range(8):
            # a walk like a cycle's demand, with now and then a jump, a pattern's torque, zero
            rhs = rhs + rng.normal(0.0, 20.0, 3) if k % 4 else rng.normal(0.0, rng.choice([10.0, 300.0, 3000.0]), 3)
            if k == 5 and lp.p:
                rhs = lp.A[:, :lp.p] @ (rng.random(lp.p) < 0.5)
            if k == 7:
                rhs = np.zeros(3)
            assert lp.solve(rhs) >= 0
            _check_optimal(lp, rhs, _highs_value(lp, rhs))


def test_a_warm_start_from_any_demands_basis_reaches_the_cold_optimum():
    rng = np.random.default_rng(7)
    lp = _random_lp(rng)
    demands = [rng.normal(0.0, 800.0, 3) for _ in range(12)]
    cold_values = []
    for u in demands:
        cold = Lp(lp.A[:, :lp.p], lp.cost[:lp.p], lp.w)
        assert cold.solve(u) >= 0
        cold_values.append(_check_optimal(cold, u))
    for i in range(len(demands)):
        for j in range(len(demands)):
            lp.cold = True
            lp.solve(demands[i])
            assert lp.solve(demands[j]) >= 0
            assert _check_optimal(lp, demands[j]) == pytest.approx(cold_values[j], rel=REL, abs=REL)


def test_no_usable_jet_leaves_the_residuals_to_carry_the_demand():
    lp = Lp(np.zeros((3, 0)), np.zeros(0), np.array([3.0, 1.0, 2.0]))
    rhs = np.array([-120.0, 40.0, 0.0])
    assert lp.solve(rhs) >= 0
    assert _check_optimal(lp, rhs) == pytest.approx(3.0 * 120.0 + 40.0)
    np.testing.assert_allclose(lp.x[3:6] - lp.x[0:3], rhs, atol=1e-12)     # r- - r+ = rhs


def test_zero_demand_fires_nothing():
    lp = Lp(T, 0.01 * THRUST, np.array([5.0, 1.0, 1.0]))
    assert lp.solve(np.zeros(3)) >= 0
    assert _check_optimal(lp, np.zeros(3)) == pytest.approx(0.0, abs=1e-12)
    assert np.all(lp.x == 0.0)


def test_a_pattern_the_jets_deliver_exactly_costs_its_penalty_at_most():
    c = 0.01 * THRUST
    lp = Lp(T, c, np.array([5.0, 1.0, 1.0]))
    rng = np.random.default_rng(3)
    for _ in range(30):
        pat = (rng.random(18) < 0.4).astype(float)
        rhs = T @ pat
        assert lp.solve(rhs) >= 0
        assert _check_optimal(lp, rhs, _highs_value(lp, rhs)) <= c @ pat + 1e-9


def test_duplicated_jets_and_a_zero_weight_keep_the_optimum_value():
    """Two copies of every column (a non-unique optimum: any split between the copies), and no
    weight on yaw (its residual is free): the value is still the LP's."""
    C = np.hstack([T[:, :6], T[:, :6]])
    lp = Lp(C, 0.01 * np.concatenate([THRUST[:6], THRUST[:6]]), np.array([5.0, 1.0, 0.0]))
    rng = np.random.default_rng(11)
    for _ in range(40):
        rhs = rng.normal(0.0, 300.0, 3)
        assert lp.solve(rhs) >= 0
        _check_optimal(lp, rhs, _highs_value(lp, rhs))


def test_demands_beyond_every_jets_authority_saturate_the_useful_jets():
    lp = Lp(T, 0.01 * THRUST, np.array([5.0, 1.0, 1.0]))
    for rhs in (np.array([1e5, 0.0, 0.0]), np.array([-1e5, 3e4, -2e4]), 1e6 * AXIS):
        assert lp.solve(rhs) >= 0
        _check_optimal(lp, rhs, _highs_value(lp, rhs))
        d = lp.x[:18]
        useful = (lp.y @ T - 0.01 * THRUST) > 1e-9     # a jet whose torque pays more than its penalty
        assert np.all(d[useful] == 1.0)


def test_the_basis_left_for_the_next_cycle_is_consistent():
    lp = Lp(T, 0.01 * THRUST, np.array([5.0, 1.0, 1.0]))
    lp.solve(np.array([-300.0, 50.0, 20.0]))
    assert sorted(np.flatnonzero(lp.state == BASIC)) == sorted(lp.basis)
    assert abs(np.linalg.det(lp.A[:, lp.basis])) > 1e-9


# -- the realiser flies the kernel
RUN82 = JetHealth.of(failed_off=(1, 7, 8), stuck_on=(14, 15))
PARAMS = load_params(Allocator.PARAMS)


def _setup():
    al = Allocator(T, THRUST, PARAMS)
    al.set_health(RUN82)
    return al, DutyCycleRealiser(AXIS, T, THRUST)


DEMANDS = [-300.0 * AXIS, np.array([-600.0, -150.0, -120.0]), np.array([-800.0, 600.0, -250.0]), 200.0 * AXIS]


def _lp_value(dc, al, u):
    usable = RUN82.usable()
    C, b = dc._cols[:, usable], dc._bias
    return float(al.w @ np.abs(u - b - C @ dc.d[usable]) + (al.penalty_per_N * THRUST[usable]) @ dc.d[usable])


def test_the_realiser_solves_its_lp_without_highs(monkeypatch):
    al, dc = _setup()
    monkeypatch.setitem(sys.modules, "highspy", None)          # any `import highspy` now fails
    for u in DEMANDS:
        dc.duty_cycles(al, u)
        assert not dc.fell_back and dc.pivots >= 0
        lp = Lp(dc._cols[:, RUN82.usable()], al.penalty_per_N * THRUST[RUN82.usable()], al.w)
        assert _lp_value(dc, al, u) == pytest.approx(_highs_value(lp, u - dc._bias), rel=REL)
    assert dc.fallbacks == 0


def test_a_failed_kernel_falls_back_to_highs_counted_and_restarts_cold(monkeypatch):
    al, dc = _setup()
    dc.duty_cycles(al, DEMANDS[0])
    monkeypatch.setattr(dutycycle_module, "duty_cycles_kernel", lambda *args: ITERATION_LIMIT)
    for u in DEMANDS[1:3]:
        dc.duty_cycles(al, u)
        assert dc.fell_back
        lp = Lp(dc._cols[:, RUN82.usable()], al.penalty_per_N * THRUST[RUN82.usable()], al.w)
        assert _lp_value(dc, al, u) == pytest.approx(_highs_value(lp, u - dc._bias), rel=1e-7)
    assert dc.fallbacks == 2 and dc._cold
    monkeypatch.undo()
    dc.duty_cycles(al, DEMANDS[3])
    assert not dc.fell_back and dc.fallbacks == 2


def test_a_rehearsal_between_modulated_cycles_changes_no_answer():
    """Real time rehearses the LP before each release for a demand near the next one: the flown
    jets, torques, duty cycles and accumulators equal those of a flight never rehearsed."""
    (al, dc), (ref_al, ref) = _setup(), _setup()
    rng = np.random.default_rng(5)
    u = -300.0 * AXIS
    modulated = 0
    for _ in range(120):
        dc.rehearse(al, u + rng.normal(0.0, 30.0, 3))
        u = u + rng.normal(0.0, 15.0, 3)
        jets, ref_jets = dc.solve(al, u), ref.solve(ref_al, u)
        modulated += dc.modulated
        assert dc.modulated == ref.modulated
        for a, b in ((jets, ref_jets), (dc.tau_B, ref.tau_B), (dc.d, ref.d), (dc.acc, ref.acc),
                     (dc._basis, ref._basis), (dc._state, ref._state)):
            assert np.array_equal(a, b)
    assert modulated > 60 and np.any(dc._d_r != 0.0)      # modulated flights, and rehearsals that solved
