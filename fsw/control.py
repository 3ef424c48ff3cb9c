"""SAMI adaptive attitude control (docs/fsw/index.md, "SAMI adaptive control", paper section 2).

Notation (spec): J(sigma) = B(sigma)/4, sigma_dot = J omega; P_a = J^-1 = 4 B^T/(1+s.s)^2;
I_a* = P_a^T I P_a; Lambda(v) h = I v with h = [I11 I22 I33 I12 I13 I23].

Control law (paper eq 18):   u_cal = J^T [Y h_hat - C_d eps_dot - K_d eps - K_i int(eps)] - L d_hat
with K = I_a*_hat k (scalars from (s + lambda)^3), which reduces to
  u_cal = M h_hat - I_hat P_a (c_d eps_dot + k_d eps + k_i int eps) - L d_hat,   Y = P_a^T M,
  M = Lambda(P_a sr_dd) - Lambda(P_a Jdot P_a sr_d) + [omega x] Lambda(P_a sr_d).
Update law (paper eqs 22-27):  theta_hat_dot = -Gamma Phi^T I_a*_hat^-1 E^T P y,
  Phi = [Y, -P_a^T L], y = [int eps; eps; eps_dot], P A + A^T P = -Q.

Beyond the paper (spec "Required beyond the paper"): parameter projection, dead zone,
saturation awareness, integrator limit, adaptation freeze, SAFE-mode rate damping, and a
controller-side MRP chart with hysteresis (see SamiController).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.linalg
from numba import njit

from common.model import Vehicle, inertia_matrix, inertia_vector
from common.mrp import B_mul, Bdot_mul, nearest_set_into, sigma_derivatives, sigma_dot_into
from common.mrp import omega_from_sigma_dot_into as _Pa_mul   # P_a x = 4 B^T x / (1 + s.s)^2
from fsw.params import Param

# prm vector layout (derived from the parameters, see SamiController._derive)
_CD, _KD, _KI, _GH, _GD, _DT, _VDEAD, _ILIM, _SFRAC, _DMIN, _DMAX, _SWITCH, _QSL, _CLB, _CMA, _CNB, _ATRIM = range(17)
_NPRM = 17
# the kernel's buffers: constants (prm, h_scale, h_lo, h_hi, u_sat_min, P 9x9) and state
# (theta, eps_int, sigma_c, u_cal, eps, eps_dot, diag; then its work arrays); two arrays to
# hand it, not twenty
_K_PRM, _K_HSCALE, _K_HLO, _K_HHI, _K_USAT, _K_P, _K_BKEEP, _K_N = 0, 17, 23, 29, 35, 38, 119, 120
_S_THETA, _S_EPSINT, _S_SIGC, _S_U, _S_EPS, _S_EPSDOT, _S_DIAG, _S_N = 0, 9, 12, 15, 18, 21, 24, 31
_W_N = 102                # the kernel's work arrays, after the state in the same buffer
assert (_K_HSCALE, _K_HLO, _K_HHI, _K_USAT, _K_P, _K_BKEEP, _K_N) == (_NPRM, _NPRM + 6, _NPRM + 12, _NPRM + 18,
                                                                     _NPRM + 21, _NPRM + 102, _NPRM + 103)
# bank keeping acts only this near the trim in alpha and beta [rad] (10 deg): its roll term is
# a small-error one
_BK_NEAR_TRIM = 0.1745
# diag vector layout (telemetry of the last update)
_D_V, _D_ADAPT, _D_SAT, _D_PROJ, _D_SWITCH, _D_BAD, _D_SHORT = range(7)


@njit(cache=True)
def _lam_rows(v, M, sign):
    """M += sign * Lambda(v) (docs/fsw/index.md, linear parameterisation I v = Lambda(v) h)."""
    M[0, 0] += sign * v[0]
    M[0, 3] += sign * v[1]
    M[0, 4] += sign * v[2]
    M[1, 1] += sign * v[1]
    M[1, 3] += sign * v[0]
    M[1, 5] += sign * v[2]
    M[2, 2] += sign * v[2]
    M[2, 4] += sign * v[0]
    M[2, 5] += sign * v[1]


@njit(cache=True)
def regressor_M(sigma, omega, sr_d, sr_dd, M):
    """M (3x6) with Y = P_a^T M: Lambda(P_a sr_dd) - Lambda(P_a Jdot P_a sr_d) + [omega x] Lambda(P_a sr_d)."""
    sd = np.empty(3)
    sigma_dot_into(sigma, omega, sd)
    a1 = np.empty(3)
    a2 = np.empty(3)
    a3 = np.empty(3)
    t = np.empty(3)
    _Pa_mul(sigma, sr_dd, a1)
    _Pa_mul(sigma, sr_d, a3)
    Bdot_mul(sigma, sd, a3, t)
    for i in range(3):
        t[i] *= 0.25
    _Pa_mul(sigma, t, a2)
    for i in range(3):
        for j in range(6):
            M[i, j] = 0.0
    _lam_rows(a1, M, 1.0)
    _lam_rows(a2, M, -1.0)
    L3 = np.zeros((3, 6))
    _lam_rows(a3, L3, 1.0)
    for j in range(6):
        c0 = omega[1] * L3[2, j] - omega[2] * L3[1, j]
        c1 = omega[2] * L3[0, j] - omega[0] * L3[2, j]
        c2 = omega[0] * L3[1, j] - omega[1] * L3[0, j]
        M[0, j] += c0
        M[1, j] += c1
        M[2, j] += c2


@njit(cache=True)
def _pd3(a00, a11, a22, a01, a02, a12, tol):
    """True when the symmetric 3x3 matrix has Cholesky pivots all > tol."""
    if a00 <= tol:
        return False
    l10 = a01 / math.sqrt(a00)
    l20 = a02 / math.sqrt(a00)
    d1 = a11 - l10 * l10
    if d1 <= tol:
        return False
    l21 = (a12 - l20 * l10) / math.sqrt(d1)
    d2 = a22 - l20 * l20 - l21 * l21
    return d2 > tol


@njit(cache=True)
def physical_inertia(h, tol_frac):
    """True when h = [I11 I22 I33 I12 I13 I23] is a positive-definite inertia whose principal
    moments obey the triangle inequality, i.e. (tr I / 2) I3 - I (the second-moment matrix)
    is positive semi-definite. tol_frac scales the margin by tr I."""
    tr = h[0] + h[1] + h[2]
    if not (tr > 0.0):
        return False
    tol = tol_frac * tr
    if not _pd3(h[0], h[1], h[2], h[3], h[4], h[5], tol):
        return False
    half = 0.5 * tr
    return _pd3(half - h[0] + tol, half - h[1] + tol, half - h[2] + tol, -h[3], -h[4], -h[5], 0.0)


@njit(cache=True)
def _inv3_mul(h, x, out):
    """out = I(h)^-1 x by the adjugate."""
    a, b, c, d, e, f = h[0], h[1], h[2], h[3], h[4], h[5]   # I11 I22 I33 I12 I13 I23
    A00 = b * c - f * f
    A01 = e * f - d * c
    A02 = d * f - b * e
    A11 = a * c - e * e
    A12 = d * e - a * f
    A22 = a * b - d * d
    det = a * A00 + d * A01 + e * A02
    out[0] = (A00 * x[0] + A01 * x[1] + A02 * x[2]) / det
    out[1] = (A01 * x[0] + A11 * x[1] + A12 * x[2]) / det
    out[2] = (A02 * x[0] + A12 * x[1] + A22 * x[2]) / det


@njit(cache=True)
def _I_mul(h, x, out):
    out[0] = h[0] * x[0] + h[3] * x[1] + h[4] * x[2]
    out[1] = h[3] * x[0] + h[1] * x[1] + h[5] * x[2]
    out[2] = h[4] * x[0] + h[5] * x[1] + h[2] * x[2]


@njit(cache=True)
def sami_kernel(sigma_nav, omega, V_mps, rho, alpha, beta, sigma_RN, omega_RN_R, domega_RN_R,
                tau_del, have_del, freeze, have_chart, kb, sb):
    """One SAMI cycle. ``kb``: the constants' buffer, ``sb``: the state's (their layouts:
    _K_*, _S_*; the controller's arrays are views of them). The command u_out (u_prev: last
    cycle's, the same array) is in sb. State (theta, eps_int, sigma_c) is committed only when
    every output is finite."""
    prm = kb[_K_PRM:_K_PRM + _NPRM]
    h_scale = kb[_K_HSCALE:_K_HSCALE + 6]
    h_lo = kb[_K_HLO:_K_HLO + 6]
    h_hi = kb[_K_HHI:_K_HHI + 6]
    u_sat_min = kb[_K_USAT:_K_USAT + 3]
    P = kb[_K_P:_K_P + 81].reshape((9, 9))
    theta = sb[_S_THETA:_S_THETA + 9]
    eps_int = sb[_S_EPSINT:_S_EPSINT + 3]
    sigma_c = sb[_S_SIGC:_S_SIGC + 3]
    u_out = sb[_S_U:_S_U + 3]
    u_prev = u_out
    eps = sb[_S_EPS:_S_EPS + 3]
    eps_dot = sb[_S_EPSDOT:_S_EPSDOT + 3]
    diag = sb[_S_DIAG:_S_DIAG + 7]
    wk = sb[_S_N:_S_N + _W_N]               # the cycle's work arrays: no allocation
    for i in range(diag.shape[0]):
        diag[i] = 0.0
    # --- controller MRP chart: continuous with the last cycle, switched with hysteresis
    s2n = sigma_nav[0] ** 2 + sigma_nav[1] ** 2 + sigma_nav[2] ** 2
    sig = wk[0:3]
    alt = wk[3:6]
    for i in range(3):
        sig[i] = sigma_nav[i]
        alt[i] = -sigma_nav[i] / s2n if s2n > 1e-300 else sigma_nav[i]
    ei = wk[6:9]
    for i in range(3):
        ei[i] = eps_int[i]
    if have_chart and s2n > 1e-300:
        d0 = 0.0
        d1 = 0.0
        for i in range(3):
            d0 += (sig[i] - sigma_c[i]) ** 2
            d1 += (alt[i] - sigma_c[i]) ** 2
        if d1 < d0:
            for i in range(3):
                sig[i], alt[i] = alt[i], sig[i]
        s2 = sig[0] ** 2 + sig[1] ** 2 + sig[2] ** 2
        if s2 > prm[_SWITCH] ** 2:
            # change chart; carry int(eps) through the shadow map's Jacobian
            # dS/dsigma = -I/s2 + 2 sigma sigma^T / s2^2 (so P_a int(eps) stays continuous)
            sx = sig[0] * ei[0] + sig[1] * ei[1] + sig[2] * ei[2]
            for i in range(3):
                ei[i] = -ei[i] / s2 + 2.0 * sig[i] * sx / (s2 * s2)
                sig[i] = alt[i]
            diag[_D_SWITCH] = 1.0
    s2 = sig[0] ** 2 + sig[1] ** 2 + sig[2] ** 2
    # --- reference in the same chart
    sr = wk[9:12]
    for i in range(3):
        sr[i] = sigma_RN[i]
    nearest_set_into(sr, sig)
    sr_d = wk[12:15]
    sr_dd = wk[15:18]
    sigma_derivatives(sr, omega_RN_R, domega_RN_R, sr_d, sr_dd)
    sd = wk[18:21]
    sigma_dot_into(sig, omega, sd)
    e = wk[21:24]
    ed = wk[24:27]
    for i in range(3):
        e[i] = sig[i] - sr[i]
        ed[i] = sd[i] - sr_d[i]
    # --- saturation awareness: last cycle's delivered torque far short of the command.
    # short[i]: axis i got more than one largest jet increment (u_sat_min / 2) and more than
    # shortfall_frac of its command away from it: the tracking error then carries torque
    # that was commanded but not delivered (or delivered unasked), which is no evidence about
    # the model, so that axis's aero factor does not learn from it, nor does the inertia.
    sat = False
    short = wk[99:102]                  # 1.0: the axis is short
    for i in range(3):
        short[i] = 0.0
    any_short = False
    if have_del:
        for i in range(3):
            miss = abs(u_prev[i] - tau_del[i])
            if abs(u_prev[i]) > u_sat_min[i] and miss > prm[_SFRAC] * abs(u_prev[i]):
                sat = True
            if miss > 0.5 * u_sat_min[i] and miss > prm[_SFRAC] * abs(u_prev[i]):
                short[i] = 1.0
                any_short = True
    diag[_D_SAT] = 1.0 if sat else 0.0
    diag[_D_SHORT] = 1.0 if any_short else 0.0
    # --- control law (paper eq 18)
    h = theta[0:6]
    M = wk[27:45].reshape((3, 6))
    regressor_M(sig, omega, sr_d, sr_dd, M)
    f = wk[45:48]
    for i in range(3):
        f[i] = prm[_CD] * ed[i] + prm[_KD] * e[i] + prm[_KI] * ei[i]
    g = wk[48:51]
    _Pa_mul(sig, f, g)
    # bank keeping: g is the feedback's body-frame angular acceleration. While pitch or yaw is
    # short, that axis's error cannot be taken out, and its component about the velocity vector
    # (a = v_B / V) is a bank error; the roll channel then nulls the whole error about a
    # instead of the body-roll error alone (g_x <- (a . g) / a_x for the short axes' terms).
    bk = kb[_K_BKEEP]
    if bk > 0.0 and abs(beta) < _BK_NEAR_TRIM and abs(alpha - prm[_ATRIM]) < _BK_NEAR_TRIM:
        a0 = math.cos(alpha) * math.cos(beta)
        if a0 > 0.1:
            a1 = math.sin(beta)
            a2 = math.sin(alpha) * math.cos(beta)
            g[0] += bk * (short[1] * a1 * g[1] + short[2] * a2 * g[2]) / a0
    ufb = wk[51:54]
    _I_mul(h, g, ufb)
    # L(t) = 1/2 S l V^2 diag(beta, alpha - alpha_trim, beta) D_est, D_est = rho_hat diag(C_lb, C_ma, C_nb)
    q = prm[_QSL] * rho * V_mps * V_mps
    lv = wk[54:57]
    lv[0] = q * beta * prm[_CLB]
    lv[1] = q * (alpha - prm[_ATRIM]) * prm[_CMA]
    lv[2] = q * beta * prm[_CNB]
    u = wk[57:60]
    for i in range(3):
        uff = 0.0
        for j in range(6):
            uff += M[i, j] * h[j]
        u[i] = uff - ufb[i] - lv[i] * theta[6 + i]
    # --- Lyapunov error state y = [int eps; eps; eps_dot]
    y = wk[60:69]
    for i in range(3):
        y[i] = ei[i]
        y[3 + i] = e[i]
        y[6 + i] = ed[i]
    Vl = 0.0
    w = wk[96:99]
    for i in range(3):
        w[i] = 0.0
    for i in range(9):
        Py = 0.0
        for j in range(9):
            Py += P[i, j] * y[j]
        Vl += y[i] * Py
        if i >= 6:
            w[i - 6] = Py                      # E^T P y
    diag[_D_V] = Vl
    # --- integrator (frozen while saturated, clamped)
    ei_new = wk[69:72]
    lim = prm[_ILIM]
    for i in range(3):
        v = ei[i] if sat else ei[i] + prm[_DT] * e[i]
        ei_new[i] = min(lim, max(-lim, v))
    # --- adaptation (paper eqs 22-27) with dead zone, freeze, saturation gate, projection
    th_new = wk[72:81]
    for i in range(9):
        th_new[i] = theta[i]
    if (not freeze) and (not sat) and Vl > prm[_VDEAD]:
        diag[_D_ADAPT] = 1.0
        # z = I_a*_hat^-1 w = J I_hat^-1 J^T w
        nsig = wk[81:84]
        for i in range(3):
            nsig[i] = -sig[i]
        t1 = wk[84:87]
        t2 = wk[87:90]
        z = wk[90:93]
        B_mul(nsig, w, t1)
        _inv3_mul(h, t1, t2)
        B_mul(sig, t2, z)
        for i in range(3):
            z[i] *= 1.0 / 16.0
        pz = wk[93:96]
        _Pa_mul(sig, z, pz)
        # h_hat_dot = -Gamma_h Y^T z, Y^T z = M^T P_a z; Gamma_h = gamma_h diag(h_scale^2)
        for j in range(6):
            if any_short:
                break
            yz = M[0, j] * pz[0] + M[1, j] * pz[1] + M[2, j] * pz[2]
            v = theta[j] - prm[_DT] * prm[_GH] * h_scale[j] * h_scale[j] * yz
            th_new[j] = min(h_hi[j], max(h_lo[j], v))
            if th_new[j] != v:
                diag[_D_PROJ] = 1.0
        if not physical_inertia(th_new[0:6], 1e-6):
            for j in range(6):
                th_new[j] = theta[j]              # reject the step: keep the last valid inertia
            diag[_D_PROJ] = 1.0
        # d_hat_dot = -Gamma_d (-P_a^T L)^T z = Gamma_d L P_a z
        for i in range(3):
            if short[i] != 0.0:
                continue
            v = theta[6 + i] + prm[_DT] * prm[_GD] * lv[i] * pz[i]
            th_new[6 + i] = min(prm[_DMAX], max(prm[_DMIN], v))
            if th_new[6 + i] != v:
                diag[_D_PROJ] = 1.0
    # --- commit only finite results
    ok = math.isfinite(Vl)
    for i in range(3):
        ok = ok and math.isfinite(u[i]) and math.isfinite(ei_new[i]) and math.isfinite(ed[i])
    for i in range(9):
        ok = ok and math.isfinite(th_new[i])
    if not ok:
        diag[_D_BAD] = 1.0
        for i in range(3):
            u_out[i] = 0.0
        return
    for i in range(3):
        u_out[i] = u[i]
        eps[i] = e[i]
        eps_dot[i] = ed[i]
        eps_int[i] = ei_new[i]
        sigma_c[i] = sig[i]
    for i in range(9):
        theta[i] = th_new[i]


class SamiController:
    """SAMI adaptive controller with the robustness the spec requires beyond the paper.

    Parameters are normalised for adaptation: h_hat_dot = -gamma_h I_ref diag(s^2) Y^T z with
    s = nominal principal moment for I11..I33 and s = h_prod_scale sqrt(Iii Ijj) for the
    products, I_ref = tr(I_nom)/3; d_hat_dot = gamma_d I_ref L P_a z. This makes gamma_h and
    gamma_d numbers of order one (the spec's kg m^2 gain of ~1e11 becomes ~1).

    MRP chart: the controller keeps its own MRP set continuous from cycle to cycle and
    switches to the shadow set only when |sigma| exceeds control.sigma_switch (> 1), carrying
    int(eps) through the shadow map's Jacobian; so eps, eps_dot and int(eps) never jump
    when navigation switches its set at |sigma| = 1, and noise near |sigma| = 1 cannot chatter.
    The reference is taken in the set nearest to that chart, its derivatives recomputed from
    guid.omega_RN_R and guid.domega_RN_R.

    Attributes for telemetry: freeze, h_hat (6) [kg m^2], d_hat (3), theta_hat (9) = [h_hat; d_hat],
    eps, eps_dot, eps_int (3), V_lyap = y^T P y, adapting, saturated, projected, chart_switched,
    rejected (bool flags of the last update), u_cal_B (3).
    """

    PARAMS: list[Param] = [
        Param("control.lambda_radps", 0.05, 10.0, "rad/s", "closed-loop pole: (s + lambda)^3"),
        Param("control.q_weight", 1e-3, 1e3, "", "Q = q_weight I9 in P A + A^T P = -Q"),
        Param("control.gamma_h", 0.0, 1e4, "", "normalised inertia adaptation gain (0 = off)"),
        Param("control.gamma_d", 0.0, 1e4, "", "normalised aero-factor adaptation gain (0 = off)"),
        Param("control.h_bound_frac", 0.01, 0.9, "", "projection: |h_hat - h_nom| <= frac * s (s: normalisation scale)"),
        Param("control.h_prod_scale", 1e-3, 1.0, "", "normalisation scale of products of inertia, fraction of sqrt(Iii Ijj)"),
        Param("control.d_min", 0.01, 1.0, "", "projection: lower bound of d_hat"),
        Param("control.d_max", 1.0, 10.0, "", "projection: upper bound of d_hat"),
        Param("control.deadzone", 0.0, 1e4, "", "no adaptation while y'Py < deadzone * V_q (V_q: smallest jet increment)"),
        Param("control.int_limit", 0.0, 10.0, "s", "clamp of each component of int(eps) [MRP s]"),
        Param("control.shortfall_frac", 0.0, 1.0, "", "saturation when |u - tau_delivered| > frac |u| on an axis"),
        Param("control.safe_rate_gain", 0.0, 10.0, "1/s", "SAFE mode: tau = -gain I_hat omega"),
        Param("control.sigma_switch", 1.0, 3.0, "", "controller MRP chart switches to the shadow set above this |sigma|"),
        Param("control.bank_keep", 0.0, 1.0, "", "share of a short pitch/yaw axis's error about the velocity vector the roll channel takes out (0 = the paper's law)"),
    ]

    def __init__(self, params: dict[str, float], vehicle: Vehicle, dt_s: float) -> None:
        if not isinstance(vehicle, Vehicle):
            raise ValueError("SamiController.vehicle: must be a common.model.Vehicle")
        if not isinstance(dt_s, (int, float)) or isinstance(dt_s, bool) or not math.isfinite(dt_s) or dt_s <= 0:
            raise ValueError(f"SamiController.dt_s: must be a finite number > 0, got {dt_s!r}")
        self._table = {p.name: p for p in self.PARAMS}
        self.params: dict[str, float] = {}
        for p in self.PARAMS:
            if p.name not in params:
                raise ValueError(f"{p.name}: missing (required)")
            self.params[p.name] = p.check(params[p.name])
        self.vehicle = vehicle
        self.dt_s = float(dt_s)
        self.h_nom = inertia_vector(vehicle.inertia_kgm2).astype(float)
        self.I_ref = float(np.trace(vehicle.inertia_kgm2)) / 3.0
        T = np.asarray(vehicle.torque_matrix_Nm, dtype=float)
        absT = np.abs(T)
        # smallest non-zero jet torque per axis (quantisation) and the largest
        self.tau_q_B = np.array([absT[i][absT[i] > 0].min() if np.any(absT[i] > 0) else 0.0 for i in range(3)])
        # a command on an axis of at least two of its largest single-jet increments should be
        # deliverable to within shortfall_frac unless authority is missing (saturation)
        self._kb = kb = np.zeros(_K_N)       # the kernel's constants and state (views below)
        self._sb = sb = np.zeros(_S_N + _W_N)
        self._rb = np.zeros(_S_N + _W_N)     # the rehearsal's copy of the state (fsw/law.py ``law_cycle``)
        self.u_sat_min_B = kb[_K_USAT:_K_USAT + 3]
        self.u_sat_min_B[:] = 2.0 * absT.max(axis=1)
        a = vehicle.aero
        self._aero = (0.5 * vehicle.S_ref_m2 * vehicle.l_ref_m, a.C_lbeta, a.C_malpha, a.C_nbeta, a.alpha_trim_rad)
        self.prm = kb[_K_PRM:_K_PRM + _NPRM]
        self.h_scale = kb[_K_HSCALE:_K_HSCALE + 6]
        self.h_lo = kb[_K_HLO:_K_HLO + 6]
        self.h_hi = kb[_K_HHI:_K_HHI + 6]
        self.P = kb[_K_P:_K_P + 81].reshape(9, 9)
        self.A = np.zeros((9, 9))
        self.theta_hat = sb[_S_THETA:_S_THETA + 9]
        self.h_hat = self.theta_hat[0:6]
        self.d_hat = self.theta_hat[6:9]
        self.eps = sb[_S_EPS:_S_EPS + 3]
        self.eps_dot = sb[_S_EPSDOT:_S_EPSDOT + 3]
        self.eps_int = sb[_S_EPSINT:_S_EPSINT + 3]
        self.u_cal_B = sb[_S_U:_S_U + 3]
        self._sigma_c = sb[_S_SIGC:_S_SIGC + 3]
        self._diag = sb[_S_DIAG:_S_DIAG + 7]
        self.chart = np.zeros(1)              # 1.0: the chart holds a valid sigma_c (``law_cycle``)
        self._zero3 = np.zeros(3)
        self._u_safe = np.zeros(3)
        self._lv = np.zeros(3)
        self.freeze = False
        self._derive()
        self.reset()

    # ------------------------------------------------------------------ configuration
    def _derive(self) -> None:
        """Gains, P, bounds and dead-zone level from the parameters."""
        p = self.params
        lam = p["control.lambda_radps"]
        c_d, k_d, k_i = 3.0 * lam, 3.0 * lam ** 2, lam ** 3          # (s + lambda)^3
        I3 = np.eye(3)
        Z = np.zeros((3, 3))
        self.A[:] = np.block([[Z, I3, Z], [Z, Z, I3], [-k_i * I3, -k_d * I3, -c_d * I3]])
        Q = p["control.q_weight"] * np.eye(9)
        # P A + A^T P = -Q  <=>  A^T P + P A^T^T = -Q (scipy solves a X + X a^H = q)
        P = scipy.linalg.solve_continuous_lyapunov(self.A.T, -Q)
        self.P[:] = 0.5 * (P + P.T)
        h = self.h_nom
        s = np.empty(6)
        s[0:3] = h[0:3]
        ps = p["control.h_prod_scale"]
        s[3] = ps * math.sqrt(h[0] * h[1])
        s[4] = ps * math.sqrt(h[0] * h[2])
        s[5] = ps * math.sqrt(h[1] * h[2])
        self.h_scale[:] = s
        frac = p["control.h_bound_frac"]
        self.h_lo[:] = h - frac * s
        self.h_hi[:] = h + frac * s
        # dead zone: eps per axis whose k_d feedback torque equals the smallest jet increment
        # (u ~ I P_a k_d eps ~ 4 I_ii k_d eps near sigma = 0), V_q = P_eps,eps |eps_q|^2
        eps_q = self.tau_q_B / (4.0 * h[0:3] * k_d)
        self.V_q = float(self.P[3, 3] * eps_q @ eps_q)
        if p["control.d_min"] > p["control.d_max"]:
            raise ValueError("control.d_min: must not exceed control.d_max")
        qsl, clb, cma, cnb, atrim = self._aero
        self.prm[:] = [c_d, k_d, k_i, p["control.gamma_h"] * self.I_ref, p["control.gamma_d"] * self.I_ref,
                       self.dt_s, p["control.deadzone"] * self.V_q, p["control.int_limit"],
                       p["control.shortfall_frac"], p["control.d_min"], p["control.d_max"],
                       p["control.sigma_switch"], qsl, clb, cma, cnb, atrim]
        self._kb[_K_BKEEP] = p["control.bank_keep"]
        # keep the current estimates inside (possibly new) bounds
        np.clip(self.theta_hat[0:6], self.h_lo, self.h_hi, out=self.theta_hat[0:6])
        np.clip(self.theta_hat[6:9], p["control.d_min"], p["control.d_max"], out=self.theta_hat[6:9])

    def set_param(self, name: str, value: float) -> None:
        """Validated (Param.check) parameter change; derived gains and P recomputed. On a
        ValueError nothing changes."""
        if name not in self._table:
            raise ValueError(f"{name}: unknown control parameter")
        v = self._table[name].check(value)
        old = self.params[name]
        self.params[name] = v
        try:
            self._derive()
        except ValueError:
            self.params[name] = old
            self._derive()
            raise

    def reset(self) -> None:
        """Estimates back to nominal (h_nom, d = 1), integrator and MRP chart cleared.
        ``freeze`` is left as it is (the mode manager owns it)."""
        self.theta_hat[0:6] = self.h_nom
        self.theta_hat[6:9] = np.clip(1.0, self.params["control.d_min"], self.params["control.d_max"])
        self.eps[:] = 0.0
        self.eps_dot[:] = 0.0
        self.eps_int[:] = 0.0
        self.u_cal_B[:] = 0.0
        self._sigma_c[:] = 0.0
        self._have_chart = False
        self._diag[:] = 0.0

    @property
    def _have_chart(self) -> bool:
        return bool(self.chart[0])

    @_have_chart.setter
    def _have_chart(self, v: bool) -> None:
        self.chart[0] = 1.0 if v else 0.0

    @property
    def V_lyap(self) -> float:
        """y^T P y of the last update."""
        return float(self._diag[_D_V])

    # ------------------------------------------------------------------ cycle
    def update(self, nav, guid, tau_delivered_prev_B: np.ndarray | None) -> np.ndarray:
        """u_cal (3,) body torque [N m] for this cycle (paper eq 18). ``tau_delivered_prev_B``
        is the torque the allocator modelled it delivered for last cycle's command (None when
        unknown). The returned array is reused: copy it to keep it."""
        have_del = tau_delivered_prev_B is not None
        tau = tau_delivered_prev_B if have_del else self._zero3
        sami_kernel(nav.sigma_BN, nav.omega_BN_B, nav.V_rel_mps, nav.rho_kgpm3, nav.alpha_rad, nav.beta_rad,
                    guid.sigma_RN, guid.omega_RN_R, guid.domega_RN_R, tau, have_del,
                    self.freeze, self._have_chart, self._kb, self._sb)
        if self._diag[_D_BAD] == 0.0:
            self._have_chart = True
        return self.u_cal_B

    @property
    def adapting(self) -> bool:
        return bool(self._diag[_D_ADAPT])

    @property
    def saturated(self) -> bool:
        return bool(self._diag[_D_SAT])

    @property
    def short(self) -> bool:
        """True when last cycle's delivered torque missed the command on some axis by more
        than quantisation: the affected aero factors and the inertia did not learn."""
        return bool(self._diag[_D_SHORT])

    @property
    def projected(self) -> bool:
        return bool(self._diag[_D_PROJ])

    @property
    def chart_switched(self) -> bool:
        return bool(self._diag[_D_SWITCH])

    @property
    def rejected(self) -> bool:
        """True when the last update met a non-finite value (u = 0, state kept)."""
        return bool(self._diag[_D_BAD])

    def safe_torque(self, nav) -> np.ndarray:
        """SAFE-mode rate damping tau = -k I_hat omega_BN_B [N m] (zero on non-finite rates)."""
        w = nav.omega_BN_B
        u = -self.params["control.safe_rate_gain"] * (self.inertia_hat() @ w)
        if not np.all(np.isfinite(u)):
            u[:] = 0.0
        self._u_safe[:] = u
        return self._u_safe

    def inertia_hat(self) -> np.ndarray:
        """Current inertia estimate I_hat (3x3) [kg m^2]."""
        return inertia_matrix(self.h_hat)

    def aero_torque_est(self, nav) -> np.ndarray:
        """Estimated static aerodynamic moment L(t) d_hat in body axes [N m] (paper eqs 4-6)."""
        qsl, clb, cma, cnb, atrim = self._aero
        q = qsl * nav.rho_kgpm3 * nav.V_rel_mps ** 2
        self._lv[:] = (q * nav.beta_rad * clb, q * (nav.alpha_rad - atrim) * cma, q * nav.beta_rad * cnb)
        return self._lv * self.d_hat
