"""Guidance reference attitude: the wind-frame rate against a finite difference of C_WN along a
propagated trajectory, omega_R / sigma_r_dot / sigma_r_ddot against finite differences,
C_RN against its definition, and the nearest shadow set keeping eps continuous."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from common import frames, mrp
from fsw.guidance.reference import BankProfile, Guidance
from fsw.navigation import NavState

MU = 4.2828e13
R_M = 3396.2e3
OMEGA = 7.0882e-4          # 10x Mars, so that a wrong rotating-frame term would show
ALPHA = math.radians(20.0)
D_ACC, L_ACC, BANK_TRAJ = 15.0, 6.0, math.radians(40.0)


def _a_ng_N(r, v):
    """Non-gravitational acceleration: drag along -w1, lift at a fixed bank (test's own model)."""
    vrel = frames.v_rel_N(r, v, OMEGA)
    C_WN = frames.wind_dcm(r, vrel)
    w1, w2, w3 = C_WN
    lift = math.sin(BANK_TRAJ) * w2 - math.cos(BANK_TRAJ) * w3
    return -D_ACC * w1 + L_ACC * lift


def _rhs(t, x):
    r, v = x[:3], x[3:]
    return np.concatenate((v, -MU * r / np.linalg.norm(r) ** 3 + _a_ng_N(r, v)))


@pytest.fixture(scope="module")
def trajectory():
    lat = math.radians(30.0)
    r0 = (R_M + 60e3) * np.array([math.cos(lat), 0.0, math.sin(lat)])
    east, north, up = np.array([0.0, 1.0, 0.0]), np.array([-math.sin(lat), 0, math.cos(lat)]), r0 / np.linalg.norm(r0)
    gam, psi, V = math.radians(-5.0), math.radians(60.0), 5000.0
    vrel = V * (math.cos(gam) * (math.sin(psi) * east + math.cos(psi) * north) + math.sin(gam) * up)
    v0 = vrel + np.cross([0, 0, OMEGA], r0)
    h = 1e-3
    times = [2.0, 3.0, 4.0]
    t_eval = sorted(t + k * h for t in times for k in (-1, 0, 1))
    sol = solve_ivp(_rhs, (0.0, 4.5), np.concatenate((r0, v0)), method="DOP853", rtol=1e-13, atol=1e-9,
                    t_eval=t_eval)
    assert sol.success
    states = {round(t, 6): sol.y[:, i] for i, t in enumerate(sol.t)}
    return states, times, h


def _profile():
    # a 1 rad reversal from t = 1 s lasting 3.75 s: the test times are inside it
    return BankProfile([(0.0, 0.5), (1.0, -0.5)], 0.5, 0.5)


def _nav(t, x, C_BN):
    n = NavState()
    n.t_s = t
    n.r_N[:] = x[:3]
    n.v_N[:] = x[3:]
    n.vrel_N[:] = frames.v_rel_N(n.r_N, n.v_N, OMEGA)
    n.V_rel_mps = float(np.linalg.norm(n.vrel_N))
    n.C_WN[:] = frames.wind_dcm(n.r_N, n.vrel_N)
    n.C_BN[:] = C_BN
    n.sigma_BN[:] = mrp.from_dcm(C_BN)
    n.accel_B[:] = C_BN @ _a_ng_N(n.r_N, n.v_N)
    return n


def _C_RN(phi, C_WN):
    return frames.R2(ALPHA) @ frames.R1(phi) @ C_WN


def test_wind_rate_and_reference_rates_match_finite_differences(trajectory):
    states, times, h = trajectory
    prof = _profile()
    g = Guidance(prof, ALPHA, OMEGA, mu_m3ps2=MU)
    # a body attitude near the reference (fixed), so one MRP set is used throughout
    x_mid = states[round(times[1], 6)]
    C_WN_mid = frames.wind_dcm(x_mid[:3], frames.v_rel_N(x_mid[:3], x_mid[3:], OMEGA))
    C_BN = frames.R3(0.05) @ _C_RN(prof.evaluate(times[1])[0], C_WN_mid)
    checked_wind = 0.0
    for t in times:
        rec = {}
        for k in (-1, 0, 1):
            tk = round(t + k * h, 6)
            n = _nav(tk, states[tk], C_BN)
            g.update(n)
            rec[k] = dict(C_WN=n.C_WN.copy(), C_RN=_C_RN(g.phi_r, n.C_WN), sigma=g.sigma_RN.copy(),
                          sdot=g.sigma_r_dot.copy(), sddot=g.sigma_r_ddot.copy(), wW=g.omega_WN_W.copy(),
                          wR=g.omega_RN_R.copy(), dwR=g.domega_RN_R.copy())
        c = rec[0]
        # C_RN of the guidance equals its definition R2(alpha) R1(phi_r) C_WN
        assert np.allclose(mrp.to_dcm(c["sigma"]), c["C_RN"], atol=1e-12)
        # dC/dt = -[omega x] C  =>  [omega x] = -Cdot C^T
        # (central-difference truncation h^2/6 * third derivative: jerk 1.1 rad/s^3 -> ~2e-7 for R)
        for key, wkey, tol in (("C_WN", "wW", 2e-9), ("C_RN", "wR", 5e-7)):
            Cdot = (rec[1][key] - rec[-1][key]) / (2 * h)
            Wt = -Cdot @ c[key].T
            w_fd = np.array([Wt[2, 1], Wt[0, 2], Wt[1, 0]])
            assert np.allclose(w_fd, c[wkey], atol=tol, rtol=0), (key, w_fd, c[wkey])
        checked_wind = max(checked_wind, float(np.linalg.norm(c["wW"])))
        # sigma_r_dot against a finite difference of sigma_r
        assert np.allclose((rec[1]["sigma"] - rec[-1]["sigma"]) / (2 * h), c["sdot"], atol=1e-7, rtol=0)
        # the neglected d(omega_WN)/dt is ~1e-5 rad/s^2 here; the phidot * (omega_W x w1)
        # term it keeps is ~5e-4, so this tolerance still checks that term
        assert np.allclose((rec[1]["wR"] - rec[-1]["wR"]) / (2 * h), c["dwR"], atol=3e-5, rtol=0)
        assert np.allclose((rec[1]["sdot"] - rec[-1]["sdot"]) / (2 * h), c["sddot"], atol=3e-5, rtol=0)
    assert checked_wind > 5e-4            # the wind frame really turns at the 1e-3 rad/s level


def test_wind_rate_without_gravity_or_rotation_terms_would_fail_the_check(trajectory):
    """The check above is sensitive: dropping gravity changes omega_W by ~g/V ~ 6e-4 rad/s."""
    states, times, h = trajectory
    g_ok = Guidance(_profile(), ALPHA, OMEGA, mu_m3ps2=MU)
    g_bad = Guidance(_profile(), ALPHA, OMEGA, mu_m3ps2=0.0)
    t = round(times[0], 6)
    n = _nav(t, states[t], np.eye(3))
    g_ok.update(n)
    g_bad.update(n)
    assert np.linalg.norm(g_ok.omega_WN_W - g_bad.omega_WN_W) > 1e-4


def test_nearest_shadow_set_keeps_eps_continuous_through_a_180_deg_reference():
    """C_RN passes a 180 deg rotation (principal MRP |sigma_r| -> 1 and flips), the body follows
    2 deg off; eps = sigma - sigma_r stays continuous because sigma_r takes the set nearest sigma."""
    target = frames.R1(-math.pi / 2) @ frames.R2(-ALPHA)      # C_WN making C_RN = R2 R1(phi - pi/2) R2^T
    w1, w2, w3 = target
    V, R0 = 5000.0, R_M + 50e3
    prof = BankProfile([(0.0, math.radians(-80.0)), (1.0, math.radians(-100.0))], 1.0, 1.0)
    g = Guidance(prof, ALPHA, 0.0, mu_m3ps2=0.0)
    offset = frames.R1(0.02) @ frames.R2(-0.03)
    n = NavState()
    n.r_N[:] = -R0 * w3
    n.v_N[:] = V * w1
    n.vrel_N[:] = n.v_N
    n.V_rel_mps = V
    n.C_WN[:] = frames.wind_dcm(n.r_N, n.vrel_N)
    assert np.allclose(n.C_WN, target, atol=1e-12)
    sig_prev, eps_prev, sr_prev = None, None, None
    max_eps_step, max_sr_principal_step = 0.0, 0.0
    for t in np.arange(0.0, 3.0, 0.02):
        n.t_s = t
        C_RN = _C_RN(prof.evaluate(t)[0], n.C_WN)
        C_BN = offset @ C_RN
        s = mrp.from_dcm(C_BN)
        if sig_prev is not None and np.linalg.norm(mrp.shadow(s) - sig_prev) < np.linalg.norm(s - sig_prev):
            s = mrp.shadow(s)                    # the body attitude as a continuous MRP
        n.C_BN[:] = C_BN
        n.sigma_BN[:] = s
        g.update(n)
        eps = n.sigma_BN - g.sigma_RN
        sr_principal = mrp.from_dcm(C_RN)
        if eps_prev is not None:
            max_eps_step = max(max_eps_step, float(np.linalg.norm(eps - eps_prev)))
            max_sr_principal_step = max(max_sr_principal_step, float(np.linalg.norm(sr_principal - sr_prev)))
        sig_prev, eps_prev, sr_prev = s.copy(), eps, sr_principal
    assert max_sr_principal_step > 1.0        # the principal set does jump (non-vacuous)
    assert max_eps_step < 2e-3                # eps does not


def test_a_trim_offset_moves_the_references_alpha_and_beta_and_keeps_its_bank(trajectory):
    states, times, _ = trajectory
    g = Guidance(_profile(), ALPHA, OMEGA, mu_m3ps2=MU)
    x = states[round(times[0], 6)]
    C_WN = frames.wind_dcm(x[:3], frames.v_rel_N(x[:3], x[3:], OMEGA))
    nav = _nav(times[0], x, _C_RN(0.0, C_WN))
    g.trim_offset_alpha_rad, g.trim_offset_beta_rad = math.radians(3.0), math.radians(-2.0)
    g.update(nav)
    # independent truth: the convention of common/frames.py, C_RN = R2(alpha) R3(-beta) R1(bank) C_WN
    C_RN = mrp.to_dcm(np.array(g.sigma_RN))
    want = frames.R2(ALPHA + math.radians(3.0)) @ frames.R3(math.radians(2.0)) @ frames.R1(g.phi_r) @ C_WN
    np.testing.assert_allclose(C_RN, want, atol=1e-12)
    a, b, phi = frames.aero_angles(C_RN, C_WN)
    assert (a, b, phi) == pytest.approx((ALPHA + math.radians(3.0), math.radians(-2.0), g.phi_r), abs=1e-12)
