"""The entry guidance's predictor (docs/fsw/entry-guidance.md), in the FSW's own models only:
point-mass gravity, the planet file's atmosphere scaled by the in-flight density estimate,
C_L and C_D at trim.

- ``predict``: the 3-DOF entry equations in the rotating planet-fixed frame (Cartesian, so
  no pole or heading singularity), RK4 in time, bank magnitude linear in energy, stopped
  at the deploy condition; ``predict_shaped`` the same after the reference shaper's
  transition from its present state (shaper.shaped_transition). Compiled, and they release
  the GIL: a real-time FSW runs them beside the control loop;
- ``path_limited_bank``: altitude-rate feedback that keeps load factor and heat rate under
  the vehicle's limits, flown by the predictor and by the vehicle (EntryGuidance.steer);
- ``predictor_constants``: the flat constants vector the kernels take (indices C_*), and
  ``deploy_energy``, the energy at which the bank line ends.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from common import atmosphere
from common.model import Scenario
from .shaper import N_TRANSITION, shaped_transition

_rho_exp = njit(cache=True, nogil=True)(atmosphere.density_exponential)
_rho_poly = njit(cache=True, nogil=True)(atmosphere.density_polynomial)
_speed_of_sound = njit(cache=True, nogil=True)(atmosphere.speed_of_sound)

# The predictor's constants: one flat vector (the compiled kernels take arrays), indexed by
# these compile-time constants; predictor_constants fills it.
C_MU = 0                        # gravitational parameter [m^3/s^2]
C_RE = 1                        # planet radius [m]
C_OM = 2                        # planet rotation rate [rad/s]
C_RHO_MODEL = 3                 # atmosphere model: 0 exponential, 1 polynomial
C_RHO0, C_H = 4, 5              # exponential atmosphere: density at zero altitude [kg/m^3], scale height [m]
C_KRHO = 6                      # density scale estimate K_rho [-]
C_KLD = 7                       # L/D scale estimate K_LD [-]
C_S_M = 8                       # reference area over mass [m^2/kg]
C_CL, C_CD = 9, 10              # lift and drag coefficients at trim [-]
C_MACH_F = 11                   # deploy Mach number (0: the deploy condition is the speed C_V_F)
C_V_F = 12                      # deploy speed [m/s]
C_H_FLOOR = 13                  # altitude at or below which a prediction has hit the ground [m]
C_H_CEIL = 14                   # altitude above which a climbing prediction has skipped out [m]
C_T_MAX = 15                    # longest prediction [s]
C_G0, C_RN, C_SG = 16, 17, 18   # surface gravity (the load factor's unit) [m/s^2], nose radius [m],
                                # Sutton-Graves constant [SI]
C_NLIM, C_QLIM = 19, 20         # path limits: load factor [g], heat rate [W/m^2] (0: off)
C_HTAU, C_HGAIN = 21, 22        # path-limit feedback: closing time [s], gain [s/m]
C_BLO, C_BHI = 23, 24           # the law's bank magnitude clipped to the phi_0 bounds [rad] (bank_profile)
C_BOX_MACH, C_BOX_QBAR = 25, 26 # the deploy box's Mach and dynamic-pressure maxima [-, Pa] (0: no box)
C_TGT = 27                      # 3: the target's unit position vector, planet-fixed (O_R_TRIG) ...
C_TRIG = 30                     # ... and 1 when the range trigger deploys (O_R_TRIG is then where it fires)
N_C = 31
# The predictor's outputs, indexed likewise
O_R = 0                         # 3: final position, planet-fixed [m]
O_T = 3                         # time of flight [s]
O_NMAX, O_QMAX = 4, 5           # peak load factor [g], peak heat rate [W/m^2]
O_H, O_V = 6, 7                 # final altitude [m] and speed [m/s]
O_FLAG = 8                      # how it ended: REACHED, SKIPPED, GROUND or TIMEOUT
O_H_BOX = 9                     # altitude where the deploy box is entered [m] (the final one without a box,
                                # or when the box is not entered before the deploy condition)
O_R_TRIG = 10                   # 3: where the range trigger fires, planet-fixed [m]: the first point inside
                                # the deploy box with the target abeam or behind (the final position when
                                # C_TRIG is 0, or the target is still ahead at the deploy condition) ...
O_XR_TRIG = 13                  # ... and the crossrange there [m, + the vehicle left of the target]: the
                                # target's distance off the track, across it (NaN when C_TRIG is 0)
N_O = 14
REACHED, SKIPPED, GROUND, TIMEOUT = 0, 1, 2, 3
T_PRED_MAX_S = 1500.0           # a prediction longer than this is a skip-out
SUTTON_GRAVES_MARS = 1.9027e-4  # k of q = k sqrt(rho / R_n) V^3 [SI] (docs/fsw/entry-guidance.md)


@njit(cache=True, nogil=True)
def path_limited_bank(bank_mag_rad: float, h_m: float, hdot_mps: float, n_g: float, q_wm2: float,
                      n_lim_g: float, q_lim_wm2: float, scale_height_m: float, tau_s: float,
                      gain_spm: float) -> float:
    """Bank magnitude [rad] after altitude-rate feedback on the path limits (Lu 2014): with an
    exponential atmosphere the load factor (~rho) and heat rate (~sqrt(rho)) would reach
    their limits at h_lim = h + H ln(n/n_lim), resp. h + 2H ln(q/q_lim), at today's speed.
    The vehicle may close on h_lim at hdot_ref = -(h - h_lim)/tau; descending faster than
    that raises cos(bank) (more lift up) by gain (hdot_ref - hdot). A limit <= 0 is off.
    Compiled: the predictor flies the same law."""
    c0 = math.cos(bank_mag_rad)
    c = c0
    for k in range(2):
        val, lim, sh = (n_g, n_lim_g, scale_height_m) if k == 0 else (q_wm2, q_lim_wm2, 2.0 * scale_height_m)
        if val <= 0.0 or lim <= 0.0:
            continue
        h_lim = h_m + sh * math.log(val / lim)
        hdot_ref = -(h_m - h_lim) / tau_s
        if hdot_mps < hdot_ref:
            c = max(c, c0 + gain_spm * (hdot_ref - hdot_mps))
    return math.acos(min(1.0, max(-1.0, c)))


@njit(cache=True, nogil=True)
def _deriv(x, c, b0, bf, e0, ef, sign, dx, aux, bank_fix=math.nan):
    """dx = f(x), x = [r (3), v (3)] in the rotating planet-fixed frame (v planet-relative):
    r'' = g - D w1 + L l - 2 Omega x v - Omega x (Omega x r); w1 = v/V, w2 = (v x r)/|.|,
    w3 = w1 x w2, l = sin(bank) w2 - cos(bank) w3 (the plant's frames, docs/plant.md).
    bank_fix: the signed bank flown instead of the law's (NaN: the law), for a shaped transition.
    aux: [h, V, load factor (g), heat rate (W/m^2), the law's bank magnitude (rad)]."""
    rx, ry, rz, vx, vy, vz = x[0], x[1], x[2], x[3], x[4], x[5]
    r2 = rx * rx + ry * ry + rz * rz
    r = math.sqrt(r2)
    mu = c[C_MU]
    kg = -mu / (r2 * r)
    h = r - c[C_RE]
    if c[C_RHO_MODEL] == 0.0:
        rho = _rho_exp(h, c[C_RHO0], c[C_H])
    else:
        rho = _rho_poly(h)
    rho *= c[C_KRHO]
    V = math.sqrt(vx * vx + vy * vy + vz * vz)
    q = 0.5 * rho * V * V * c[C_S_M]
    D = q * c[C_CD]
    L = q * c[C_CL] * c[C_KLD]
    # bank magnitude linear in energy e = mu/r - V^2/2 (docs/fsw/entry-guidance.md, longitudinal),
    # within the phi_0 bounds (a line from beyond one holds it: bank_profile), then the same
    # altitude-rate path-limit feedback the vehicle flies (EntryGuidance.steer):
    # without it the prediction misses the lift-up the feedback adds near peak load, and the
    # corrector learns of that range only after it is flown
    e = mu / r - 0.5 * V * V
    f = (e - e0) / (ef - e0) if ef != e0 else 1.0
    f = min(1.0, max(0.0, f))
    n_g = math.sqrt(D * D + L * L) / c[C_G0]
    q_heat = c[C_SG] * math.sqrt(rho / c[C_RN]) * V * V * V
    hdot = (rx * vx + ry * vy + rz * vz) / r
    mag = path_limited_bank(min(c[C_BHI], max(c[C_BLO], b0 + (bf - b0) * f)), h, hdot, n_g, q_heat, c[C_NLIM],
                            c[C_QLIM], c[C_H], c[C_HTAU], c[C_HGAIN])
    bank = sign * mag if math.isnan(bank_fix) else bank_fix
    e1x, e1y, e1z = vx / V, vy / V, vz / V
    hx, hy, hz = vy * rz - vz * ry, vz * rx - vx * rz, vx * ry - vy * rx
    hn = math.sqrt(hx * hx + hy * hy + hz * hz)
    e2x, e2y, e2z = hx / hn, hy / hn, hz / hn
    e3x, e3y, e3z = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    cb, sb = math.cos(bank), math.sin(bank)
    lx, ly, lz = sb * e2x - cb * e3x, sb * e2y - cb * e3y, sb * e2z - cb * e3z
    om = c[C_OM]
    dx[0], dx[1], dx[2] = vx, vy, vz
    dx[3] = kg * rx - D * e1x + L * lx + 2.0 * om * vy + om * om * rx
    dx[4] = kg * ry - D * e1y + L * ly - 2.0 * om * vx + om * om * ry
    dx[5] = kg * rz - D * e1z + L * lz
    aux[0] = h
    aux[1] = V
    aux[2] = n_g
    aux[3] = q_heat
    aux[4] = mag


@njit(cache=True, nogil=True)
def _end_metric(h, V, c):
    """Distance to the deploy condition, positive before it: Mach - Mach_f, or V - V_f."""
    if c[C_MACH_F] > 0.0:
        return V / _speed_of_sound(h) - c[C_MACH_F]
    return V - c[C_V_F]


@njit(cache=True, nogil=True)
def _box_metric(h, V, c):
    """Distance to the deploy box from above, positive before it: the larger of the Mach and
    the dynamic pressure (density scaled by the estimate) past the box's maxima, relative."""
    rho = _rho_exp(h, c[C_RHO0], c[C_H]) if c[C_RHO_MODEL] == 0.0 else _rho_poly(h)
    q = 0.5 * rho * c[C_KRHO] * V * V
    return max(V / _speed_of_sound(h) / c[C_BOX_MACH] - 1.0, q / c[C_BOX_QBAR] - 1.0)


@njit(cache=True, nogil=True)
def _ahead(x, c):
    """Along-track distance to the target, to first order [m^2/s]: the velocity's component
    along the target's direction in the local horizontal, times the distance (positive while
    the target is ahead; the range trigger's range to go, whose sign it has)."""
    r = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    ux, uy, uz = x[0] / r, x[1] / r, x[2] / r
    tu = c[C_TGT] * ux + c[C_TGT + 1] * uy + c[C_TGT + 2] * uz
    hv = ux * x[3] + uy * x[4] + uz * x[5]
    return (c[C_TGT] * x[3] + c[C_TGT + 1] * x[4] + c[C_TGT + 2] * x[5] - tu * hv) * r


@njit(cache=True, nogil=True)
def _across(x, c):
    """The crossrange at x [m]: the target's offset across the track (along the local
    horizontal normal to the velocity), positive when the vehicle is left of the target. At
    the target abeam it is the deploy miss, signed."""
    r = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
    ux, uy, uz = x[0] / r, x[1] / r, x[2] / r
    lx, ly, lz = uy * x[5] - uz * x[4], uz * x[3] - ux * x[5], ux * x[4] - uy * x[3]     # up x v: left
    ln = math.sqrt(lx * lx + ly * ly + lz * lz)
    d = (c[C_TGT] - ux) * lx + (c[C_TGT + 1] - uy) * ly + (c[C_TGT + 2] - uz) * lz
    return -d / ln * c[C_RE]


@njit(cache=True, nogil=True)
def predict(x0, c, b0, bf, e0, ef, sign, dt, out, t_flip=0.0):
    """Fly the 3-DOF model from x0 (planet-fixed [r, v_rel], m and m/s) until the deploy
    condition (or skip, ground, timeout). c: the constants (predictor_constants, indices
    C_*); the bank magnitude [rad] on the line from b0 at energy e0 to bf at ef [J/kg]
    (clipped to the phi_0 bounds, then the path-limit feedback); dt: RK4 step [s]. The
    bank's sign is ``sign``, or ``-sign`` before ``t_flip`` [s] (a reversal that takes
    effect then: the lateral mid-point of the shaped transition). out: final position (3)
    [m, planet-fixed], time of flight [s], peak load [g], peak heat rate [W/m^2], final
    altitude [m] and speed [m/s], flag (REACHED/SKIPPED/GROUND/TIMEOUT), the altitude where
    the deploy box was entered [m] (O_H_BOX: the highest the trigger can deploy), where the range
    trigger fires (O_R_TRIG, 3; interpolated to the target abeam) and the crossrange there
    (O_XR_TRIG). The last step is
    cut back linearly to the deploy condition. The law's bank is flown from the start."""
    _fly(x0, c, b0, bf, e0, ef, sign, dt, out, t_flip, np.empty(0), 0)


@njit(cache=True, nogil=True)
def predict_shaped(x0, c, b0, bf, e0, ef, sign, dt, out, shp, t_switch=0.0):
    """``predict``, but the bank first follows the reference shaper from its present state
    (shp, see shaped_transition) to the law's bank at x0 (sign ``sign``, the magnitude with
    the path-limit feedback) within the rate and acceleration limits the attitude chain is
    given (the controllability LP's authority): a reversal in progress, or one just
    commanded, is flown as the vehicle will fly it, by the way the shaper takes (through lift
    up unless lift down is shorter by more than shaper.REVERSAL_LIFT_UP_RAD). With t_switch > 0, the reference keeps the other sign until then (a reversal
    commanded at t_switch). Afterwards the law, as in ``predict``."""
    dx = np.empty(6)
    aux = np.empty(5)
    _deriv(x0, c, b0, bf, e0, ef, sign, dx, aux, math.nan)
    tab = np.empty(N_TRANSITION)
    n = shaped_transition(shp, -sign * aux[4] if t_switch > 0.0 else sign * aux[4], t_switch, sign * aux[4],
                          0.5 * dt, tab)
    _fly(x0, c, b0, bf, e0, ef, sign, dt, out, 0.0, tab, n)


@njit(cache=True, nogil=True)
def _bank_at(tab, n, t, t_sample):
    """The transition's bank at t (a multiple of t_sample), NaN once it has settled."""
    j = int(round(t / t_sample))
    return tab[j] if j < n - 1 else math.nan


@njit(cache=True, nogil=True)
def _fly(x0, c, b0, bf, e0, ef, sign, dt, out, t_flip, tab, n_tab):
    """The integration of ``predict`` and ``predict_shaped`` (tab: the transition's bank every
    dt/2, n_tab samples; 0: none)."""
    x = x0.copy()
    xp = x0.copy()                  # the state a step back (a prediction of no step ends at x0)
    k1 = np.empty(6)
    k2 = np.empty(6)
    k3 = np.empty(6)
    k4 = np.empty(6)
    xt = np.empty(6)
    aux = np.empty(5)
    t = 0.0
    nmax = 0.0
    qmax = 0.0
    _deriv(x, c, b0, bf, e0, ef, sign, k1, aux)
    m_prev = _end_metric(aux[0], aux[1], c)
    b_prev = _box_metric(aux[0], aux[1], c) if c[C_BOX_MACH] > 0.0 else 1.0
    h_prev = aux[0]
    h_box = math.nan
    flag = TIMEOUT
    frac = 1.0
    trig = c[C_TRIG] != 0.0
    g_prev = _ahead(x, c) if trig else 0.0
    fired = False
    while t < c[C_T_MAX]:
        xp[:] = x
        sg = -sign if t < t_flip else sign
        bf0 = bf1 = bf2 = math.nan
        if n_tab > 1:
            bf0 = _bank_at(tab, n_tab, t, 0.5 * dt)
            bf1 = _bank_at(tab, n_tab, t + 0.5 * dt, 0.5 * dt)
            bf2 = _bank_at(tab, n_tab, t + dt, 0.5 * dt)
        _deriv(x, c, b0, bf, e0, ef, sg, k1, aux, bf0)
        if aux[2] > nmax:
            nmax = aux[2]
        if aux[3] > qmax:
            qmax = aux[3]
        for i in range(6):
            xt[i] = x[i] + 0.5 * dt * k1[i]
        _deriv(xt, c, b0, bf, e0, ef, sg, k2, aux, bf1)
        for i in range(6):
            xt[i] = x[i] + 0.5 * dt * k2[i]
        _deriv(xt, c, b0, bf, e0, ef, sg, k3, aux, bf1)
        for i in range(6):
            xt[i] = x[i] + dt * k3[i]
        _deriv(xt, c, b0, bf, e0, ef, sg, k4, aux, bf2)
        for i in range(6):
            x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        t += dt
        r = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
        h = r - c[C_RE]
        V = math.sqrt(x[3] * x[3] + x[4] * x[4] + x[5] * x[5])
        w_box = 0.0                     # where in this step the box was entered (fraction)
        if math.isnan(h_box) and c[C_BOX_MACH] > 0.0:
            b = _box_metric(h, V, c)
            if b <= 0.0:
                w_box = b_prev / (b_prev - b) if b_prev > b else 1.0
                h_box = h_prev + w_box * (h - h_prev)
            b_prev = b
        h_prev = h
        if trig and not fired:
            g = _ahead(x, c)
            if g <= 0.0 and (c[C_BOX_MACH] <= 0.0 or not math.isnan(h_box)):
                # the trigger fires here: at the target abeam, interpolated within the step,
                # or where the box is entered when the target was passed above it
                w = max(g_prev / (g_prev - g) if g_prev > 0.0 else 0.0, w_box)
                for i in range(6):
                    xt[i] = xp[i] + w * (x[i] - xp[i])
                out[O_R_TRIG], out[O_R_TRIG + 1], out[O_R_TRIG + 2] = xt[0], xt[1], xt[2]
                out[O_XR_TRIG] = _across(xt, c)
                fired = True
            g_prev = g
        m = _end_metric(h, V, c)
        if m <= 0.0:
            frac = m_prev / (m_prev - m) if m_prev > m else 1.0
            flag = REACHED
            break
        m_prev = m
        if h <= c[C_H_FLOOR]:
            flag = GROUND
            break
        if h >= c[C_H_CEIL] and (x[0] * x[3] + x[1] * x[4] + x[2] * x[5]) > 0.0:
            flag = SKIPPED
            break
    for i in range(6):
        x[i] = xp[i] + frac * (x[i] - xp[i])
    t -= (1.0 - frac) * dt
    out[0], out[1], out[2] = x[0], x[1], x[2]
    out[O_T] = t
    out[O_NMAX] = nmax
    out[O_QMAX] = qmax
    out[O_H] = math.sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]) - c[C_RE]
    out[O_V] = math.sqrt(x[3] * x[3] + x[4] * x[4] + x[5] * x[5])
    out[O_FLAG] = flag
    out[O_H_BOX] = out[O_H] if math.isnan(h_box) else h_box
    if not fired:
        out[O_R_TRIG], out[O_R_TRIG + 1], out[O_R_TRIG + 2] = x[0], x[1], x[2]
        out[O_XR_TRIG] = _across(x, c) if trig else math.nan


