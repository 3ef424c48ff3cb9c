"""SAMI in closed loop with the test's own rigid body (Euler equation + MRP kinematics, RK4)
and a continuous (unquantised) actuator: exact parameters give the designed (s + lambda)^3
error response; wrong inertia is learned in the direction that reduces the error."""
import math

import numpy as np
import pytest

from common import frames, mrp
from common.model import inertia_matrix, inertia_vector, load_vehicle
from fsw.control import SamiController
from fsw.guidance.reference import BankProfile, Guidance
from fsw.navigation import NavState
from fsw.params import load_params

DT = 0.02
V_MPS, RHO = 5000.0, 2.4e-4          # q_bar = 3 kPa
VEH = load_vehicle("ellipsled")
ALPHA = VEH.aero.alpha_trim_rad


def _wind_frame():
    r = np.array([3396.2e3 + 40e3, 0.0, 0.0])
    v = V_MPS * np.array([0.0, math.cos(0.1), -math.sin(0.1)])
    return r, v, frames.wind_dcm(r, v)


def _aero_torque(C_BN, C_WN, omega, aero_scale):
    """Truth static + damping moments (docs/plant.md), test's own evaluation."""
    a = VEH.aero
    w1_B = C_BN @ C_WN[0]                     # v_rel direction in B: V [cos a cos b, sin b, sin a cos b]
    alpha, beta = math.atan2(w1_B[2], w1_B[0]), math.asin(max(-1.0, min(1.0, w1_B[1])))
    q = 0.5 * RHO * V_MPS ** 2
    k = VEH.l_ref_m / (2 * V_MPS)
    Cl = a.C_lbeta * aero_scale[0] * beta + a.C_lp * omega[0] * k
    Cm = a.C_malpha * aero_scale[1] * (alpha - ALPHA) + a.C_mq * omega[1] * k
    Cn = a.C_nbeta * aero_scale[2] * beta + a.C_nr * omega[2] * k
    return q * VEH.S_ref_m2 * VEH.l_ref_m * np.array([Cl, Cm, Cn])


def _deriv(x, I, Iinv, u, C_WN, aero_scale):
    s, w = x[:3], x[3:]
    tau = u + _aero_torque(mrp.to_dcm(s), C_WN, w, aero_scale)
    return np.concatenate((mrp.sigma_dot(s, w), Iinv @ (tau - np.cross(w, I @ w))))


def fly(profile, t_end, params=None, truth_h_scale=np.ones(6), aero_scale=(1.0, 1.0, 1.0), bank_err0_deg=5.0,
        n_sub=2):
    """Closed loop; returns (t, total attitude error [deg], controller, history of h_hat)."""
    prm = load_params(SamiController.PARAMS)
    prm.update(params or {})
    ctl = SamiController(prm, VEH, DT)
    guid = Guidance(profile, ALPHA, 0.0, mu_m3ps2=0.0)       # straight flight: W fixed
    r, v, C_WN = _wind_frame()
    I = inertia_matrix(inertia_vector(VEH.inertia_kgm2) * truth_h_scale)
    Iinv = np.linalg.inv(I)
    phi0 = profile.evaluate(0.0)[0]
    C_BN = frames.R2(ALPHA) @ frames.R1(phi0 + math.radians(bank_err0_deg)) @ C_WN
    x = np.concatenate((mrp.from_dcm(C_BN), np.zeros(3)))
    nav = NavState()
    nav.r_N[:], nav.v_N[:], nav.vrel_N[:], nav.C_WN[:] = r, v, v, C_WN
    nav.V_rel_mps, nav.rho_kgpm3 = V_MPS, RHO
    ts, errs, hs = [], [], []
    h = DT / n_sub
    for k in range(int(round(t_end / DT)) + 1):
        t = k * DT
        nav.t_s = t
        nav.sigma_BN[:] = x[:3]
        nav.omega_BN_B[:] = x[3:]
        nav.C_BN[:] = mrp.to_dcm(x[:3])
        nav.alpha_rad, nav.beta_rad, nav.bank_rad = frames.aero_angles(nav.C_BN, C_WN)
        guid.update(nav)
        u = ctl.update(nav, guid, None).copy()      # continuous actuator: delivered = commanded
        C_RN = frames.R2(ALPHA) @ frames.R1(guid.phi_r) @ C_WN
        cang = (np.trace(nav.C_BN @ C_RN.T) - 1.0) / 2.0
        ts.append(t)
        errs.append(math.degrees(math.acos(max(-1.0, min(1.0, cang)))))
        hs.append(ctl.h_hat.copy())
        for _ in range(n_sub):
            k1 = _deriv(x, I, Iinv, u, C_WN, aero_scale)
            k2 = _deriv(x + 0.5 * h * k1, I, Iinv, u, C_WN, aero_scale)
            k3 = _deriv(x + 0.5 * h * k2, I, Iinv, u, C_WN, aero_scale)
            k4 = _deriv(x + h * k3, I, Iinv, u, C_WN, aero_scale)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            x[:3] = mrp.switch_shadow(x[:3])
    return np.array(ts), np.array(errs), ctl, np.array(hs)


