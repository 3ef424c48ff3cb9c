"""The allocator is a global optimum with the spec's tie-break (docs/fsw/index.md), checked
against exhaustive enumeration on ≥ 10,000 demands over ≥ 20 configurations, and against
HiGHS (mip_rel_gap = 0) on ≥ 1,000 of them; the enumeration oracle itself is checked
against a plain Python loop."""
import itertools

import numpy as np
import pytest

from common.model import load_vehicle
from ellipsled.bench.allocator import cases, demands, params_for
from fsw.allocation import Allocator, effective_model
from fsw.allocation.model import TOL_BOX_NM, spill_of
from fsw.allocation.reference import solve_enumeration, solve_enumeration_many, solve_highs
from fsw.health import FAILED_OFF, STUCK_ON, JetHealth
from fsw.params import load_params

VEH = load_vehicle("ellipsled")
T, THRUST = VEH.torque_matrix_Nm, VEH.thrust_N
CASES = cases()
N_PER_CASE = 400            # 26 configurations x 400 = 10,400 demands
N_HIGHS_PER_CASE = 40       # 26 x 40 = 1,040 HiGHS solves


@pytest.fixture(scope="module")
def allocator():
    return Allocator(T, THRUST, load_params(Allocator.PARAMS))


def _obj_equal(a, b, rel):
    return abs(a - b) <= 1e-7 + rel * abs(b)


def test_there_are_at_least_20_configurations_including_the_paper_cases():
    names = [c.name for c in CASES]
    assert len(CASES) >= 20
    assert {"nominal", "case1-failed_off-1-2-17-18", "case2-stuck_on-2-3-4-5-8-9-10",
            "case3-degraded-3-7-14-15"} <= set(names)


def test_matches_exhaustive_enumeration_objective_choice_and_degraded_flag(allocator):
    total = n_degraded = 0
    for ci, case in enumerate(CASES):
        allocator.set_params(params_for(case))
        allocator.set_health(case.health)
        D = demands(T, THRUST, case, N_PER_CASE, seed=1000 + ci)
        U_e, obj_e, deg_e = solve_enumeration_many(T, THRUST, case.health, np.array(case.w),
                                                   case.penalty_per_N, D, case.fault_tolerance,
                                                   spill_of(T, case.spill_jets))
        usable, cols, b, ck = effective_model(T, THRUST, case.health, case.penalty_per_N,
                                              case.fault_tolerance)
        for i, d in enumerate(D):
            u = allocator.solve(d)
            ctx = f"{case.name} demand {i} {d!r}"
            assert allocator.degraded == deg_e[i], ctx
            assert _obj_equal(allocator.objective, obj_e[i], 1e-12), ctx
            assert np.array_equal(u, U_e[i]), ctx              # the tie-break rule
            assert not np.any(u[~usable]), ctx                  # failed/stuck/inhibited off
            tau = b + cols @ u                                  # tau_B is the modelled torque
            np.testing.assert_allclose(allocator.tau_B, tau, atol=1e-9, err_msg=ctx)
            if not allocator.degraded:       # inside the box: the sign box, widened by the spill
                e = spill_of(T, case.spill_jets)
                lo = np.minimum(d, 0.0) - e - TOL_BOX_NM
                hi = np.maximum(d, 0.0) + e + TOL_BOX_NM
                assert np.all((tau >= lo) & (tau <= hi)), ctx
            total += 1
            n_degraded += allocator.degraded
    assert total >= 10_000
    assert n_degraded > 100        # the infeasible branch is exercised, not just reachable


def test_matches_highs_on_a_subset(allocator):
    total = 0
    for ci, case in enumerate(CASES):
        allocator.set_params(params_for(case))
        allocator.set_health(case.health)
        D = demands(T, THRUST, case, N_HIGHS_PER_CASE, seed=5000 + ci)
        for d in D:
            allocator.solve(d)
            _, obj_h, deg_h = solve_highs(T, THRUST, case.health, np.array(case.w),
                                          case.penalty_per_N, d, case.fault_tolerance,
                                          spill_of(T, case.spill_jets))
            ctx = f"{case.name} {d!r}"
            assert allocator.degraded == deg_h, ctx
            assert _obj_equal(allocator.objective, obj_h, 1e-9), ctx
            total += 1
    assert total >= 1_000


