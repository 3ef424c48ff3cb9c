"""Entry dynamics of the plant (docs/plant.md): the 6-DOF equations of motion over a
rotating Mars as numba kernels on flat float64 arrays, and the truth parameter vector they
read. sim/plant.py steps them with the jets, faults and sensors.

State x (12,) = [r_N (3) m, v_N (3) m/s, sigma_BN (3), omega_BN_B (3) rad/s], integrated
with fixed-step RK4. Bank, alpha and beta are always derived from the attitude and v_rel,
never integrated.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from common import atmosphere, mrp
from common.frames import local_axes
from common.model import MAX_RHO_WAVES, Scenario, inertia_matrix, inertia_vector

# ---- flat parameter vector p (indices are compile-time constants in the kernels) ----
P_MU, P_RE, P_OMEGA, P_J2, P_USE_J2 = 0, 1, 2, 3, 4
P_RHO_MODEL, P_RHO0, P_HSCALE, P_RHO_SCALE = 5, 6, 7, 8
P_MASS, P_S, P_LREF = 9, 10, 11
P_ALPHA_TRIM, P_CL, P_CD, P_CLA, P_CYB = 12, 13, 14, 15, 16
P_CMA, P_CNB, P_CLB, P_CLP, P_CMQ, P_CNR = 17, 18, 19, 20, 21, 22
P_I = 23        # 9 entries, row-major truth inertia [kg m^2]
P_IINV = 32     # 9 entries, its inverse
P_RHO_NWAVE = 41   # number of altitude waves of the density perturbation (0: none)
P_RHO_WAVE = 42    # MAX_RHO_WAVES x (amplitude, wavelength [m], phase [rad])
N_P = P_RHO_WAVE + 3 * MAX_RHO_WAVES

# ---- derived outputs at the end of a step (aux) ----
A_H, A_V, A_ALPHA, A_BETA, A_BANK, A_RHO, A_QBAR, A_MACH = 0, 1, 2, 3, 4, 5, 6, 7
A_TAU_AERO_B = 8     # 3
A_ACC_B = 11         # 3: sensed (non-gravitational) acceleration, body [m/s^2]
A_F_AERO_N = 14      # 3: aerodynamic force, N [N]
A_E1, A_E2, A_E3 = 17, 20, 23   # wind-frame unit vectors w1, w2, w3 in N (rows of C_WN)
A_OMEGA_W_N = 26     # 3: angular velocity of W relative to N, in N [rad/s]
A_R = 29             # |r| [m]
A_SIN_GAMMA = 30     # sin(flight-path angle)
N_AUX = 31

_rho_exp = njit(cache=True)(atmosphere.density_exponential)
_rho_poly = njit(cache=True)(atmosphere.density_polynomial)
_speed_of_sound = njit(cache=True)(atmosphere.speed_of_sound)


@njit(cache=True)
def deriv(x, p, tau_B, F_B, dx, C, aux, want_aux):
    """dx = f(x) for the coupled 6-DOF state (docs/plant.md, translational and
    rotational dynamics). tau_B: jet + external torque [N m]; F_B: jet force [N].
    C is scratch for C_BN. When want_aux, the derived outputs are written to aux."""
    rx, ry, rz = x[0], x[1], x[2]
    vx, vy, vz = x[3], x[4], x[5]
    s1, s2, s3 = x[6], x[7], x[8]
    w1, w2, w3 = x[9], x[10], x[11]

    # gravity: point mass (+ J2, optional)
    r2 = rx * rx + ry * ry + rz * rz
    r = math.sqrt(r2)
    mu = p[P_MU]
    kg = -mu / (r2 * r)
    gx, gy, gz = kg * rx, kg * ry, kg * rz
    if p[P_USE_J2] != 0.0:
        re = p[P_RE]
        zr2 = rz * rz / r2
        cj = -1.5 * p[P_J2] * mu * re * re / (r2 * r2 * r)
        gx += cj * rx * (1.0 - 5.0 * zr2)
        gy += cj * ry * (1.0 - 5.0 * zr2)
        gz += cj * rz * (3.0 - 5.0 * zr2)

    # planet-relative velocity u = v - Omega x r (Omega along N3)
    om = p[P_OMEGA]
    ux, uy, uz = vx + om * ry, vy - om * rx, vz
    V = math.sqrt(ux * ux + uy * uy + uz * uz)
    h = r - p[P_RE]
    if p[P_RHO_MODEL] == 0.0:
        rho = _rho_exp(h, p[P_RHO0], p[P_HSCALE])
    else:
        rho = _rho_poly(h)
    rho *= p[P_RHO_SCALE]
    nw = int(p[P_RHO_NWAVE])
    if nw > 0:
        # altitude-correlated perturbation of the profile: rho x (1 + sum a sin(2 pi h / L + phase))
        f = 1.0
        for i in range(nw):
            j = P_RHO_WAVE + 3 * i
            f += p[j] * math.sin(2.0 * math.pi * h / p[j + 1] + p[j + 2])
        rho *= f
    qbar = 0.5 * rho * V * V

    # wind frame W: w1 along u, w2 = (u x r)/|u x r| (right), w3 = w1 x w2 (down)
    e1x, e1y, e1z = ux / V, uy / V, uz / V
    hx, hy, hz = uy * rz - uz * ry, uz * rx - ux * rz, ux * ry - uy * rx
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    e2x, e2y, e2z = hx / hn, hy / hn, hz / hn
    e3x, e3y, e3z = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x

    # aerodynamic angles from C_BN = R2(alpha) R3(-beta) R1(bank) C_WN (common/frames.py)
    mrp.dcm_into(s1, s2, s3, C)
    b1x = C[0, 0] * e1x + C[0, 1] * e1y + C[0, 2] * e1z
    b1y = C[1, 0] * e1x + C[1, 1] * e1y + C[1, 2] * e1z
    b1z = C[2, 0] * e1x + C[2, 1] * e1y + C[2, 2] * e1z
    beta = math.asin(min(1.0, max(-1.0, b1y)))
    alpha = math.atan2(b1z, b1x)
    ca, sa, cb, sb = math.cos(alpha), math.sin(alpha), math.cos(beta), math.sin(beta)
    # a2 (A-frame y axis) is [-ca sb, cb, -sa sb] in B; in N it is C^T of that
    ya0, ya1, ya2 = -ca * sb, cb, -sa * sb
    a2x = C[0, 0] * ya0 + C[1, 0] * ya1 + C[2, 0] * ya2
    a2y = C[0, 1] * ya0 + C[1, 1] * ya1 + C[2, 1] * ya2
    a2z = C[0, 2] * ya0 + C[1, 2] * ya1 + C[2, 2] * ya2
    bank = math.atan2(a2x * e3x + a2y * e3y + a2z * e3z, a2x * e2x + a2y * e2y + a2z * e2z)
    cp, sp = math.cos(bank), math.sin(bank)
    # lift l = sin(bank) w2 - cos(bank) w3; side y = cos(bank) w2 + sin(bank) w3
    lx, ly, lz = sp * e2x - cp * e3x, sp * e2y - cp * e3y, sp * e2z - cp * e3z
    yx, yy, yz = cp * e2x + sp * e3x, cp * e2y + sp * e3y, cp * e2z + sp * e3z

    # F_aero = qbar S (-C_D w1 + C_L l + C_Y beta y), C_L = C_L + C_Lalpha (alpha - alpha_trim)
    da = alpha - p[P_ALPHA_TRIM]
    cl = p[P_CL] + p[P_CLA] * da
    cd = p[P_CD]
    cy = p[P_CYB] * beta
    qs = qbar * p[P_S]
    fax = qs * (-cd * e1x + cl * lx + cy * yx)
    fay = qs * (-cd * e1y + cl * ly + cy * yy)
    faz = qs * (-cd * e1z + cl * lz + cy * yz)
    # jet force (geometry model) from B to N: C^T F_B
    fjx = C[0, 0] * F_B[0] + C[1, 0] * F_B[1] + C[2, 0] * F_B[2]
    fjy = C[0, 1] * F_B[0] + C[1, 1] * F_B[1] + C[2, 1] * F_B[2]
    fjz = C[0, 2] * F_B[0] + C[1, 2] * F_B[1] + C[2, 2] * F_B[2]
    m = p[P_MASS]
    ax = gx + (fax + fjx) / m
    ay = gy + (fay + fjy) / m
    az = gz + (faz + fjz) / m

    # aerodynamic moments: static derivatives about trim + damping, p_hat = p l/(2V)
    lref = p[P_LREF]
    lh = lref / (2.0 * V)
    qsl = qs * lref
    ml = qsl * (p[P_CLB] * beta + p[P_CLP] * w1 * lh)
    mm = qsl * (p[P_CMA] * da + p[P_CMQ] * w2 * lh)
    mn = qsl * (p[P_CNB] * beta + p[P_CNR] * w3 * lh)

    # Euler: I w_dot = -w x (I w) + tau
    I0 = P_I
    iw1 = p[I0] * w1 + p[I0 + 1] * w2 + p[I0 + 2] * w3
    iw2 = p[I0 + 3] * w1 + p[I0 + 4] * w2 + p[I0 + 5] * w3
    iw3 = p[I0 + 6] * w1 + p[I0 + 7] * w2 + p[I0 + 8] * w3
    t1 = -(w2 * iw3 - w3 * iw2) + tau_B[0] + ml
    t2 = -(w3 * iw1 - w1 * iw3) + tau_B[1] + mm
    t3 = -(w1 * iw2 - w2 * iw1) + tau_B[2] + mn
    J0 = P_IINV
    dx[0], dx[1], dx[2] = vx, vy, vz
    dx[3], dx[4], dx[5] = ax, ay, az
    mrp.sigma_dot_into(x[6:9], x[9:12], dx[6:9])
    dx[9] = p[J0] * t1 + p[J0 + 1] * t2 + p[J0 + 2] * t3
    dx[10] = p[J0 + 3] * t1 + p[J0 + 4] * t2 + p[J0 + 5] * t3
    dx[11] = p[J0 + 6] * t1 + p[J0 + 7] * t2 + p[J0 + 8] * t3

    if want_aux:
        aux[A_H] = h
        aux[A_V] = V
        aux[A_ALPHA] = alpha
        aux[A_BETA] = beta
        aux[A_BANK] = bank
        aux[A_RHO] = rho
        aux[A_QBAR] = qbar
        aux[A_MACH] = V / _speed_of_sound(h)
        aux[A_TAU_AERO_B], aux[A_TAU_AERO_B + 1], aux[A_TAU_AERO_B + 2] = ml, mm, mn
        nx, ny, nz = (fax + fjx) / m, (fay + fjy) / m, (faz + fjz) / m
        aux[A_ACC_B] = C[0, 0] * nx + C[0, 1] * ny + C[0, 2] * nz
        aux[A_ACC_B + 1] = C[1, 0] * nx + C[1, 1] * ny + C[1, 2] * nz
        aux[A_ACC_B + 2] = C[2, 0] * nx + C[2, 1] * ny + C[2, 2] * nz
        aux[A_F_AERO_N], aux[A_F_AERO_N + 1], aux[A_F_AERO_N + 2] = fax, fay, faz
        aux[A_E1], aux[A_E1 + 1], aux[A_E1 + 2] = e1x, e1y, e1z
        aux[A_E2], aux[A_E2 + 1], aux[A_E2 + 2] = e2x, e2y, e2z
        aux[A_E3], aux[A_E3 + 1], aux[A_E3 + 2] = e3x, e3y, e3z
        # omega_WN: derivatives of the wind axes. u_dot = a - Omega x v; (u x r)' = u_dot x r + u x v
        udx, udy, udz = ax + om * vy, ay - om * vx, az
        k1 = e1x * udx + e1y * udy + e1z * udz
        d1x, d1y, d1z = (udx - k1 * e1x) / V, (udy - k1 * e1y) / V, (udz - k1 * e1z) / V
        hdx = (udy * rz - udz * ry) + (uy * vz - uz * vy)
        hdy = (udz * rx - udx * rz) + (uz * vx - ux * vz)
        hdz = (udx * ry - udy * rx) + (ux * vy - uy * vx)
        k2 = e2x * hdx + e2y * hdy + e2z * hdz
        d2x, d2y, d2z = (hdx - k2 * e2x) / hn, (hdy - k2 * e2y) / hn, (hdz - k2 * e2z) / hn
        # e3 = e1 x e2 => e3_dot = d1 x e2 + e1 x d2
        d3x = (d1y * e2z - d1z * e2y) + (e1y * d2z - e1z * d2y)
        d3y = (d1z * e2x - d1x * e2z) + (e1z * d2x - e1x * d2z)
        d3z = (d1x * e2y - d1y * e2x) + (e1x * d2y - e1y * d2x)
        pw = d2x * e3x + d2y * e3y + d2z * e3z     # omega . w1
        qw = d3x * e1x + d3y * e1y + d3z * e1z     # omega . w2
        rw = d1x * e2x + d1y * e2y + d1z * e2z     # omega . w3
        aux[A_OMEGA_W_N] = pw * e1x + qw * e2x + rw * e3x
        aux[A_OMEGA_W_N + 1] = pw * e1y + qw * e2y + rw * e3y
        aux[A_OMEGA_W_N + 2] = pw * e1z + qw * e2z + rw * e3z
        aux[A_R] = r
        aux[A_SIN_GAMMA] = (e1x * rx + e1y * ry + e1z * rz) / r


@njit(cache=True)
def rk4(x, p, tau_B, F_B, n_sub, dt, ws, C, aux):
    """n_sub RK4 substeps of dt with tau_B, F_B held; MRP shadow switch between substeps;
    aux filled at the final state."""
    k1, k2, k3, k4, xt = ws[0], ws[1], ws[2], ws[3], ws[4]
    h2 = 0.5 * dt
    h6 = dt / 6.0
    for _ in range(n_sub):
        deriv(x, p, tau_B, F_B, k1, C, aux, False)
        for j in range(12):
            xt[j] = x[j] + h2 * k1[j]
        deriv(xt, p, tau_B, F_B, k2, C, aux, False)
        for j in range(12):
            xt[j] = x[j] + h2 * k2[j]
        deriv(xt, p, tau_B, F_B, k3, C, aux, False)
        for j in range(12):
            xt[j] = x[j] + dt * k3[j]
        deriv(xt, p, tau_B, F_B, k4, C, aux, False)
        for j in range(12):
            x[j] += h6 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
        mrp.switch_shadow_into(x[6:9])
    deriv(x, p, tau_B, F_B, k1, C, aux, True)


def state_derivative(x: np.ndarray, p: np.ndarray, tau_B=None, F_B=None) -> tuple[np.ndarray, np.ndarray]:
    """(x_dot, aux) at state x with parameter vector p (for tests and analysis)."""
    dx = np.empty(12)
    aux = np.zeros(N_AUX)
    tau = np.zeros(3) if tau_B is None else np.asarray(tau_B, float)
    F = np.zeros(3) if F_B is None else np.asarray(F_B, float)
    deriv(np.asarray(x, float), p, tau, F, dx, np.empty((3, 3)), aux, True)
    return dx, aux


def params_vector(scenario: Scenario) -> np.ndarray:
    """The truth parameter vector p: nominal vehicle and planet, dispersed by scenario.truth
    (docs/scenarios.md, uncertainty)."""
    pl, veh, tr = scenario.planet, scenario.vehicle, scenario.truth
    ae = veh.aero
    I = inertia_matrix(inertia_vector(veh.inertia_kgm2) * tr.inertia_scale)
    p = np.zeros(N_P)
    p[P_MU], p[P_RE], p[P_OMEGA] = pl.mu_m3ps2, pl.radius_m, pl.omega_radps
    p[P_J2], p[P_USE_J2] = pl.j2, float(pl.use_j2)
    p[P_RHO_MODEL] = {"exponential": 0.0, "polynomial": 1.0}[pl.density_model]
    p[P_RHO0], p[P_HSCALE], p[P_RHO_SCALE] = pl.rho0_kgpm3, pl.scale_height_m, tr.density_scale
    waves = tr.density_waves
    if len(waves) > MAX_RHO_WAVES:
        raise ValueError(f"truth.density_waves: at most {MAX_RHO_WAVES} waves, got {len(waves)}")
    if sum(abs(a) for a, _, _ in waves) >= 1.0:
        raise ValueError("truth.density_waves: amplitudes must sum below 1 (density stays positive)")
    p[P_RHO_NWAVE] = len(waves)
    for i, (a, L, ph) in enumerate(waves):
        p[P_RHO_WAVE + 3 * i:P_RHO_WAVE + 3 * i + 3] = a, L, ph
    p[P_MASS], p[P_S], p[P_LREF] = veh.mass_kg, veh.S_ref_m2, veh.l_ref_m
    p[P_ALPHA_TRIM], p[P_CL], p[P_CD], p[P_CLA], p[P_CYB] = ae.alpha_trim_rad, ae.C_L, ae.C_D, ae.C_Lalpha, ae.C_Ybeta
    p[P_CMA] = ae.C_malpha * tr.C_malpha_scale
    p[P_CNB] = ae.C_nbeta * tr.C_nbeta_scale
    p[P_CLB] = ae.C_lbeta * tr.C_lbeta_scale
    p[P_CLP], p[P_CMQ], p[P_CNR] = ae.C_lp, ae.C_mq, ae.C_nr
    p[P_I:P_I + 9] = I.ravel()
    p[P_IINV:P_IINV + 9] = np.linalg.inv(I).ravel()
    return p


def initial_translation(scenario: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """(r_N, v_N) at t = 0 from altitude, planet-relative speed, flight-path angle, heading
    (clockwise from north), latitude, longitude; N and the planet frame coincide at t = 0."""
    pl = scenario.planet
    lat, lon = scenario.latitude_rad, scenario.longitude_rad
    rn = pl.radius_m + scenario.altitude_m
    r_N = rn * np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    north, east, up = local_axes(r_N)
    V, g, psi = scenario.speed_rel_mps, scenario.flight_path_rad, scenario.heading_rad
    u = V * (math.cos(g) * math.cos(psi) * north + math.cos(g) * math.sin(psi) * east + math.sin(g) * up)
    v_N = u + np.array([-pl.omega_radps * r_N[1], pl.omega_radps * r_N[0], 0.0])
    return r_N, v_N
