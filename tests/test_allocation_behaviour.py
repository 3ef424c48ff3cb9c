"""Allocator behaviour with hand-derived truth: designed ties, infeasible (degraded)
allocation, fault tolerance off, bad input, parameters, table cache (docs/fsw/index.md)."""
import numpy as np
import pytest

from common.config import ConfigError
from common.model import load_vehicle
from fsw.allocation import Allocator
from fsw.allocation.reference import solve_enumeration, solve_highs
from fsw.health import DEGRADED, FAILED_OFF, STUCK_ON, JetHealth
from fsw.params import load_params

VEH = load_vehicle("ellipsled")
T, THRUST = VEH.torque_matrix_Nm, VEH.thrust_N


def _params(w=(1.0, 1.0, 1.0), pen=0.01, ft=1, spill_jets=0.0):
    """The paper's sign box unless spill_jets says otherwise."""
    return {"allocator.w_roll": w[0], "allocator.w_pitch": w[1], "allocator.w_yaw": w[2],
            "allocator.penalty_per_N": pen, "allocator.fault_tolerance": ft,
            "allocator.spill_jets": spill_jets}


def _jets(u):
    return [k + 1 for k in np.flatnonzero(u)]


# ------------------------------------------------------------------ designed ties
def test_identical_jets_tie_goes_to_the_lower_jet_number():
    # jets 1 and 7 have identical columns and thrust: demand = T1 exactly
    al = Allocator(T, THRUST, _params())
    assert _jets(al.solve(T[:, 0].copy())) == [1]
    assert al.objective == pytest.approx(0.01 * 14)
    h = JetHealth()
    h.set(1, FAILED_OFF)
    al.set_health(h)
    assert _jets(al.solve(T[:, 0].copy())) == [7]


def test_zero_demand_fires_nothing_even_with_zero_penalty():
    # jets 1,2,4,5 sum to zero torque: with no penalty it ties with u = 0; 0 is the smaller pattern
    np.testing.assert_allclose(T[:, [0, 1, 3, 4]].sum(axis=1), 0.0, atol=1e-12)
    al = Allocator(T, THRUST, _params(pen=0.0))
    assert not al.solve(np.zeros(3)).any()
    assert al.objective == 0.0


def test_penalty_breaks_a_tie_before_the_bit_pattern():
    # three jets, hand-derived: j3 alone gives the same torque as j1 + j2
    Tm = np.array([[10.0, 0.0, 10.0], [0.0, 10.0, 10.0], [0.0, 0.0, 0.0]])
    d = np.array([10.0, 10.0, 0.0])
    # j3 costs 2 N (= j1 + j2): exact tie in objective and penalty -> smaller pattern {1,2} (=3) over {3} (=4)
    al = Allocator(Tm, np.array([1.0, 1.0, 2.0]), _params(pen=0.1))
    assert _jets(al.solve(d)) == [1, 2]
    assert al.objective == pytest.approx(0.2)
    # j3 costs 1.5 N: cheaper, so it wins although its pattern is larger
    al = Allocator(Tm, np.array([1.0, 1.0, 1.5]), _params(pen=0.1))
    assert _jets(al.solve(d)) == [3]
    assert al.objective == pytest.approx(0.15)
    # zero penalty: every way to reach (10,10,0) ties; pattern decides -> {1,2}
    al = Allocator(Tm, np.array([1.0, 1.0, 1.5]), _params(pen=0.0))
    assert _jets(al.solve(d)) == [1, 2]