def _naive(Tm, thrust, health, w, c, d, e=(0.0, 0.0, 0.0)):
    """Plain Python over every pattern of the usable jets (independent of the oracle);
    e: the box's allowance per axis (0: the sign box)."""
    usable = health.usable()
    eta = np.where(health.state == 3, health.eta, 1.0)
    b = sum((Tm[:, k] for k in range(Tm.shape[1]) if health.state[k] == STUCK_ON), np.zeros(3))
    idx = [k for k in range(Tm.shape[1]) if usable[k]]
    rows = []
    for bits in itertools.product((0, 1), repeat=len(idx)):
        u = np.zeros(Tm.shape[1], dtype=np.uint8)
        u[idx] = bits
        tau = b + (Tm * eta) @ u
        # the box with the stated slack: exact zero sums (e.g. 41.72 - 41.72 + ...) round to ~1e-14
        tol = TOL_BOX_NM
        feas = all(min(d[i], 0.0) - e[i] - tol <= tau[i] <= max(d[i], 0.0) + e[i] + tol for i in range(3))
        obj = float(np.sum(w * np.abs(d - tau)) + c * float(thrust @ u))
        pattern = sum(int(u[k]) << k for k in range(len(u)))
        rows.append((feas, obj, c * float(thrust @ u), pattern, u))
    pool = [r for r in rows if r[0]] or rows
    best = min(r[1] for r in pool)
    tied = [r for r in pool if r[1] <= best + 1e-9]
    min_pen = min(r[2] for r in tied)
    chosen = min((r for r in tied if r[2] <= min_pen + 1e-9), key=lambda r: r[3])
    return chosen[4], chosen[1], not any(r[0] for r in rows)


def test_enumeration_oracle_agrees_with_a_plain_python_loop():
    # 10 of 18 jets out of play keeps the naive loop at 256 patterns
    h = JetHealth()
    for j in (1, 2, 6, 8, 13, 17, 18):
        h.set(j, FAILED_OFF)
    h.set(10, STUCK_ON)
    h.set(3, 3, 0.5)
    h.inhibited[11] = True
    rng = np.random.default_rng(3)
    w = np.array([1.0, 1.5, 0.7])
    for e in ((0.0, 0.0, 0.0), (26.32, 283.1, 283.1), (0.0, 30.0, 100.0)):
        for d in np.vstack([rng.normal(0, 150, (40, 3)), [[0, 0, 0], [41.72, 0, 0], [-1e5, 3, 0]]]):
            u_n, obj_n, deg_n = _naive(T, THRUST, h, w, 0.02, d, e)
            u_e, obj_e, deg_e = solve_enumeration(T, THRUST, h, w, 0.02, d, spill=np.array(e))
            assert deg_e == deg_n
            assert obj_e == pytest.approx(obj_n, abs=1e-9)
            assert np.array_equal(u_e, u_n)


def test_the_spill_box_delivers_roll_the_sign_box_cannot_once_the_cancelling_pairs_are_gone():
    # jets 7, 16, 18 off and 1, 3, 8 degraded (a campaign fault set): every jet left that rolls
    # the vehicle negatively also pitches or yaws, so the sign box gives almost nothing of a
    # negative-roll demand with a small pitch/yaw demand; one jet's allowance per axis does
    h = JetHealth.of(failed_off=(7, 16, 18), degraded=((1, 0.5), (3, 0.6), (8, 0.8)))
    w = np.array([3.0, 1.0, 1.0])
    d = np.array([-500.0, -20.0, 10.0])
    u0, _, deg0 = solve_enumeration(T, THRUST, h, w, 0.01, d)
    u1, _, deg1 = solve_enumeration(T, THRUST, h, w, 0.01, d, spill=spill_of(T, 1.0))
    usable, cols, b, _ = effective_model(T, THRUST, h, 0.01)
    roll0, roll1 = (b + cols @ u0)[0], (b + cols @ u1)[0]
    assert not deg0 and not deg1
    assert roll0 > -20.0 and roll1 < -45.0
    assert np.all(np.abs((b + cols @ u1)[1:] - d[1:]) <= np.abs(d[1:]) + spill_of(T, 1.0)[1:] + 1e-9)
