"""The guided scenarios' roll weight (docs/fsw/allocation.md "The roll weight of guided flights").

Once failures remove the jet pairs that cancel exactly, the jets left that roll the vehicle also
pitch and yaw. A small jet gives 26.32 N m of roll for 41.72 N m of pitch and of yaw: with the
pitch and yaw demands met, firing it lowers the weighted roll error by w_roll * 26.32 and raises
the pitch and yaw errors by w_pitch * 41.72 + w_yaw * 41.72, so below the break-even
w_roll = (41.72 + 41.72) / 26.32 = 3.17 the exact allocator never spends a small jet on roll and
the bank axis gets only what comes free. Independent truth: the break-even from the vehicle's
torque matrix, and the exhaustive enumeration of every jet pattern (fsw/allocation/reference.py).
"""
import numpy as np
import pytest

from common.model import load_scenario, load_vehicle
from fsw.allocation import Allocator
from fsw.allocation.model import spill_of
from fsw.allocation.reference import solve_enumeration
from fsw.health import FAILED_OFF, STUCK_ON, JetHealth
from fsw.params import load_params

VEH = load_vehicle("ellipsled")
T, THRUST = np.asarray(VEH.torque_matrix_Nm), np.asarray(VEH.thrust_N)
GUIDED = ["guided-nominal", "guided-west", "guided-case1", "guided-case2", "guided-case3", "guided-case4"]
BANK_AXIS = np.array([np.cos(VEH.aero.alpha_trim_rad), 0.0, np.sin(VEH.aero.alpha_trim_rad)])


def _break_even(w_pitch: float, w_yaw: float) -> float:
    """The smallest roll weight at which some jet's roll outweighs its own pitch and yaw."""
    roll = np.abs(T[0])
    has = roll > 0.0
    return float(np.min((w_pitch * np.abs(T[1, has]) + w_yaw * np.abs(T[2, has])) / roll[has]))


def _params(scenario: str | None) -> dict:
    return load_params(Allocator.PARAMS, load_scenario(scenario).fsw if scenario else None)


def _health_without_roll_pairs() -> JetHealth:
    """Jets 11, 14, 16, 18 failed off, 4 and 10 stuck on (a dispersed guided run's faults): no
    pair of jets left whose pitch and yaw cancel while their roll adds."""
    h = JetHealth()
    for j in (11, 14, 16, 18):
        h.set(j, FAILED_OFF)
    for j in (4, 10):
        h.set(j, STUCK_ON)
    return h


def test_break_even_of_this_vehicle_is_the_small_jets():
    assert _break_even(1.0, 1.0) == pytest.approx((41.72 + 41.72) / 26.32)


@pytest.mark.parametrize("scenario", GUIDED)
def test_guided_scenarios_weigh_roll_above_the_break_even(scenario):
    p = _params(scenario)
    assert p["allocator.w_roll"] > _break_even(p["allocator.w_pitch"], p["allocator.w_yaw"])


def test_paper_weights_stay_below_it():
    # the paper cases fly the defaults (unchanged): their roll weight does not pay for the spill
    p = _params(None)
    assert p["allocator.w_roll"] < _break_even(p["allocator.w_pitch"], p["allocator.w_yaw"])


@pytest.mark.parametrize("demand", [[-210.0, 0.0, 0.0], [-210.0, -19.0, -82.0], [-196.0, 28.0, -113.0]])
def test_guided_weights_give_the_bank_axis_the_small_jets(demand):
    """Demands of a slow braking reversal with these faults: the guided weights' exact answer (checked
    against the enumeration) turns the vehicle about the bank axis at least as hard as the
    paper's weights, and harder on the pure roll demand."""
    health = _health_without_roll_pairs()
    demand = np.array(demand)
    bank = {}
    for name, scenario in (("paper", None), ("guided", "guided-nominal")):
        p = _params(scenario)
        al = Allocator(T, THRUST, p)
        al.set_health(health)
        u = al.solve(demand.copy())
        w = np.array([p["allocator.w_roll"], p["allocator.w_pitch"], p["allocator.w_yaw"]])
        _, ref, _ = solve_enumeration(T, THRUST, health, w, p["allocator.penalty_per_N"], demand, True,
                                      spill_of(T, p["allocator.spill_jets"]))
        assert al.objective == pytest.approx(ref, abs=1e-9)
        assert not al.degraded
        tau = T[:, (u == 1) | (health.state == STUCK_ON)].sum(axis=1)
        assert np.allclose(tau, al.tau_B)
        bank[name] = float(BANK_AXIS @ tau)
    assert bank["guided"] <= bank["paper"] + 1e-9            # the demand is negative about the bank axis
    if demand[1] == demand[2] == 0.0:
        assert bank["guided"] < bank["paper"] - 10.0          # a second small jet's roll at least