def test_objective_tie_between_different_torques_goes_to_smaller_penalty():
    # j1 = (10,0,0) 1 N, j2 = (0,10,0) 2 N, w = (1, 1, 0), penalty 1 per N:
    # d = (10, 10, 0): {} -> 20, {1} -> 10 + 1 = 11, {2} -> 10 + 2 = 12, {1,2} -> 0 + 3 = 3
    Tm = np.array([[10.0, 0.0], [0.0, 10.0], [0.0, 0.0]])
    al = Allocator(Tm, np.array([1.0, 2.0]), _params(w=(1, 1, 0), pen=1.0))
    assert _jets(al.solve(np.array([10.0, 10.0, 0.0]))) == [1, 2]
    assert al.objective == pytest.approx(3.0)
    # w = (0.1, 0.1, 0), d = (10, 0, 0): {} -> 0.1 * 10 = 1.0, {1} -> 0 + 1 * 1 N = 1.0,
    # {2} overshoots pitch: an objective tie between different torques -> smaller penalty {}
    al = Allocator(Tm, np.array([1.0, 2.0]), _params(w=(0.1, 0.1, 0), pen=1.0))
    assert not al.solve(np.array([10.0, 0.0, 0.0])).any()
    assert al.objective == pytest.approx(1.0)


# ------------------------------------------------------------------ degraded (infeasible)
def test_stuck_jet_makes_opposite_demand_infeasible_and_degraded():
    # one jet stuck on at (+10,0,0), one usable jet (-4,0,0): demand (-5,0,0) cannot be met in the box
    Tm = np.array([[10.0, -4.0], [0.0, 0.0], [0.0, 0.0]])
    h = JetHealth(2)
    h.set(1, STUCK_ON)
    al = Allocator(Tm, np.array([1.0, 1.0]), _params(pen=0.0))
    al.set_health(h)
    u = al.solve(np.array([-5.0, 0.0, 0.0]))
    # unconstrained: tau = 10 - 4 = 6 (|-5-6| = 11) beats tau = 10 (15)
    assert _jets(u) == [2] and al.degraded
    np.testing.assert_allclose(al.tau_B, [6.0, 0.0, 0.0])
    assert al.objective == pytest.approx(11.0)
    u = al.solve(np.array([8.0, 0.0, 0.0]))            # 6 is inside [0, 8]: feasible again
    assert _jets(u) == [2] and not al.degraded
    assert al.objective == pytest.approx(2.0)


def test_paper_case2_stuck_jets_degrade_some_demands_and_highs_agrees():
    h = JetHealth()
    for j in (2, 3, 4, 5, 8, 9, 10):
        h.set(j, STUCK_ON)
    al = Allocator(T, THRUST, {**load_params(Allocator.PARAMS), "allocator.spill_jets": 0.0})   # sign box
    al.set_health(h)
    bias = T[:, [1, 2, 3, 4, 7, 8, 9]].sum(axis=1)
    d = -bias                                         # straight against the stuck bias
    al.solve(d)
    u_h, obj_h, deg_h = solve_highs(T, THRUST, h, al.w, al.penalty_per_N, d)
    assert al.degraded and deg_h
    assert al.objective == pytest.approx(obj_h, abs=1e-6)


# ------------------------------------------------------------------ fault tolerance off
def test_fault_tolerance_off_ignores_health():
    h = JetHealth()
    for j in (1, 2, 17, 18):
        h.set(j, FAILED_OFF)
    h.set(5, STUCK_ON)
    h.set(14, DEGRADED, 0.5)
    h.inhibited[9] = True
    on = Allocator(T, THRUST, load_params(Allocator.PARAMS))
    off = Allocator(T, THRUST, {**load_params(Allocator.PARAMS), "allocator.fault_tolerance": 0})
    nominal = Allocator(T, THRUST, load_params(Allocator.PARAMS))
    on.set_health(h)
    off.set_health(h)
    rng = np.random.default_rng(11)
    differ = 0
    for d in rng.normal(0, 300, (300, 3)):
        u_off = off.solve(d).copy()
        assert np.array_equal(u_off, nominal.solve(d))
        u_e, obj_e, _ = solve_enumeration(T, THRUST, h, off.w, off.penalty_per_N, d, fault_tolerance=False,
                                          spill=off.spill)
        assert np.array_equal(u_off, u_e) and off.objective == pytest.approx(obj_e)
        differ += not np.array_equal(u_off, on.solve(d))
    assert differ > 100                  # the health really changes the answer when on
    off.set_fault_tolerance(True)        # switching on adopts the stored health
    d = np.array([-200.0, 300.0, -300.0])
    assert np.array_equal(off.solve(d), on.solve(d))


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("bad", [[np.nan, 0, 0], [0, np.inf, 0], [0, 0, -np.inf]])
def test_non_finite_demand_is_rejected_with_all_jets_off(bad):
    h = JetHealth()
    h.set(13, STUCK_ON)
    al = Allocator(T, THRUST, load_params(Allocator.PARAMS))
    al.set_health(h)
    u = al.solve(np.array(bad, dtype=float))
    assert not u.any() and al.rejected and np.isnan(al.objective) and not al.degraded
    np.testing.assert_allclose(al.tau_B, T[:, 12])     # only the stuck jet acts
    al.solve(np.array([10.0, 10.0, 10.0]))
    assert not al.rejected and np.isfinite(al.objective)


