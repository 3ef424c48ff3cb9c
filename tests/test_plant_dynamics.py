"""Plant dynamics against independent truth: the spherical 3-DOF entry equations (
docs/plant.md), conservation laws with aero off, a closed-form spin, and a full-trajectory
comparison with a separately integrated 3-DOF model."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from common import mrp
from common.model import load_scenario
from sim.dynamics import A_OMEGA_W_N, state_derivative
from sim.plant import Plant

SC = load_scenario("nominal")
MU, RE, OM = SC.planet.mu_m3ps2, SC.planet.radius_m, SC.planet.omega_radps


def rot1(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0], [0, c, s], [0, -s, c]])


def rot2(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])


def local_basis(r):
    up = r / np.linalg.norm(r)
    lam = math.atan2(r[1], r[0])
    east = np.array([-math.sin(lam), math.cos(lam), 0.0])
    return np.cross(up, east), east, up


def spherical(R, U):
    """(r, lon, lat, V, gamma, psi) from planet-fixed position and planet-relative velocity."""
    r = np.linalg.norm(R)
    n, e, up = local_basis(R)
    V = np.linalg.norm(U)
    return np.array([r, math.atan2(R[1], R[0]), math.asin(R[2] / r), V,
                     math.asin(U @ up / V), math.atan2(U @ e, U @ n)])


def state_at(h, V, gamma, psi, lat, lon, bank, alpha):
    """Cartesian state (t = 0, planet frame = N) with the body at (alpha, beta = 0, bank)."""
    r = (RE + h) * np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    n, e, up = local_basis(r)
    u = V * (math.cos(gamma) * math.cos(psi) * n + math.cos(gamma) * math.sin(psi) * e + math.sin(gamma) * up)
    v = u + OM * np.array([-r[1], r[0], 0.0])
    w1 = u / V
    w2 = np.cross(u, r)
    w2 /= np.linalg.norm(w2)
    C_WN = np.vstack((w1, w2, np.cross(w1, w2)))
    C_BN = rot2(alpha) @ rot1(bank) @ C_WN
    return np.concatenate((r, v, mrp.from_dcm(C_BN), np.zeros(3)))


def vinh_rates(s, bank, rho, veh):
    """Spec docs/plant.md spherical equations with rotation (psi from north, clockwise)."""
    r, th, la, V, g, psi = s
    q = 0.5 * rho * V * V
    D = q * veh.S_ref_m2 * veh.aero.C_D / veh.mass_kg
    L = q * veh.S_ref_m2 * veh.aero.C_L / veh.mass_kg
    gr = MU / r ** 2
    cl, sl = math.cos(la), math.sin(la)
    cg, sg = math.cos(g), math.sin(g)
    return np.array([
        V * sg,
        V * cg * math.sin(psi) / (r * cl),
        V * cg * math.cos(psi) / r,
        -D - gr * sg + OM ** 2 * r * cl * (sg * cl - cg * sl * math.cos(psi)),
        L / V * math.cos(bank) + (V / r - gr / V) * cg + 2 * OM * cl * math.sin(psi)
        + OM ** 2 * r / V * cl * (cg * cl + sg * sl * math.cos(psi)),
        L * math.sin(bank) / (V * cg) + V / r * math.sin(psi) * cg * math.tan(la)
        - 2 * OM * (math.tan(g) * cl * math.cos(psi) - sl) + OM ** 2 * r * sl * cl * math.sin(psi) / (V * cg),
    ])


def test_translational_derivative_matches_spherical_entry_equations_at_random_states():
    plant = Plant(SC)
    veh = SC.vehicle
    rng = np.random.default_rng(7)
    for _ in range(40):
        h = rng.uniform(20e3, 125e3)
        V = rng.uniform(800.0, 7500.0)
        gamma = math.radians(rng.uniform(-25, 15))
        psi = math.radians(rng.uniform(-180, 180))
        lat = math.radians(rng.uniform(-60, 60))
        lon = math.radians(rng.uniform(-180, 180))
        bank = math.radians(rng.uniform(-175, 175))
        x = state_at(h, V, gamma, psi, lat, lon, bank, veh.aero.alpha_trim_rad)
        dx, aux = state_derivative(x, plant.p)
        assert np.array_equal(dx[0:3], x[3:6])
        assert aux[2] == pytest.approx(veh.aero.alpha_trim_rad, abs=1e-12)
        assert abs(aux[3]) < 1e-12
        assert math.remainder(aux[4] - bank, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
        # planet-frame trajectory: R' = U, U' = a - 2 Om x U - Om x (Om x R)
        Omv = np.array([0.0, 0.0, OM])
        R, U = x[0:3], x[3:6] - np.cross(Omv, x[0:3])
        Rd, Ud = U, dx[3:6] - 2 * np.cross(Omv, U) - np.cross(Omv, np.cross(Omv, R))

        def fd(hs):
            return (spherical(R + hs * Rd, U + hs * Ud) - spherical(R - hs * Rd, U - hs * Ud)) / (2 * hs)
        rates = (4 * fd(0.005) - fd(0.01)) / 3           # Richardson: O(h^4)
        rho = SC.truth.density_scale * SC.planet.rho0_kgpm3 * math.exp(-h / SC.planet.scale_height_m)
        oracle = vinh_rates(spherical(R, U), bank, rho, veh)
        scale = np.array([V, V / RE, V / RE, 1.0, V / RE, V / RE])   # natural size of each rate
        assert np.all(np.abs(rates - oracle) <= 1e-8 * (np.abs(oracle) + scale)), (rates, oracle)


def test_wind_frame_rate_equals_numerical_derivative_of_wind_axes():
    plant = Plant(SC)
    x = state_at(60e3, 5000.0, math.radians(-8), 1.0, 0.3, 0.2, 0.7, SC.vehicle.aero.alpha_trim_rad)
    dx, aux = state_derivative(x, plant.p)

    def C_WN(xx):
        r, v = xx[0:3], xx[3:6]
        u = v - np.cross([0, 0, OM], r)
        w1 = u / np.linalg.norm(u)
        w2 = np.cross(u, r)
        w2 /= np.linalg.norm(w2)
        return np.vstack((w1, w2, np.cross(w1, w2)))
    hs = 1e-3
    Cd = (C_WN(x + hs * dx) - C_WN(x - hs * dx)) / (2 * hs)
    # C_dot = -[w_W x] C with w_W in W components
    Wt = -Cd @ C_WN(x).T
    w_W = np.array([Wt[2, 1], Wt[0, 2], Wt[1, 0]])
    assert np.allclose(C_WN(x).T @ w_W, aux[A_OMEGA_W_N:A_OMEGA_W_N + 3], rtol=1e-6, atol=1e-11)


def vacuum(scenario, **planet):
    return scenario.with_(planet=replace(scenario.planet, rho0_kgpm3=0.0, **planet))


@pytest.mark.parametrize("use_j2", [False, True])
def test_keplerian_energy_and_angular_momentum_conserved_with_aero_off(use_j2):
    plant = Plant(vacuum(SC, use_j2=use_j2))
    plant.set_state(r_N=[3.0e6, 1.5e6, 1.2e6], v_N=[-2000.0, 3000.0, 1000.0])
    J2 = SC.planet.j2

    def energy(x):
        r = np.linalg.norm(x[0:3])
        U = -MU / r
        if use_j2:
            sl = x[2] / r
            U += MU / r * J2 * (RE / r) ** 2 * (3 * sl * sl - 1) / 2
        return 0.5 * x[3:6] @ x[3:6] + U
    E0, H0 = energy(plant.x), np.cross(plant.x[0:3], plant.x[3:6])
    u = np.zeros(18, np.uint8)
    for _ in range(1000):
        plant.step(u)
    E1, H1 = energy(plant.x), np.cross(plant.x[0:3], plant.x[3:6])
    assert abs(E1 - E0) <= 1e-11 * abs(E0)
    if use_j2:     # J2 is axisymmetric: only the polar component is conserved
        assert abs(H1[2] - H0[2]) <= 1e-11 * np.linalg.norm(H0)
        assert np.linalg.norm(H1 - H0) > 1e-9 * np.linalg.norm(H0)   # and J2 really acts
    else:
        assert np.linalg.norm(H1 - H0) <= 1e-11 * np.linalg.norm(H0)
    assert np.linalg.norm(plant.x[0:3]) > RE


def test_torque_free_tumble_conserves_inertial_angular_momentum_and_energy():
    plant = Plant(vacuum(SC))
    I = plant.inertia_truth_kgm2
    plant.set_state(omega_BN_B=[0.4, 1.2, -0.3])

    def H_N(x):
        return mrp.to_dcm(x[6:9]).T @ I @ x[9:12]
    H0, T0 = H_N(plant.x), 0.5 * plant.x[9:12] @ I @ plant.x[9:12]
    u = np.zeros(18, np.uint8)
    for _ in range(1000):
        plant.step(u)
    H1, T1 = H_N(plant.x), 0.5 * plant.x[9:12] @ I @ plant.x[9:12]
    assert np.linalg.norm(H1 - H0) <= 1e-9 * np.linalg.norm(H0)
    assert abs(T1 - T0) <= 1e-9 * T0
    assert not np.allclose(plant.x[9:12], [0.4, 1.2, -0.3], atol=1e-2)   # it really tumbled


def test_spin_about_principal_axis_matches_closed_form_through_shadow_switches():
    veh = replace(SC.vehicle, inertia_kgm2=np.diag([2000.0, 5000.0, 5200.0]))
    sc = vacuum(SC).with_(vehicle=veh, truth=replace(SC.truth, inertia_scale=np.ones(6)))
    plant = Plant(sc)
    w = 2.0
    plant.set_state(omega_BN_B=[w, 0.0, 0.0])
    C0 = mrp.to_dcm(plant.x[6:9])
    u = np.zeros(18, np.uint8)
    switches = 0
    prev = plant.x[6:9].copy()
    for k in range(1, 501):
        plant.step(u)
        s = plant.x[6:9]
        assert s @ s <= 1.0 + 1e-15
        if np.linalg.norm(s - prev) > 0.5:
            switches += 1
        prev = s.copy()
        assert np.max(np.abs(mrp.to_dcm(s) - rot1(w * k * SC.dt_control_s) @ C0)) < 1e-10
    assert switches >= 3


def test_tumbling_attitude_stays_continuous_and_mrp_bounded():
    plant = Plant(vacuum(SC))
    plant.set_state(omega_BN_B=[3.0, -2.0, 4.0])
    u = np.zeros(18, np.uint8)
    C_prev = mrp.to_dcm(plant.x[6:9])
    jumps = 0
    for _ in range(400):
        s_prev = plant.x[6:9].copy()
        plant.step(u)
        s = plant.x[6:9]
        assert s @ s <= 1.0 + 1e-15
        jumps += np.linalg.norm(s - s_prev) > 0.5
        C = mrp.to_dcm(s)
        # an attitude change over one period is bounded by |omega| dt
        assert np.linalg.norm(C - C_prev, 2) <= 1.01 * np.linalg.norm(plant.x[9:12]) * SC.dt_control_s * 1.5
        C_prev = C
    assert jumps >= 2


def test_initial_state_from_scenario_and_rates_follow_the_wind_frame():
    plant = Plant(SC)
    tr = plant.truth()
    assert tr["h_m"] == pytest.approx(125e3, abs=1e-6)
    assert tr["V_rel_mps"] == pytest.approx(7300.0, rel=1e-12)
    assert tr["gamma_rad"] == pytest.approx(math.radians(-12), abs=1e-12)
    assert tr["psi_rad"] == pytest.approx(SC.heading_rad, abs=1e-12)
    assert tr["lat_rad"] == pytest.approx(0.0, abs=1e-12) and tr["lon_rad"] == pytest.approx(0.0, abs=1e-12)
    assert tr["bank_rad"] == pytest.approx(math.radians(90), abs=1e-12)
    assert tr["alpha_rad"] == pytest.approx(SC.vehicle.aero.alpha_trim_rad, abs=1e-12)
    # with no torque at all, the aerodynamic angles barely move over the first second
    vac = Plant(vacuum(SC))
    for _ in range(50):
        vac.step(np.zeros(18, np.uint8))
    t1 = vac.truth()
    assert abs(t1["bank_rad"] - math.radians(90)) < 1e-6
    assert abs(t1["alpha_rad"] - SC.vehicle.aero.alpha_trim_rad) < 1e-6
    assert abs(t1["beta_rad"]) < 1e-6


def vinh_fly(sc, t_end):
    """Spherical 3-DOF (spec equations) with the open-loop bank reference, RK4 at dt."""
    from sim.openloop import BankReference
    veh = sc.vehicle
    ref = BankReference(sc.bank_schedule, sc.bank_rate_limit_radps, sc.bank_accel_limit_radps2, sc.dt_control_s)
    s = np.array([RE + sc.altitude_m, 0.0, 0.0, sc.speed_rel_mps, sc.flight_path_rad, sc.heading_rad])
    dt = sc.dt_control_s

    def f(s, bank):
        rho = sc.truth.density_scale * sc.planet.rho0_kgpm3 * math.exp(-(s[0] - RE) / sc.planet.scale_height_m)
        return vinh_rates(s, bank, rho, veh)
    for k in range(int(round(t_end / dt))):
        bank, bdot, bdd = ref.update(k * dt)
        b2 = bank + 0.5 * dt * bdot + 0.125 * dt * dt * bdd
        b3 = bank + dt * bdot + 0.5 * dt * dt * bdd
        k1 = f(s, bank)
        k2 = f(s + 0.5 * dt * k1, b2)
        k3 = f(s + 0.5 * dt * k2, b2)
        k4 = f(s + dt * k3, b3)
        s = s + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return s


def test_open_loop_trajectory_follows_the_spherical_model_for_200_s():
    from sim.openloop import fly
    sc = SC.with_(max_duration_s=200.0)
    out = fly(sc)
    h = out["history"]
    t, hh, V, g = h[-1][0], h[-1][1], h[-1][2], h[-1][3]
    assert t == pytest.approx(200.0)
    s = vinh_fly(sc, 200.0)
    assert hh == pytest.approx(s[0] - RE, abs=5.0)          # 200 s, through peak qbar and a reversal
    assert V == pytest.approx(s[3], abs=0.1)
    assert g == pytest.approx(math.degrees(s[4]), abs=1e-3)


def test_open_loop_entry_reproduces_the_spec_figures_under_the_spec_conditions():
    """docs/plant.md: ~450 s to Mach 2 near 9 km, peak qbar ~6.6 kPa near 100 s, gamma > 0
    near 140 s and changing sign again near 250 s — stated for a non-rotating planet, nominal
    density, bank steps."""
    from sim.openloop import fly
    sc = SC.with_(planet=replace(SC.planet, omega_radps=0.0), truth=replace(SC.truth, density_scale=1.0),
                  bank_rate_limit_radps=math.radians(1000.0), bank_accel_limit_radps2=math.radians(1000.0))
    out = fly(sc)
    assert out["end_reason"] == "mach"
    assert 430 < out["t_end_s"] < 475
    assert 8e3 < out["h_end_m"] < 11e3
    assert 6.2e3 < out["qbar_max_pa"] < 7.0e3 and 90 < out["t_qbar_max_s"] < 110
    assert 130 < out["gamma_turns_positive_s"][0] < 150
    assert len(out["gamma_turns_negative_s"]) == 1 and 235 < out["gamma_turns_negative_s"][0] < 265
    assert out["bank_err_max_after_10s_deg"] < 2.0


def rot3(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])


def test_aero_force_moment_and_kinematics_off_trim_with_sideslip_and_rates():
    """Spec docs/plant.md: F = qbar S (-C_D w1 + C_L l + C_Y beta y), C_L about trim; moments
    from the truth-dispersed static derivatives plus damping; sigma_dot = B(sigma) omega / 4."""
    plant = Plant(SC)
    veh, tr, ae = SC.vehicle, SC.truth, SC.vehicle.aero
    I = plant.inertia_truth_kgm2
    rng = np.random.default_rng(5)
    for _ in range(20):
        h, V = rng.uniform(20e3, 90e3), rng.uniform(1000, 7000)
        alpha = ae.alpha_trim_rad + math.radians(rng.uniform(-8, 8))
        beta = math.radians(rng.uniform(-6, 6))
        bank = rng.uniform(-3, 3)
        x = state_at(h, V, math.radians(rng.uniform(-15, 5)), rng.uniform(-3, 3), rng.uniform(-1, 1),
                     rng.uniform(-3, 3), 0.0, 0.0)
        r, v = x[0:3], x[3:6]
        u = v - np.cross([0, 0, OM], r)
        w1 = u / np.linalg.norm(u)
        w2 = np.cross(u, r) / np.linalg.norm(np.cross(u, r))
        w3 = np.cross(w1, w2)
        C_BN = rot2(alpha) @ rot3(-beta) @ rot1(bank) @ np.vstack((w1, w2, w3))
        x[6:9] = mrp.from_dcm(C_BN)
        x[9:12] = rng.normal(0, 0.05, 3)
        dx, aux = state_derivative(x, plant.p)
        assert (aux[2], aux[3], math.remainder(aux[4] - bank, 2 * math.pi)) == pytest.approx((alpha, beta, 0.0), abs=1e-10)
        rho = tr.density_scale * SC.planet.rho0_kgpm3 * math.exp(-h / SC.planet.scale_height_m)
        qS = 0.5 * rho * V * V * veh.S_ref_m2
        F = (dx[3:6] + MU * r / np.linalg.norm(r) ** 3) * veh.mass_kg
        lift = math.sin(bank) * w2 - math.cos(bank) * w3
        side = math.cos(bank) * w2 + math.sin(bank) * w3
        assert F @ w1 == pytest.approx(-qS * ae.C_D, rel=1e-9)
        assert F @ lift == pytest.approx(qS * (ae.C_L + ae.C_Lalpha * (alpha - ae.alpha_trim_rad)), rel=1e-9)
        assert F @ side == pytest.approx(qS * ae.C_Ybeta * beta, rel=1e-7, abs=1e-9 * qS)
        w = x[9:12]
        tau = I @ dx[9:12] + np.cross(w, I @ w)
        l = veh.l_ref_m
        ph = w * l / (2 * V)
        expected = qS * l * np.array([
            ae.C_lbeta * tr.C_lbeta_scale * beta + ae.C_lp * ph[0],
            ae.C_malpha * tr.C_malpha_scale * (alpha - ae.alpha_trim_rad) + ae.C_mq * ph[1],
            ae.C_nbeta * tr.C_nbeta_scale * beta + ae.C_nr * ph[2]])
        assert np.allclose(tau, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
        assert np.allclose(dx[6:9], mrp.sigma_dot(x[6:9], w), rtol=1e-12, atol=1e-15)
