"""SAMI algebra and robustness, each against a direct computation from the spec's definitions
(numpy matrices, np.linalg.inv for P_a) or an eigenvalue oracle."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from common import mrp
from common.model import inertia_matrix, inertia_vector, load_vehicle
from fsw.control import SamiController, physical_inertia, regressor_M
from fsw.navigation import NavState
from fsw.params import load_params

VEH = load_vehicle("ellipsled")
DT = 0.02
RNG = np.random.default_rng(12345)


def _random_h(rng):
    """A random physical inertia (principal moments obeying the triangle inequality, rotated)."""
    while True:
        m = rng.uniform(1000, 6000, 3)
        if m.sum() - m.max() >= m.max():
            break
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return inertia_vector(q @ np.diag(m) @ q.T)


def _direct(sigma, omega, h):
    """J, P_a, Jdot, I_a*, C_a* from their definitions (docs/fsw/index.md)."""
    B = mrp.B_matrix(sigma)
    J = 0.25 * B
    Pa = np.linalg.inv(J)
    sd = J @ omega
    Jdot = 0.25 * mrp.B_dot(sigma, sd)
    I = inertia_matrix(h)
    Ia = Pa.T @ I @ Pa
    Ca = Pa.T @ (-I @ Pa @ Jdot @ Pa + mrp.tilde(omega) @ I @ Pa)
    return J, Pa, Jdot, sd, Ia, Ca


def test_B_dot_matches_a_finite_difference():
    for _ in range(20):
        s, sd = RNG.normal(size=3) * 0.5, RNG.normal(size=3)
        h = 1e-6
        fd = (mrp.B_matrix(s + h * sd) - mrp.B_matrix(s - h * sd)) / (2 * h)
        assert np.allclose(fd, mrp.B_dot(s, sd), atol=1e-8)


def test_regressor_times_h_equals_Ia_sigma_r_ddot_plus_Ca_sigma_r_dot():
    for _ in range(200):
        sigma = RNG.normal(size=3) * RNG.uniform(0.05, 0.8)
        omega, srd, srdd = RNG.normal(size=3) * 0.3, RNG.normal(size=3) * 0.1, RNG.normal(size=3) * 0.05
        M = np.empty((3, 6))
        regressor_M(sigma, omega, srd, srdd, M)
        J, Pa, Jdot, sd, _, _ = _direct(sigma, omega, np.ones(6))
        Y = Pa.T @ M
        # column j of Y is the direct expression with the (linear) inertia of unit h_j
        for j in range(6):
            ej = np.zeros(6)
            ej[j] = 1.0
            _, _, _, _, Ia, Ca = _direct(sigma, omega, ej)
            col = Ia @ srdd + Ca @ srd
            assert np.allclose(Y[:, j], col, rtol=1e-12, atol=1e-12 * np.linalg.norm(col) + 1e-15)
        h = _random_h(RNG)
        _, _, _, _, Ia, Ca = _direct(sigma, omega, h)
        rhs = Ia @ srdd + Ca @ srd
        assert np.linalg.norm(Y @ h - rhs) <= 1e-12 * np.linalg.norm(rhs) + 1e-12


def test_mrp_plant_form_is_the_euler_equation():
    """I_a* sigma_ddot + C_a* sigma_dot = P_a^T tau for a rigid body (spec restated plant)."""
    for _ in range(50):
        sigma, omega, tau = RNG.normal(size=3) * 0.4, RNG.normal(size=3) * 0.3, RNG.normal(size=3) * 100
        h = _random_h(RNG)
        I = inertia_matrix(h)
        J, Pa, Jdot, sd, Ia, Ca = _direct(sigma, omega, h)
        wdot = np.linalg.solve(I, tau - np.cross(omega, I @ omega))
        sdd = Jdot @ omega + J @ wdot
        assert np.allclose(Ia @ sdd + Ca @ sd, Pa.T @ tau, rtol=1e-11, atol=1e-9)


def _controller(**over):
    prm = load_params(SamiController.PARAMS)
    prm.update(over)
    return SamiController(prm, VEH, DT)


def _nav(sigma, omega, alpha=0.37, beta=0.01, V=4000.0, rho=3e-4):
    n = NavState()
    n.sigma_BN[:] = sigma
    n.omega_BN_B[:] = omega
    n.alpha_rad, n.beta_rad, n.V_rel_mps, n.rho_kgpm3 = alpha, beta, V, rho
    return n


def _guid(sigma_RN, omega_R, domega_R):
    return SimpleNamespace(sigma_RN=np.array(sigma_RN, float), omega_RN_R=np.array(omega_R, float),
                           domega_RN_R=np.array(domega_R, float))


def _paper_u(ctl, nav, guid, eps_int):
    """Paper eq 18 from matrices: u = J^T [Y h - C_d eps_dot - K_d eps - K_i int eps] - L d."""
    lam = ctl.params["control.lambda_radps"]
    c_d, k_d, k_i = 3 * lam, 3 * lam ** 2, lam ** 3
    sigma, omega = nav.sigma_BN, nav.omega_BN_B
    sr = mrp.nearest_set(guid.sigma_RN, sigma)
    srd = 0.25 * mrp.B_matrix(sr) @ guid.omega_RN_R
    srdd = 0.25 * (mrp.B_dot(sr, srd) @ guid.omega_RN_R + mrp.B_matrix(sr) @ guid.domega_RN_R)
    h, d = ctl.h_hat.copy(), ctl.d_hat.copy()
    J, Pa, Jdot, sd, Ia, Ca = _direct(sigma, omega, h)
    eps, eps_dot = sigma - sr, sd - srd
    Y = np.column_stack([_direct(sigma, omega, np.eye(6)[j])[4] @ srdd + _direct(sigma, omega, np.eye(6)[j])[5] @ srd
                         for j in range(6)])
    a = VEH.aero
    L = (0.5 * VEH.S_ref_m2 * VEH.l_ref_m * nav.V_rel_mps ** 2
         * np.diag([nav.beta_rad, nav.alpha_rad - a.alpha_trim_rad, nav.beta_rad])
         @ np.diag([nav.rho_kgpm3 * a.C_lbeta, nav.rho_kgpm3 * a.C_malpha, nav.rho_kgpm3 * a.C_nbeta]))
    u = J.T @ (Y @ h - c_d * Ia @ eps_dot - k_d * Ia @ eps - k_i * Ia @ eps_int) - L @ d
    return u, dict(Y=Y, Pa=Pa, J=J, Ia=Ia, L=L, eps=eps, eps_dot=eps_dot)


def test_control_law_is_paper_eq18_and_update_law_is_eq27():
    ctl = _controller(**{"control.deadzone": 0.0})
    ctl.theta_hat[:6] = inertia_vector(VEH.inertia_kgm2) * [1.1, 0.9, 1.05, 1.2, 0.8, 1.1]
    ctl.theta_hat[6:] = [1.2, 0.8, 1.1]
    for _ in range(20):
        ctl._have_chart = False
        sigma = RNG.normal(size=3) * 0.3
        nav = _nav(sigma, RNG.normal(size=3) * 0.1)
        guid = _guid(sigma + RNG.normal(size=3) * 0.02, RNG.normal(size=3) * 0.1, RNG.normal(size=3) * 0.02)
        ctl.eps_int[:] = RNG.normal(size=3) * 0.01
        ei = ctl.eps_int.copy()
        th0 = ctl.theta_hat.copy()
        u_ref, m = _paper_u(ctl, nav, guid, ei)
        u = ctl.update(nav, guid, None).copy()
        assert np.allclose(u, u_ref, rtol=1e-10, atol=1e-9 * np.linalg.norm(u_ref))
        assert np.allclose(ctl.eps, m["eps"], atol=1e-15) and np.allclose(ctl.eps_dot, m["eps_dot"], atol=1e-15)
        # update law: theta_dot = -Gamma Phi^T Ia_hat^-1 E^T P y, Phi = [Y, -P_a^T L]
        y = np.concatenate((ei, m["eps"], m["eps_dot"]))
        assert ctl.V_lyap == pytest.approx(y @ ctl.P @ y, rel=1e-12)
        Phi = np.hstack((m["Y"], -m["Pa"].T @ m["L"]))
        Gamma = np.diag(np.concatenate((ctl.params["control.gamma_h"] * ctl.I_ref * ctl.h_scale ** 2,
                                        ctl.params["control.gamma_d"] * ctl.I_ref * np.ones(3))))
        thdot = -Gamma @ Phi.T @ np.linalg.solve(m["Ia"], (ctl.P @ y)[6:9])
        assert ctl.adapting and not ctl.projected
        assert np.allclose(ctl.theta_hat - th0, DT * thdot, rtol=1e-8, atol=1e-12 * np.abs(th0).max())
        ctl.theta_hat[:] = th0


def test_P_solves_the_lyapunov_equation_and_is_positive_definite():
    for lam, q in ((1.0, 1.0), (0.3, 5.0), (2.5, 0.1)):
        ctl = _controller(**{"control.lambda_radps": lam, "control.q_weight": q})
        A, P = ctl.A, ctl.P
        assert np.allclose(P @ A + A.T @ P, -q * np.eye(9), atol=1e-10 * max(1.0, np.abs(P).max()))
        assert np.allclose(P, P.T)
        assert np.min(np.linalg.eigvalsh(P)) > 0
        # (s + lambda)^3 on each axis
        assert np.allclose(np.sort_complex(np.linalg.eigvals(A)).real, -lam, atol=1e-3 * lam)
    ctl = _controller()
    ctl.set_param("control.lambda_radps", 2.0)
    assert np.allclose(ctl.P @ ctl.A + ctl.A.T @ ctl.P, -np.eye(9), atol=1e-10)
    assert ctl.A[6, 0] == pytest.approx(-8.0)


def test_physical_inertia_agrees_with_an_eigenvalue_oracle():
    n_valid = n_invalid = 0
    for _ in range(3000):
        h = np.concatenate((RNG.uniform(-500, 6000, 3), RNG.uniform(-2500, 2500, 3)))
        ev = np.linalg.eigvalsh(inertia_matrix(h))
        margin = 1e-3 * h[:3].sum()
        oracle_ok = ev[0] > margin and ev[0] + ev[1] - ev[2] > margin
        oracle_bad = ev[0] < -margin or ev[0] + ev[1] - ev[2] < -margin
        got = physical_inertia(h, 1e-6)
        if oracle_ok:
            assert got
            n_valid += 1
        elif oracle_bad:
            assert not got
            n_invalid += 1
    assert n_valid > 100 and n_invalid > 100


def _drive(ctl, n, rng, big=True, tau=None):
    for _ in range(n):
        sigma = rng.normal(size=3) * 0.3
        nav = _nav(sigma, rng.normal(size=3) * (0.5 if big else 1e-5), alpha=rng.uniform(0, 0.7),
                   beta=rng.uniform(-0.2, 0.2))
        err = 0.3 if big else 1e-6
        guid = _guid(sigma + rng.normal(size=3) * err, rng.normal(size=3) * (0.5 if big else 1e-5),
                     rng.normal(size=3) * (0.5 if big else 1e-6))
        ctl.update(nav, guid, tau)


def test_projection_keeps_the_estimates_physical_and_bounded():
    ctl = _controller(**{"control.gamma_h": 1e4, "control.gamma_d": 1e4, "control.deadzone": 0.0,
                         "control.h_bound_frac": 0.5})
    rng = np.random.default_rng(7)
    projected = 0
    for _ in range(400):
        _drive(ctl, 1, rng)
        projected += ctl.projected
        h = ctl.h_hat
        assert np.all(h >= ctl.h_lo - 1e-9) and np.all(h <= ctl.h_hi + 1e-9)
        ev = np.linalg.eigvalsh(inertia_matrix(h))
        assert ev[0] > 0 and ev[0] + ev[1] >= ev[2] * (1 - 1e-9)
        assert np.all(ctl.d_hat >= 0.3 - 1e-12) and np.all(ctl.d_hat <= 3.0 + 1e-12)
    assert projected > 50                                   # the bounds were really exercised
    assert np.ptp(ctl.h_hat - inertia_vector(VEH.inertia_kgm2)) > 0   # and the estimates moved


def test_dead_zone_stops_adaptation_at_small_errors():
    rng = np.random.default_rng(3)
    ctl = _controller(**{"control.deadzone": 1.0})
    th0 = ctl.theta_hat.copy()
    _drive(ctl, 50, rng, big=False)
    assert ctl.V_lyap < ctl.prm[6] and not ctl.adapting
    assert np.array_equal(ctl.theta_hat, th0)
    _drive(ctl, 5, rng, big=True)
    assert ctl.adapting and not np.array_equal(ctl.theta_hat, th0)
    # the level scales with the smallest jet torque increment (roll 17.6 N m)
    assert ctl.tau_q_B[0] == pytest.approx(17.6)
    assert ctl.V_q > 0


def test_saturation_freezes_integrator_and_adaptation_but_quantisation_does_not():
    ctl = _controller(**{"control.deadzone": 0.0})
    nav = _nav([0.1, 0.0, 0.0], [0.0, 0.0, 0.0], alpha=VEH.aero.alpha_trim_rad + 0.01, beta=0.01)
    guid = _guid([0.0, 0.0, 0.0], [0.05, 0, 0], [0.02, 0, 0])   # 0.1 MRP (~23 deg) roll error, rolling ref
    u0 = ctl.update(nav, guid, None).copy()
    assert abs(u0[0]) > ctl.u_sat_min_B[0]
    ei, th = ctl.eps_int.copy(), ctl.theta_hat.copy()
    for _ in range(20):                                      # the allocator delivered nothing
        ctl.update(nav, guid, np.zeros(3))
        assert ctl.saturated
    assert np.array_equal(ctl.eps_int, ei) and np.array_equal(ctl.theta_hat, th)
    ctl.update(nav, guid, ctl.u_cal_B.copy())                # delivered what was asked
    assert not ctl.saturated and ctl.eps_int[0] > ei[0] and not np.array_equal(ctl.theta_hat, th)
    # a command below two jet increments that gets nothing is quantisation, not saturation
    small = _controller(**{"control.lambda_radps": 0.05})
    nav2 = _nav([1e-3, 0.0, 0.0], [0.0, 0.0, 0.0], alpha=VEH.aero.alpha_trim_rad, beta=0.0)
    guid2 = _guid([0.0, 0.0, 0.0], [0, 0, 0], [0, 0, 0])
    small.update(nav2, guid2, None)
    assert 0 < np.max(np.abs(small.u_cal_B)) < small.u_sat_min_B.min()
    small.update(nav2, guid2, np.zeros(3))
    assert not small.saturated and small.eps_int[0] > 0


def test_integrator_is_clamped_and_freeze_stops_only_adaptation():
    ctl = _controller(**{"control.int_limit": 0.01, "control.deadzone": 0.0})
    ctl.freeze = True
    nav = _nav([0.05, -0.05, 0.02], [0.0, 0.0, 0.0])
    guid = _guid([0.0, 0.0, 0.0], [0, 0, 0], [0, 0, 0])
    th = ctl.theta_hat.copy()
    for _ in range(500):
        ctl.update(nav, guid, None)
    assert np.allclose(np.abs(ctl.eps_int), 0.01)
    assert np.array_equal(ctl.theta_hat, th) and not ctl.adapting
    ctl.freeze = False
    ctl.update(nav, guid, None)
    assert ctl.adapting
    ctl.reset()
    assert np.array_equal(ctl.eps_int, np.zeros(3)) and np.allclose(ctl.h_hat, inertia_vector(VEH.inertia_kgm2))


def test_controller_chart_keeps_errors_continuous_when_navigation_switches_mrp_set():
    """The body turns through 180 deg and beyond about a fixed axis; navigation switches its
    MRP set at |sigma| = 1; the reference is 2 deg behind plus 1 deg off-axis. The controller's
    eps and eps_dot never jump, and across its own chart switch (|sigma| = 1.2) the body-frame
    errors P_a eps and P_a int(eps) stay continuous."""
    ctl = _controller(**{"control.gamma_h": 0.0, "control.gamma_d": 0.0})
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    perp = np.cross(axis, [1.0, 0.0, 0.0])
    perp /= np.linalg.norm(perp)
    rate = math.radians(10.0)
    prev = None
    steps, switches, nav_flips = [], 0, 0
    last_nav = None
    for k in range(300):
        theta = math.radians(170.0) + rate * k * DT
        s_body = mrp.switch_shadow(math.tan(theta / 4) * axis)
        C_RN = mrp.to_dcm(math.tan(math.radians(1.0) / 4) * perp) @ mrp.to_dcm(math.tan((theta - math.radians(2.0)) / 4) * axis)
        nav = _nav(s_body, rate * axis)
        guid = _guid(mrp.from_dcm(C_RN), rate * axis, [0, 0, 0])   # (rate approximately)
        if last_nav is not None and np.linalg.norm(s_body - last_nav) > 0.5:
            nav_flips += 1
        last_nav = s_body.copy()
        ctl.update(nav, guid, None)
        sig = ctl._sigma_c.copy()
        Pa = np.linalg.inv(0.25 * mrp.B_matrix(sig))
        cur = dict(eps=ctl.eps.copy(), body=Pa @ ctl.eps, body_int=Pa @ ctl.eps_int)
        if prev is not None:
            if ctl.chart_switched:
                switches += 1
                assert np.linalg.norm(cur["body"] - prev["body"]) < 0.05 * np.linalg.norm(prev["body"])
                assert np.linalg.norm(cur["body_int"] - prev["body_int"]) < 0.05 * np.linalg.norm(prev["body_int"])
            else:
                steps.append(np.linalg.norm(cur["eps"] - prev["eps"]))
        prev = cur
    assert nav_flips == 1 and switches == 1
    assert max(steps) < 1e-3


def test_non_finite_input_gives_zero_torque_and_keeps_state():
    ctl = _controller()
    nav = _nav([0.1, 0.0, 0.0], [0.01, 0.0, 0.0])
    guid = _guid([0.0, 0.0, 0.0], [0, 0, 0], [0, 0, 0])
    ctl.update(nav, guid, None)
    state = (ctl.theta_hat.copy(), ctl.eps_int.copy())
    nav.omega_BN_B[1] = float("nan")
    u = ctl.update(nav, guid, None)
    assert ctl.rejected and np.array_equal(u, np.zeros(3))
    assert np.array_equal(ctl.theta_hat, state[0]) and np.array_equal(ctl.eps_int, state[1])
    nav.omega_BN_B[1] = 0.0
    ctl.update(nav, guid, None)
    assert not ctl.rejected and np.all(np.isfinite(ctl.u_cal_B))


def test_safe_torque_damps_rates_and_aero_estimate():
    ctl = _controller(**{"control.safe_rate_gain": 0.5})
    w = np.array([0.1, -0.05, 0.02])
    u = ctl.safe_torque(_nav([0, 0, 0], w))
    assert np.allclose(u, -0.5 * VEH.inertia_kgm2 @ w)
    assert u @ w < 0
    nav = _nav([0, 0, 0], w, alpha=VEH.aero.alpha_trim_rad + 0.01, beta=0.02, V=4000.0, rho=3e-4)
    q = 0.5 * 3e-4 * 4000.0 ** 2 * VEH.S_ref_m2 * VEH.l_ref_m
    a = VEH.aero
    assert np.allclose(ctl.aero_torque_est(nav), q * np.array([a.C_lbeta * 0.02, a.C_malpha * 0.01, a.C_nbeta * 0.02]))
    assert np.allclose(ctl.inertia_hat(), VEH.inertia_kgm2)


def test_bad_parameters_are_rejected_and_leave_the_controller_unchanged():
    ctl = _controller()
    P = ctl.P.copy()
    for name, value in (("control.lambda_radps", -1.0), ("control.lambda_radps", float("nan")),
                        ("control.gamma_h", 1e9), ("control.nope", 1.0), ("control.q_weight", "x")):
        with pytest.raises(ValueError, match=name.split(".")[1] if name != "control.nope" else "unknown"):
            ctl.set_param(name, value)
    assert np.array_equal(ctl.P, P) and ctl.params["control.lambda_radps"] == 1.0
    prm = load_params(SamiController.PARAMS)
    del prm["control.deadzone"]
    with pytest.raises(ValueError, match="control.deadzone"):
        SamiController(prm, VEH, DT)
    with pytest.raises(ValueError, match="dt_s"):
        SamiController(load_params(SamiController.PARAMS), VEH, 0.0)
    # narrowing the bounds clips the current estimates into them
    ctl.theta_hat[0] = ctl.h_hi[0]
    ctl.set_param("control.h_bound_frac", 0.1)
    assert ctl.h_hat[0] <= ctl.h_hi[0] + 1e-9


def test_an_axis_short_of_its_command_teaches_neither_its_aero_factor_nor_the_inertia():
    ctl = _controller(**{"control.deadzone": 0.0})
    nav = _nav([0.002, -0.002, 0.002], [0.0, 0.0, 0.0], alpha=VEH.aero.alpha_trim_rad + 0.01, beta=0.01)
    guid = _guid([0.0, 0.0, 0.0], [0.01, 0.005, 0.0], [0.002, 0.0, 0.0])   # a turning reference: inertia observable
    ctl.update(nav, guid, None)
    th = ctl.theta_hat.copy()
    delivered = ctl.u_cal_B.copy()
    assert np.all(np.abs(delivered) < ctl.u_sat_min_B)   # no axis saturated: only pitch will miss
    delivered[1] -= 0.6 * ctl.u_sat_min_B[1]            # pitch: 1.2 largest pitch jets off the command
    ctl.update(nav, guid, delivered)
    assert ctl.short and not ctl.saturated and not ctl.rejected
    assert ctl.theta_hat[7] == th[7]                              # pitch aero factor: not learnt
    assert np.array_equal(ctl.theta_hat[0:6], th[0:6])           # inertia: not learnt
    assert ctl.theta_hat[6] != th[6] and ctl.theta_hat[8] != th[8]   # roll and yaw factors learn
    th = ctl.theta_hat.copy()
    ctl.update(nav, guid, ctl.u_cal_B.copy())                     # delivered as commanded
    assert not ctl.short and ctl.theta_hat[7] != th[7] and not np.array_equal(ctl.theta_hat[0:6], th[0:6])
    # within one largest jet increment of the command is quantisation: everything learns
    th = ctl.theta_hat.copy()
    ctl.update(nav, guid, ctl.u_cal_B + 0.4 * ctl.u_sat_min_B)
    assert not ctl.short and ctl.theta_hat[7] != th[7]


@pytest.mark.parametrize("keep", [0.0, 1.0, 0.5])
def test_bank_keeping_rolls_out_a_short_yaw_axis_error_about_the_velocity_vector(keep):
    """With control.bank_keep = k and the yaw axis short, the roll channel's body-frame feedback
    acceleration g_x becomes g_x + k a_z g_z / a_x (a: the velocity's direction in B), so at
    k = 1 the roll channel takes out the error about the velocity vector; otherwise (and at
    k = 0 always) the law is paper eq 18. Truth: eq 18 from matrices and g = P_a (c_d eps_dot +
    k_d eps + k_i int eps)."""
    ctl = _controller(**{"control.deadzone": 0.0, "control.bank_keep": keep})
    alpha, beta = VEH.aero.alpha_trim_rad + 0.02, 0.03
    nav = _nav([0.01, -0.004, 0.03], [0.01, 0.0, -0.02], alpha=alpha, beta=beta)   # mostly a yaw error
    guid = _guid([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    ctl.update(nav, guid, None)
    delivered = ctl.u_cal_B.copy()
    assert abs(delivered[2]) > ctl.u_sat_min_B[2]
    delivered[2] = 0.0                                              # the yaw jets gave nothing
    ei = ctl.eps_int.copy()
    u_ref, m = _paper_u(ctl, nav, guid, ei)
    u = ctl.update(nav, guid, delivered).copy()
    assert ctl.short
    lam = ctl.params["control.lambda_radps"]
    g = m["Pa"] @ (3 * lam * m["eps_dot"] + 3 * lam ** 2 * m["eps"] + lam ** 3 * ei)
    a = np.array([math.cos(alpha) * math.cos(beta), math.sin(beta), math.sin(alpha) * math.cos(beta)])
    dg = np.array([keep * a[2] * g[2] / a[0], 0.0, 0.0])
    I_hat = inertia_matrix(ctl.h_hat)
    assert np.allclose(u, u_ref - I_hat @ dg, rtol=1e-10, atol=1e-9 * np.linalg.norm(u_ref))
    if keep == 1.0:                  # the roll feedback is the error's component about a, over a_x
        assert (g + dg)[0] * a[0] == pytest.approx(a[0] * g[0] + a[2] * g[2], rel=1e-12)
    if keep > 0.0:
        assert not np.allclose(u, u_ref, rtol=1e-6)
    # delivered as commanded: nothing is short, the law is eq 18 whatever bank_keep says
    u_ref, m = _paper_u(ctl, nav, guid, ctl.eps_int.copy())
    u = ctl.update(nav, guid, ctl.u_cal_B.copy()).copy()
    assert not ctl.short
    assert np.allclose(u, u_ref, rtol=1e-10, atol=1e-9 * np.linalg.norm(u_ref))


@pytest.mark.parametrize("d_alpha, beta", [(0.0, 0.2), (-0.2, 0.03)])
def test_bank_keeping_stays_out_beyond_ten_degrees_of_the_trim(d_alpha, beta):
    """The roll term is a small-error one: beyond 10 deg of the trim in alpha or beta the law is
    eq 18 with the yaw axis short (truth: eq 18 from matrices)."""
    ctl = _controller(**{"control.deadzone": 0.0, "control.bank_keep": 1.0})
    nav = _nav([0.01, -0.004, 0.03], [0.01, 0.0, -0.02], alpha=VEH.aero.alpha_trim_rad + d_alpha, beta=beta)
    guid = _guid([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    ctl.update(nav, guid, None)
    delivered = ctl.u_cal_B.copy()
    delivered[2] = 0.0
    u_ref, _ = _paper_u(ctl, nav, guid, ctl.eps_int.copy())
    u = ctl.update(nav, guid, delivered).copy()
    assert ctl.short
    assert np.allclose(u, u_ref, rtol=1e-10, atol=1e-9 * np.linalg.norm(u_ref))