def test_demand_of_wrong_shape_raises_and_lists_are_accepted():
    al = Allocator(T, THRUST, load_params(Allocator.PARAMS))
    with pytest.raises(ValueError, match="tau_d"):
        al.solve(np.zeros(4))
    with pytest.raises(ValueError, match="tau_d"):
        al.solve("abc")
    u = al.solve([41.72, 0.0, 0.0])
    assert u.dtype == np.uint8 and u.shape == (18,)
    assert al.solve(np.zeros((3, 2))[:, 0]) is u       # strided input coerced; same output array


@pytest.mark.parametrize("name,value", [("allocator.w_roll", -1.0), ("allocator.penalty_per_N", np.nan),
                                         ("allocator.fault_tolerance", 0.5), ("allocator.w_yaw", 1e9)])
def test_bad_parameters_are_refused_with_their_name(name, value):
    with pytest.raises(ValueError, match=name):
        Allocator(T, THRUST, {**load_params(Allocator.PARAMS), name: value})


def test_defaults_load_and_overrides_are_validated():
    p = load_params(Allocator.PARAMS)
    assert p["allocator.fault_tolerance"] == 1.0 and p["allocator.penalty_per_N"] >= 0
    with pytest.raises(ConfigError, match="allocator.w_pitch"):
        load_params(Allocator.PARAMS, {"allocator": {"w_pitch": -3}})


def test_bad_matrix_or_health_is_refused():
    with pytest.raises(ValueError, match="torque_matrix_Nm"):
        Allocator(T[:2], THRUST, load_params(Allocator.PARAMS))
    with pytest.raises(ValueError, match="thrust_N"):
        Allocator(T, THRUST[:5], load_params(Allocator.PARAMS))
    al = Allocator(T, THRUST, load_params(Allocator.PARAMS))
    with pytest.raises(ValueError, match="health"):
        al.set_health(JetHealth(5))


# ------------------------------------------------------------------ tables, cache, hot path
def test_distinct_torque_count_and_cache():
    al = Allocator(T, THRUST, load_params(Allocator.PARAMS))
    # 6 pairs of identical 14 N columns (3 choices each) x 6 single 95 N columns: 3^6 * 2^6
    assert al._tables.n_raw == 3 ** 6 * 2 ** 6
    assert 10_000 < al.n_candidates < 15_000           # ~13,000 distinct torques (spec)
    h = JetHealth()
    h.set(3, FAILED_OFF)
    al.set_health(h)
    assert not al.tables_from_cache and 0 < al.rebuild_time_s < 1.0   # generous sanity bound
    al.set_health(JetHealth())
    assert al.tables_from_cache
    al.set_health(h)
    assert al.tables_from_cache


def test_solve_reuses_its_output_array():
    al = Allocator(T, THRUST, load_params(Allocator.PARAMS))
    u1 = al.solve(np.array([100.0, 0.0, -50.0]))
    u2 = al.solve(np.array([-300.0, 20.0, 50.0]))
    assert u1 is u2 is al.u