def test_exact_parameters_give_the_designed_error_response():
    """Exact inertia and aero (d = 1), static reference, 5 deg initial bank error: the error
    follows the (s + lambda)^3 response eps0 e^-lt (1 + lt - (lt)^2) and is below 0.1 deg in 8 s."""
    prof = BankProfile([(0.0, math.radians(30.0))], 0.1, 0.1)
    lam = 1.0
    t, err, ctl, _ = fly(prof, 10.0, params={"control.gamma_h": 0.0, "control.gamma_d": 0.0,
                                             "control.lambda_radps": lam})
    # continuous-time design response of the rotation angle (4 |eps| for small MRP errors)
    tau = lam * t
    ideal = 5.0 * np.abs(np.exp(-tau) * (1 + tau - tau ** 2))
    assert np.max(np.abs(err - ideal)) < 0.08          # discrete 50 Hz control, neglected C_a* eps_dot
    assert err[0] == pytest.approx(5.0, abs=1e-9)
    assert np.all(err[t >= 8.0] < 0.1)
    assert err[-1] < 0.03


@pytest.fixture(scope="module")
def oscillation():
    # +-40 deg roll oscillation (bank reversals every 10 s, 7.5 s transitions)
    sched = [(10.0 * k, math.radians(40.0 if k % 2 == 0 else -40.0)) for k in range(8)]
    return BankProfile(sched, math.radians(20.0), math.radians(10.0))


def test_wrong_inertia_is_learned_toward_truth_and_tracking_improves(oscillation):
    truth = np.array([1.25, 0.85, 0.80, 1.3, 1.3, 1.3])
    t_end = 60.0
    base = {"control.gamma_d": 0.0, "control.deadzone": 0.0}
    t, err_fixed, _, _ = fly(oscillation, t_end, params={**base, "control.gamma_h": 0.0},
                             truth_h_scale=truth, bank_err0_deg=0.0)
    t, err_adapt, ctl, hs = fly(oscillation, t_end, params=base, truth_h_scale=truth, bank_err0_deg=0.0)
    # the identifiable combination: inertia about the bank axis (w1 in body = [cos a, 0, sin a])
    e = np.array([math.cos(ALPHA), 0.0, math.sin(ALPHA)])
    h_nom = inertia_vector(VEH.inertia_kgm2)
    I_true = e @ inertia_matrix(h_nom * truth) @ e
    I_start = e @ inertia_matrix(h_nom) @ e
    I_end = e @ inertia_matrix(hs[-1]) @ e
    assert abs(I_end - I_true) < 0.2 * abs(I_start - I_true)        # most of the way to the truth
    assert abs(hs[-1][0] - truth[0] * h_nom[0]) < 0.2 * abs(h_nom[0] - truth[0] * h_nom[0])   # I11 too
    late = t >= 40.0
    rms_fixed = math.sqrt(np.mean(err_fixed[late] ** 2))
    rms_adapt = math.sqrt(np.mean(err_adapt[late] ** 2))
    assert rms_adapt < 0.2 * rms_fixed
    # the estimates stayed physical and inside the projection bounds throughout
    assert np.all(hs >= ctl.h_lo - 1e-9) and np.all(hs <= ctl.h_hi + 1e-9)
    for h in hs[::50]:
        ev = np.linalg.eigvalsh(inertia_matrix(h))
        assert ev[0] > 0 and ev[0] + ev[1] >= ev[2]