def predictor_constants(scenario: Scenario, params: dict) -> np.ndarray:
    """The predictor's constants from the FSW's models (nominal vehicle, planet file)."""
    pl, veh = scenario.planet, scenario.vehicle
    c = np.zeros(N_C)
    c[C_MU], c[C_RE], c[C_OM] = pl.mu_m3ps2, pl.radius_m, pl.omega_radps
    c[C_RHO_MODEL] = 0.0 if pl.density_model == "exponential" else 1.0
    c[C_RHO0], c[C_H] = pl.rho0_kgpm3, pl.scale_height_m
    c[C_KRHO] = c[C_KLD] = 1.0
    c[C_S_M] = veh.S_ref_m2 / veh.mass_kg
    c[C_CL], c[C_CD] = veh.aero.C_L, veh.aero.C_D
    c[C_MACH_F] = scenario.end_mach if scenario.end_speed_mps is None else 0.0
    c[C_V_F] = scenario.end_speed_mps or 0.0
    c[C_H_FLOOR] = 0.0
    c[C_H_CEIL] = scenario.altitude_m + 10_000.0
    c[C_T_MAX] = T_PRED_MAX_S
    c[C_G0] = pl.g0_mps2
    c[C_RN] = veh.nose_radius_m
    c[C_SG] = SUTTON_GRAVES_MARS
    c[C_NLIM] = params["npc.limit_frac"] * veh.max_load_g
    c[C_QLIM] = params["npc.limit_frac"] * veh.max_heat_rate_wcm2 * 1e4
    c[C_HTAU], c[C_HGAIN] = params["npc.hdot_tau_s"], params["npc.hdot_gain"]
    c[C_BLO], c[C_BHI] = math.radians(params["npc.bank_min_deg"]), math.radians(params["npc.bank_max_deg"])
    box = veh.deploy_box
    if box is not None:
        c[C_BOX_MACH], c[C_BOX_QBAR] = box.mach_max, box.qbar_max_pa
    if scenario.target_lat_rad is not None:
        lat, lon = scenario.target_lat_rad, scenario.target_lon_rad
        c[C_TGT:C_TGT + 3] = math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)
        c[C_TRIG] = float(scenario.deploy_by == "fsw" and params.get("deploy.trigger") == "range")
    return c


def deploy_energy(scenario: Scenario, h_deploy_m: float) -> float:
    """e_f = mu/r - V^2/2 at the deploy condition, taken at altitude h_deploy_m."""
    pl = scenario.planet
    V = scenario.end_speed_mps if scenario.end_speed_mps is not None else \
        scenario.end_mach * atmosphere.speed_of_sound(h_deploy_m)
    return pl.mu_m3ps2 / (pl.radius_m + h_deploy_m) - 0.5 * V * V
