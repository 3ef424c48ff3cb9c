"""The bank authority across the edge where the jets alone stop cancelling a stuck-on bias.

The case is a dispersed guided run (master seed 1111, run 27): jets 8, 13, 17 off, 2 and 16 stuck
on, 11, 15, 18 degraded. Jet 15 pushes against the stuck-on jet 16; whether the jets alone
cancel the bias turns on jet 15's efficiency, which FDIR estimates to about a per cent (flown:
0.4712 against a truth of 0.4652). Truth, independent of HiGHS's formulation here: a jet's
columns scale with its efficiency, so the average torques the jets hold only grow with it, and
the best weak way over the same trims can only grow (monotone in eta); each answer's authority
with its own trim held, from scipy's LP (tests/lp_oracle.py ``weak_way_truth``); the
smallest trim checked against a grid of trims.
"""
import math

import numpy as np
import pytest

from common.model import load_vehicle
from fsw.controllability import aero_moment_per_rad, controllability, inertia_corners, jet_columns, velocity_dir_B
from fsw.health import JetHealth

from tests.lp_oracle import weak_way_truth

VEH = load_vehicle("ellipsled")
T = np.asarray(VEH.torque_matrix_Nm, float)
I_NOM = np.asarray(VEH.inertia_kgm2, float)
V_B = velocity_dir_B(VEH.aero.alpha_trim_rad)
A = aero_moment_per_rad(2000.0, VEH.S_ref_m2, VEH.l_ref_m, VEH.aero.C_lbeta, VEH.aero.C_malpha, VEH.aero.C_nbeta)
W = inertia_corners(I_NOM, V_B, 0.0)


def _health(eta15):
    return JetHealth.of(failed_off=[8, 13, 17], stuck_on=[2, 16], degraded=[(11, 0.5954), (15, eta15), (18, 0.5485)])


def _weak(r):
    return min(r.authority_pos_radps2, r.authority_neg_radps2)


def _theta(r):
    return np.radians([r.trim_alpha_deg, r.trim_beta_deg])


def test_the_weak_way_grows_with_the_thrust_of_the_jet_that_cancels_the_bias():
    """Sweeping jet 15's efficiency across the edge (jets alone cancel the bias from about 0.475):
    the weaker way never falls as the jet gets stronger, and each answer is the authority of its
    own trim. (Allowing a trim only once the jets cannot cancel the bias dropped the weak way from
    1.4 to 0.04 deg/s^2 at the edge: 0.4652 and 0.4712, truth and FDIR's estimate, 100x apart.)"""
    weak = []
    for eta in np.linspace(0.40, 0.56, 17):
        h = _health(eta)
        r = controllability(T, h, I_NOM, V_B, A, 5.0, 0.0, qbar_pa=2000.0)
        C, b = jet_columns(T, h)
        assert _weak(r) == pytest.approx(weak_way_truth(C, b, A, W, _theta(r)), rel=1e-6, abs=1e-9)
        assert np.max(np.abs(_theta(r))) <= math.radians(5.0) * (1 + 1e-6)
        weak.append(_weak(r))
    assert all(b >= a * (1 - 1e-6) for a, b in zip(weak, weak[1:]))
    truth, est = (_weak(controllability(T, _health(e), I_NOM, V_B, A, 5.0, 0.0, qbar_pa=2000.0))
                  for e in (0.4652, 0.4712))
    assert est >= truth * (1 - 1e-6) and truth > math.radians(1.0)


def test_while_the_jets_cancel_the_bias_the_trim_is_the_smallest_that_gives_what_the_reference_can_use():
    """On the jets' side of the edge, asked for at most ``weak_enough``: the weaker way is exactly
    that (the jets alone give 0.04 deg/s^2), and no trim on a 0.1-deg grid smaller (sum of
    |theta_i|) than the answer's by more than the grid's step gives it. A weak way the jets give
    without a trim gets none, exactly zero (the guidance flies no offset: the flight is unchanged)."""
    enough = math.radians(1.0) / 0.75
    h = _health(0.4712)
    C, b = jet_columns(T, h)
    assert weak_way_truth(C, b, A, W, np.zeros(2)) < math.radians(0.05)
    r = controllability(T, h, I_NOM, V_B, A, 5.0, 0.0, qbar_pa=2000.0, weak_enough_radps2=enough)
    assert _weak(r) == pytest.approx(enough, rel=1e-6)
    norm = np.sum(np.abs(_theta(r)))
    grid = np.radians(np.arange(-3.0, 3.0001, 0.1))
    step = math.radians(0.1)
    smaller = [(x, y) for x in grid for y in grid if abs(x) + abs(y) < norm - 2 * step]
    assert smaller and all(weak_way_truth(C, b, A, W, np.array(t)) < enough for t in smaller)
    # the jets alone give it: no trim at all
    h_ok = JetHealth.of(failed_off=[2], stuck_on=[4, 12], degraded=[(13, .7), (18, .3)])
    C2, b2 = jet_columns(T, h_ok)
    low = math.radians(0.5)
    assert weak_way_truth(C2, b2, A, W, np.zeros(2)) > low
    r_ok = controllability(T, h_ok, I_NOM, V_B, A, 5.0, 0.0, qbar_pa=2000.0, weak_enough_radps2=low)
    assert r_ok.trim_alpha_deg == 0.0 and r_ok.trim_beta_deg == 0.0
    assert _weak(r_ok) == pytest.approx(weak_way_truth(C2, b2, A, W, np.zeros(2)), rel=1e-6)


def test_the_reference_keeps_its_limit_when_a_trim_gives_the_weaker_way_back():
    """The flight software's own reconfiguration (fsw/authority.py) on those faults, FDIR's
    estimate of jet 15, at 2 kPa: the weaker way reads what the reference can use (its limit over
    guidance.authority_use), the trim that gives it is flown, and the reference keeps the
    scenario's acceleration limit. With no trim allowed (trim_max_deg 0) the same answer is the
    jets' 0.01-0.04 deg/s^2 and the reference is re-planned to authority_use of that."""
    from common.model import load_scenario
    from fsw.flightsoftware import FlightSoftware
    sc = load_scenario("guided-case2")        # a guided entry: no schedule need under the reference's limit

    def fsw(**over):
        f = FlightSoftware(sc, param_overrides={"guidance": over} if over else None)
        f.nav.state.qbar_pa = 2000.0
        f.fdir.health_active = _health(0.4712)
        f.t_s = 3.0
        f.health_changed()
        return f
    f = fsw()
    use = f.params["guidance.authority_use"]
    assert _weak(f.controllability) == pytest.approx(sc.bank_accel_limit_radps2 / use, rel=1e-6)
    assert max(abs(f.controllability.trim_alpha_deg), abs(f.controllability.trim_beta_deg)) > 0.1
    assert f.guidance.profile.accel_limit_radps2 == pytest.approx(sc.bank_accel_limit_radps2)
    f0 = fsw(trim_max_deg=0.0)
    assert _weak(f0.controllability) < math.radians(0.05)
    assert f0.guidance.profile.accel_limit_radps2 == pytest.approx(use * _weak(f0.controllability))
