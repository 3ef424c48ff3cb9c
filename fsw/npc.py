"""Numerical predictor-corrector entry guidance (spec 60-guidance.md), after P. Lu,
"Entry Guidance: A Unified Method", JGCD 37(3), 2014 (FNPEG).

Only the FSW's own models: point-mass gravity, the planet file's atmosphere scaled by the
in-flight density estimate, C_L and C_D at trim. The pieces, each testable on its own:

- ``predict``: the 3-DOF entry equations in the rotating planet-fixed frame (Cartesian,
  so no pole or heading singularity), RK4 in time, bank magnitude linear in energy,
  stopped at the deploy condition; compiled, and it releases the GIL (a real-time FSW runs
  it beside the control loop);
- ``solve_bank``: the corrector, a safeguarded secant on the range miss z(phi_0), over the
  family ``bank_profile`` (the line in energy, a phi_0 bound held beyond it);
- ``DensityEstimator``: K_rho = sensed drag / modelled drag, and K_LD likewise for L/D,
  low-pass filtered and bounded;
- ``LateralLogic``: bank-sign reversals when the heading error to the target leaves a
  corridor that narrows with speed;
- ``path_limited_bank``: altitude-rate feedback that keeps load factor and heat rate
  under the vehicle's limits;
- ``BankShaper``: the commanded bank turned into phi_r, phidot_r, phiddot_r within the
  rate and acceleration limits (the attitude chain downstream is the profile mode's);
- ``EntryGuidance``: the guidance cycle that ties them together.
"""
from __future__ import annotations

import math
import threading
import time

import numpy as np
from numba import njit

from common import atmosphere, rt
from common.model import Scenario
from common.events import EventLog, Severity
from .params import Param

_rho_exp = njit(cache=True, nogil=True)(atmosphere.density_exponential)
_rho_poly = njit(cache=True, nogil=True)(atmosphere.density_polynomial)
_speed_of_sound = njit(cache=True, nogil=True)(atmosphere.speed_of_sound)

# Ground-settable: EntryGuidance.set_param takes a new value, and the next guidance cycle
# applies it to the predictor, the corrector, the estimator, the path limits and the lateral
# logic before it starts its correction (never inside one).
PARAMS = [
    Param("npc.bank_final_deg", 0.0, 180.0, "deg", "bank magnitude at the deploy energy (phi_f)"),
    Param("npc.bank_min_deg", 0.0, 90.0, "deg", "lower bound of phi_0"),
    Param("npc.bank_max_deg", 90.0, 180.0, "deg", "upper bound of phi_0"),
    Param("npc.h_deploy_m", 0.0, 5e4, "m", "altitude that defines the deploy energy e_f"),
    Param("npc.dt_pred_s", 0.1, 10.0, "s", "predictor RK4 step"),
    Param("npc.max_iter", 1, 20, "", "predictions per guidance cycle (at most)", integer=True),
    Param("npc.tol_m", 1.0, 1e5, "m", "range miss accepted by the corrector"),
    Param("npc.k_tau_s", 0.1, 100.0, "s", "time constant of the density and L/D estimates"),
    Param("npc.k_min", 0.05, 1.0, "", "lower bound of the density and L/D scale estimates"),
    Param("npc.k_max", 1.0, 20.0, "", "upper bound of the density and L/D scale estimates"),
    Param("npc.k_drag_min", 0.0, 10.0, "m/s^2", "modelled drag below which the estimates hold"),
    Param("npc.dpsi_hi_deg", 0.0, 45.0, "deg", "heading corridor half-width at entry speed"),
    Param("npc.dpsi_lo_deg", 0.0, 45.0, "deg", "heading corridor half-width at deploy speed"),
    Param("npc.rev_gap_s", 0.0, 300.0, "s", "minimum time between bank reversals"),
    Param("npc.v_norev_mps", 0.0, 8000.0, "m/s", "no reversal below this speed"),
    Param("npc.limit_frac", 0.1, 1.0, "", "path limits enforced at this fraction of the vehicle's"),
    Param("npc.hdot_tau_s", 0.5, 200.0, "s", "altitude-rate feedback: time to close on the limit altitude"),
    Param("npc.hdot_gain", 0.0, 1.0, "s/m", "altitude-rate feedback: change of cos(bank) per m/s"),
    Param("npc.tgo_freeze_s", 0.0, 300.0, "s", "predicted time to deploy below which phi_0 is held"),
    Param("npc.h_floor_m", 0.0, 5e4, "m", "predicted deploy altitude kept above this, range traded (0: off)"),
    # a design bound of the floor's trade (the unit tests show it); no take-effect case from
    # the guided-nominal start, where no trade within any bound reaches a floor
    Param("npc.floor_miss_max_m", 0.0, 1e5, "m", "predicted deploy miss the altitude floor may trade up to",
          ground_settable=False),
]

# flat constants vector of the predictor (indices are compile-time constants)
C_MU, C_RE, C_OM, C_RHO_MODEL, C_RHO0, C_H, C_KRHO, C_KLD = 0, 1, 2, 3, 4, 5, 6, 7
C_S_M, C_CL, C_CD, C_MACH_F, C_V_F, C_H_FLOOR, C_H_CEIL, C_T_MAX = 8, 9, 10, 11, 12, 13, 14, 15
C_G0, C_RN, C_SG = 16, 17, 18
C_NLIM, C_QLIM, C_HTAU, C_HGAIN = 19, 20, 21, 22   # path-limit feedback (0 limits: off)
C_BLO, C_BHI = 23, 24     # the law's bank magnitude clipped to the phi_0 bounds (bank_profile)
N_C = 25
# predictor outputs
O_R = 0                     # 3: final position, planet-fixed [m]
O_T, O_NMAX, O_QMAX, O_H, O_V, O_FLAG = 3, 4, 5, 6, 7, 8
N_O = 9
REACHED, SKIPPED, GROUND, TIMEOUT = 0, 1, 2, 3
T_PRED_MAX_S = 1500.0             # a prediction longer than this is a skip-out
SUTTON_GRAVES_MARS = 1.9027e-4     # k of q = k sqrt(rho / R_n) V^3 [SI] (spec 60-guidance.md)


@njit(cache=True, nogil=True)
def path_limited_bank(bank_mag: float, h: float, hdot: float, n_g: float, q_wm2: float, n_lim: float,
                      q_lim: float, H_m: float, tau_s: float, gain: float) -> float:
    """Bank magnitude after altitude-rate feedback on the path limits (Lu 2014): with an
    exponential atmosphere the load factor (~rho) and heat rate (~sqrt(rho)) would reach
    their limits at h_lim = h + H ln(n/n_lim), resp. h + 2H ln(q/q_lim), at today's speed.
    The vehicle may close on h_lim at hdot_ref = -(h - h_lim)/tau; descending faster than
    that raises cos(bank) (more lift up) by gain (hdot_ref - hdot). Compiled: the predictor
    flies the same law."""
    c0 = math.cos(bank_mag)
    c = c0
    for k in range(2):
        val, lim, sh = (n_g, n_lim, H_m) if k == 0 else (q_wm2, q_lim, 2.0 * H_m)
        if val <= 0.0 or lim <= 0.0:
            continue
        h_lim = h + sh * math.log(val / lim)
        hdot_ref = -(h - h_lim) / tau_s
        if hdot < hdot_ref:
            c = max(c, c0 + gain * (hdot_ref - hdot))
    return math.acos(min(1.0, max(-1.0, c)))


@njit(cache=True, nogil=True)
def shaper_accel(phi, phid, target, rate_limit, accel_limit, dt):
    """The reference's acceleration towards target: bang-bang at the acceleration limit to
    the desired rate min(rate limit, sqrt(2 a |e|) (braking), |e|/dt), by sign of the error.
    One law for the BankShaper and the predictor."""
    e = target - phi
    v_des = math.copysign(min(rate_limit, math.sqrt(2.0 * accel_limit * abs(e)), abs(e) / dt), e)
    return max(-accel_limit, min(accel_limit, (v_des - phid) / dt))


@njit(cache=True, nogil=True)
def shaper_branch(phi, sign_now, turn, bank_signed):
    """(sign, turn) of the reference's target bank_signed + turn (turn a multiple of 2 pi): a
    new reversal goes the shorter way from phi; once the reference is on the commanded
    side, magnitude changes take the nearest way (they never cross 0 or 180 deg)."""
    s = 1.0 if bank_signed >= 0 else -1.0
    if s != sign_now or math.sin(phi) * s > 0.0:
        return s, 2.0 * math.pi * round((phi - bank_signed) / (2.0 * math.pi))
    return sign_now, turn


def reversal_other_way(shp: np.ndarray, sign: float) -> np.ndarray | None:
    """The shaper's state (shaped_transition's shp) with a reversal to ``sign`` going the
    other way round, or None: when no reversal is under way (the reference already on the
    side of ``sign``: magnitude changes take the nearest way), or when the other way is not
    the shorter one from the reference's state (braking included). The way a reversal
    goes is chosen for the magnitude commanded when it starts; the corrector's next answer
    can make the other way the shorter (a reversal begun at 92 deg through 180 deg, then a
    10 deg command: 258 deg on through lift down, ~100 deg back through lift up). The way
    round is the turn (a multiple of 2 pi) added to the command; the shaper keeps a given
    turn until the reference has crossed to the commanded side."""
    phi, phid, accel, mag = float(shp[0]), float(shp[1]), float(shp[5]), float(shp[7])
    if math.sin(phi) * sign >= 0.0 or accel <= 0.0:
        return None
    s, turn = shaper_branch(phi, float(shp[2]), float(shp[3]), math.copysign(mag, sign))
    target = math.copysign(mag, sign) + turn
    other = target - math.copysign(2.0 * math.pi, target - phi)
    # moving towards the present target, the other way first brakes: v^2/2a out and back
    brake = phid * phid / accel if phid * (target - phi) > 0.0 else 0.0
    if abs(other - phi) + brake >= abs(target - phi):
        return None
    alt = shp.copy()
    alt[2], alt[3] = s, other - math.copysign(mag, sign)
    return alt


@njit(cache=True, nogil=True)
def _deriv(x, c, b0, bf, e0, ef, sign, dx, aux, bank_fix=math.nan):
    """dx = f(x), x = [r (3), v (3)] in the rotating planet-fixed frame (v planet-relative):
    r'' = g - D w1 + L l - 2 Omega x v - Omega x (Omega x r); w1 = v/V, w2 = (v x r)/|.|,
    w3 = w1 x w2, l = sin(bank) w2 - cos(bank) w3 (the plant's frames, spec 10-plant.md).
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
    # bank magnitude linear in energy e = mu/r - V^2/2 (spec 60-guidance.md, longitudinal),
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
def predict(x0, c, b0, bf, e0, ef, sign, dt, out, t_flip=0.0):
    """Fly the 3-DOF model from x0 until the deploy condition (or skip, ground, timeout).
    The bank's sign is ``sign``, or ``-sign`` before ``t_flip`` [s] (a reversal that takes
    effect then: the lateral mid-point of the shaped transition). out: final position (3)
    [m, planet-fixed], time of flight [s], peak load [g], peak heat rate [W/m^2], final
    altitude [m] and speed [m/s], flag (REACHED/SKIPPED/GROUND/TIMEOUT). The last step is
    cut back linearly to the deploy condition. The law's bank is flown from the start."""
    _fly(x0, c, b0, bf, e0, ef, sign, dt, out, t_flip, np.empty(0), 0)


# a shaped transition longer than this is not modelled past it (the law takes over)
N_TRANSITION = 256


@njit(cache=True, nogil=True)
def shaped_transition(shp, bank_a, t_switch, bank_b, t_sample, tab):
    """The reference's bank [rad, signed, on the shaper's branch] every t_sample [s] from now
    while the BankShaper moves from its state towards bank_a and, from t_switch on, towards
    bank_b (a reversal commanded then): the same branch rule and acceleration law, stepped
    at the control period. shp: [phi, phidot, sign, turn, rate limit, acceleration limit,
    control period, the magnitude commanded now]. The branch (which way round) is the one
    the shaper takes for the command now, fixed for the prediction: in flight the new
    answer arrives after the reversal has set off, and a branch that followed the
    corrector's trial bank would flip near a 180 deg swing and make the miss function jump.
    Returns the number of samples written to tab; the last is the first at which the
    reference has settled on bank_b (<= 1 when it already has)."""
    phi, phid, s_now, turn = shp[0], shp[1], shp[2], shp[3]
    rate, accel, dtc, mag_now = shp[4], shp[5], shp[6], shp[7]
    s_now, turn = shaper_branch(phi, s_now, turn, math.copysign(mag_now, bank_a))
    target = bank_a + turn
    switched = t_switch <= 0.0
    if switched:
        s_now, turn = shaper_branch(phi, s_now, turn, math.copysign(mag_now, bank_b))
        target = bank_b + turn
    per = max(1, int(round(t_sample / dtc)))
    n = 0
    k = 0
    while n < tab.shape[0]:
        if not switched and k * dtc >= t_switch - 1e-9:
            switched = True
            s_now, turn = shaper_branch(phi, s_now, turn, math.copysign(mag_now, bank_b))
            target = bank_b + turn
        if k % per == 0:
            tab[n] = phi
            n += 1
            if switched and abs(target - phi) < 1e-3 and abs(phid) < 1e-3:
                break
        a = shaper_accel(phi, phid, target, rate, accel, dtc)
        phi += phid * dtc + 0.5 * a * dtc * dtc
        phid += a * dtc
        k += 1
    return n


@njit(cache=True, nogil=True)
def predict_shaped(x0, c, b0, bf, e0, ef, sign, dt, out, shp, t_switch=0.0):
    """``predict``, but the bank first follows the reference shaper from its present state
    (shp, see shaped_transition) to the law's bank at x0 (sign ``sign``, the magnitude with
    the path-limit feedback) within the rate and acceleration limits the attitude chain is
    given (the controllability LP's authority): a reversal in progress, or one just
    commanded, is flown as the vehicle will fly it, through lift down when its shorter way
    is that. With t_switch > 0, the reference keeps the other sign until then (a reversal
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
    xp = np.empty(6)
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
    flag = TIMEOUT
    frac = 1.0
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


def central_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Great-circle angle between two position vectors [rad] (atan2 form: exact near 0)."""
    cr = np.cross(a, b)
    return math.atan2(math.sqrt(float(cr @ cr)), float(a @ b))


def unit_from_latlon(lat_rad: float, lon_rad: float) -> np.ndarray:
    return np.array([math.cos(lat_rad) * math.cos(lon_rad), math.cos(lat_rad) * math.sin(lon_rad),
                     math.sin(lat_rad)])


def planet_fixed(r_N: np.ndarray, v_N: np.ndarray, t_s: float, omega_radps: float) -> np.ndarray:
    """[r, v_rel] in the planet-fixed frame at t (N and the planet frame coincide at t = 0;
    longitude = atan2(y, x) - Omega t, as the plant reports it)."""
    a = omega_radps * t_s
    ca, sa = math.cos(a), math.sin(a)
    vr = np.array([v_N[0] + omega_radps * r_N[1], v_N[1] - omega_radps * r_N[0], v_N[2]])
    x = np.empty(6)
    x[0], x[1], x[2] = ca * r_N[0] + sa * r_N[1], -sa * r_N[0] + ca * r_N[1], r_N[2]
    x[3], x[4], x[5] = ca * vr[0] + sa * vr[1], -sa * vr[0] + ca * vr[1], vr[2]
    return x


def heading_error(x: np.ndarray, target_u: np.ndarray) -> tuple[float, float]:
    """(heading error to the target [rad] (positive: the target lies to the left), range
    to go [rad]) from a planet-fixed state. Heading clockwise from north."""
    r = x[:3]
    up = r / np.linalg.norm(r)
    east = np.array([-up[1], up[0], 0.0])
    en = np.linalg.norm(east)
    east = east / en if en > 1e-12 else np.array([0.0, 1.0, 0.0])
    north = np.cross(up, east)
    v = x[3:]
    psi = math.atan2(float(v @ east), float(v @ north))
    d = target_u - float(target_u @ up) * up          # direction to the target, in the local plane
    bearing = math.atan2(float(d @ east), float(d @ north))
    return math.remainder(psi - bearing, 2.0 * math.pi), central_angle(r, target_u)


def crossrange(r_now: np.ndarray, target_u: np.ndarray, r_f: np.ndarray, radius_m: float) -> float:
    """Signed distance [m] of the point r_f off the great circle from r_now to the target,
    positive to the left of that path (atan2 form of the angle off the circle's plane)."""
    n = np.cross(r_now, target_u)
    nn = math.sqrt(float(n @ n))
    if nn == 0.0:
        return 0.0
    rf = math.sqrt(float(r_f @ r_f))
    s = float(r_f @ n) / (nn * rf)
    return math.asin(min(1.0, max(-1.0, s))) * radius_m


def solve_bank(z, x_lo: float, x_hi: float, x0: float, tol: float, max_iter: int,
               dx0: float = math.radians(5.0)) -> tuple[float, float, int, bool]:
    """Root of a monotonic scalar function z on [x_lo, x_hi]: secant steps warm-started at
    x0; once two points of opposite sign are known, an iterate outside them is replaced by
    their midpoint (so it cannot diverge). Returns (x, z(x), evaluations, converged
    |z| <= tol). Without a root in the bounds the secant runs into a bound and stops
    there: the answer is then the point of smallest |z| seen (converged False)."""
    pts: list[tuple[float, float]] = []

    def ev(x: float) -> float:
        zx = float(z(x))
        pts.append((x, zx))
        return zx

    x1 = min(max(x0, x_lo), x_hi)
    if abs(ev(x1)) <= tol:
        return x1, pts[0][1], 1, True
    ev(x1 + dx0 if x1 + dx0 <= x_hi else x1 - dx0)
    while len(pts) < max_iter:
        best = min(pts, key=lambda p: abs(p[1]))
        if abs(best[1]) <= tol:
            break
        (xa, za), (xb, zb) = pts[-2], pts[-1]
        xn = xb - zb * (xb - xa) / (zb - za) if zb != za else xb + dx0
        neg = [p[0] for p in pts if p[1] < 0.0]
        pos = [p[0] for p in pts if p[1] > 0.0]
        if neg and pos:
            a, b = min(((u, v) for u in neg for v in pos), key=lambda uv: abs(uv[0] - uv[1]))
            a, b = min(a, b), max(a, b)
            if not a < xn < b:
                xn = 0.5 * (a + b)
        else:
            xn = min(max(xn, x_lo), x_hi)
            if any(abs(xn - p[0]) < 1e-12 for p in pts):
                break              # pushed against a bound already tried: no root inside
        ev(xn)
    best = min(pts, key=lambda p: abs(p[1]))
    return best[0], best[1], len(pts), abs(best[1]) <= tol


HOLD_MAX = 1.0 - 1e-6    # bank_profile: a bound held to the deploy, within float reach


def bank_profile(p: float, lo: float, hi: float, f: float) -> tuple[float, float]:
    """The corrector's one-parameter family: (phi_0, phi_f) of the line in energy from the
    bank now to phi_f at the deploy energy, which the predictor clips to the phi_0 bounds
    [lo, hi]. Inside them phi_0 = p and phi_f = f. Beyond a bound (p up to profile_span's)
    the family goes on with the bound held for the fraction k = (p - hi) / (hi - f) of the
    energy to go (resp. (lo - p) / (f - lo)) and the line to f after it: phi_0 is then the
    line's start above hi (below lo) that reaches the bound at k; k = 1 holds it to the end.

    Why a held bound and not phi_0 pinned at it: the bank commanded is the profile's now,
    and the next cycle re-anchors the profile at its own energy. A profile "from hi now to f
    at the deploy" pinned at hi is re-anchored at hi every cycle and flown at hi to the end,
    while every prediction had the bank leave it (guided-nominal after its final reversal:
    165 deg for 57 s, each prediction 0.1-1 km off across and 0.6-1 km along; predicted
    with 165 deg held, the deploy was the flown one within 10 m). A held bound is a profile
    the next cycle finds again (the same line, clipped), so the predictions are the flight.
    Continuous at the bounds and monotonic in range as p is."""
    if p > hi and hi > f:
        k = min((p - hi) / (hi - f), HOLD_MAX)
        return (hi - f * k) / (1.0 - k), f
    if p < lo and f > lo:
        k = min((lo - p) / (f - lo), HOLD_MAX)
        return (lo - f * k) / (1.0 - k), f
    return p, f


def profile_span(lo: float, hi: float, f: float) -> tuple[float, float]:
    """The range of bank_profile's parameter: down to lo held to the end, up to hi held."""
    return lo - max(0.0, f - lo), hi + max(0.0, hi - f)


def profile_at(p: float, lo: float, hi: float, f: float, frac: float) -> float:
    """bank_profile(p)'s parameter re-anchored at the fraction frac of its energy span: the
    same profile from there on, as the next cycle's family writes it (its warm start: an
    answer still within tolerance is then the profile already flown, not a new one)."""
    b0, bf = bank_profile(p, lo, hi, f)
    b = b0 + (bf - b0) * min(1.0, max(0.0, frac))
    if b > hi and hi > f:
        return hi + (b - hi) / (b - bf) * (hi - f)
    if b < lo and f > lo:
        return lo - (lo - b) / (bf - b) * (f - lo)
    return b


class DensityEstimator:
    """K_rho = sensed drag / modelled drag and K_LD = sensed L/D / model L/D, first-order
    low-pass filtered (time constant npc.k_tau_s), bounded to [k_min, k_max], held while
    the modelled drag is below npc.k_drag_min (too thin an atmosphere to measure)."""

    def __init__(self, params: dict, S_m2: float, mass_kg: float, C_L: float, C_D: float):
        self.tau_s = params["npc.k_tau_s"]
        self.k_min, self.k_max = params["npc.k_min"], params["npc.k_max"]
        self.drag_min = params["npc.k_drag_min"]
        self.S_m, self.C_L, self.C_D = S_m2 / mass_kg, C_L, C_D
        self.k_rho = 1.0
        self.k_ld = 1.0
        self.updates = 0
        self.drag_sensed = 0.0      # [m/s^2]
        self.lift_sensed = 0.0

    def update(self, dt_s: float, accel_B: np.ndarray, C_BN: np.ndarray, vrel_N: np.ndarray, rho_model: float) -> None:
        V = math.sqrt(float(vrel_N @ vrel_N))
        if V <= 0.0:
            return
        a_N = C_BN.T @ accel_B
        drag = -float(a_N @ vrel_N) / V
        lift_v = a_N + drag * vrel_N / V
        lift = math.sqrt(float(lift_v @ lift_v))
        self.drag_sensed, self.lift_sensed = drag, lift
        d_model = 0.5 * rho_model * V * V * self.S_m * self.C_D
        if d_model < self.drag_min or drag <= 0.0:
            return
        a = min(1.0, dt_s / self.tau_s)
        k = min(self.k_max, max(self.k_min, drag / d_model))
        kl = min(self.k_max, max(self.k_min, (lift / drag) / (self.C_L / self.C_D))) if self.C_L != 0 else 1.0
        self.k_rho += a * (k - self.k_rho)
        self.k_ld += a * (kl - self.k_ld)
        self.updates += 1


class LateralLogic:
    """Bank sign, two rules (spec 60-guidance.md, lateral channel):

    - corridor: reverse when the heading error to the target leaves a corridor whose
      half-width narrows linearly with speed (dpsi_hi at v_hi, dpsi_lo at v_lo). Positive
      bank turns right (heading up), so an error beyond +corridor wants a negative bank
      and beyond -corridor a positive one. It keeps the heading near the target while the
      vehicle has more lateral reach left than it needs;
    - final reversal, by prediction: xr_keep and xr_rev are the predicted crossranges at
      the deploy point if the sign is kept to the end, resp. reversed now (and kept). The
      current sign pushes the deploy point towards xr_keep - xr_rev; once even a reversal
      now leaves it on that side of the target line (or on it), waiting only adds miss: it
      reverses. After that reversal the corridor is off: the heading error near the end
      grows geometrically as the target comes close (its bearing swings), and a corridor
      reversal then would undo the null the prediction set up. Only the prediction may
      reverse again (if the deploy crossrange drifts past what a reversal can null).

    Both at most one reversal per rev_gap_s, and none in the last stretch: below v_norev, or
    when the predicted time to deploy is shorter than the reversal itself plus the time
    the corrector holds still before the deploy (tgo_freeze_s): the vehicle deploys with
    its bank settled."""

    def __init__(self, params: dict, v_hi_mps: float, v_lo_mps: float, sign0: float = 1.0):
        self.dpsi_hi = math.radians(params["npc.dpsi_hi_deg"])
        self.dpsi_lo = math.radians(params["npc.dpsi_lo_deg"])
        self.gap_s = params["npc.rev_gap_s"]
        self.v_norev = params["npc.v_norev_mps"]
        self.t_settle = params["npc.tgo_freeze_s"]
        self.v_hi, self.v_lo = v_hi_mps, v_lo_mps
        self.sign = 1.0 if sign0 >= 0 else -1.0
        self.t_last = -math.inf
        self.final = False            # the prediction has taken over (corridor off)
        self._xr_rev_prev = math.nan  # xr_rev of the last update
        self.reversals: list[float] = []
        self.rules: list[str] = []    # which rule made each reversal

    def corridor(self, V: float) -> float:
        f = (V - self.v_lo) / (self.v_hi - self.v_lo) if self.v_hi != self.v_lo else 1.0
        f = min(1.0, max(0.0, f))
        return self.dpsi_lo + (self.dpsi_hi - self.dpsi_lo) * f

    def update(self, t_s: float, V: float, dpsi: float, xr_keep: float = math.nan,
               xr_rev: float = math.nan, t_go_s: float = math.inf, t_rev_s: float = 0.0) -> bool:
        """New sign from the heading error dpsi [rad] at speed V, the predicted deploy
        crossranges [m] (NaN: no prediction), the predicted time to deploy and the time a
        reversal takes [s]; True when it reversed."""
        prev, self._xr_rev_prev = self._xr_rev_prev, xr_rev
        if V < self.v_norev or t_s - self.t_last < self.gap_s or t_go_s < t_rev_s + self.t_settle:
            return False
        push = xr_keep - xr_rev
        # the cycle nearest the crossing: now, if waiting one more cycle (xr_rev extrapolated
        # linearly from the last) would overshoot by more than reversing now falls short; the
        # crossrange a cycle is worth grows with speed (~1 km per second of delay at 1.8 km/s)
        nxt = 2.0 * xr_rev - prev
        if push != 0.0 and (push * xr_rev >= 0.0 or (push * nxt >= 0.0 and abs(nxt) > abs(xr_rev))):  # NaN: False
            rule = "final"
        elif not self.final and (dpsi > self.corridor(V) if self.sign > 0 else dpsi < -self.corridor(V)):
            rule = "corridor"
        else:
            return False
        self.final = self.final or rule == "final"
        self.rules.append(rule)
        self.sign = -self.sign
        self.t_last = t_s
        self.reversals.append(t_s)
        return True




class BankShaper:
    """The commanded bank turned into a reference phi_r, phidot_r, phiddot_r that respects
    the rate and acceleration limits: a second-order tracker (bang-bang towards the
    target, braking on sqrt(2 a |e|)), stepped once per control period. A reversal (sign
    change) goes the shorter way round (through lift up below 90 deg, lift down above);
    magnitude changes keep the branch. Same interface as guidance.BankProfile for the
    attitude chain: evaluate(t) and replan(t, rate, accel)."""

    def __init__(self, phi0_rad: float, rate_limit_radps: float, accel_limit_radps2: float, dt_s: float):
        self.rate_limit_radps = float(rate_limit_radps)
        self.accel_limit_radps2 = float(accel_limit_radps2)
        self.dt = float(dt_s)
        self.phi = float(phi0_rad)
        self.phid = 0.0
        self.phidd = 0.0
        self.target = self.phi
        self._sign = 1.0 if phi0_rad >= 0 else -1.0
        self._turn = 0.0            # target = command + turn (a multiple of 2 pi)
        self._t = None

    def command(self, bank_signed_rad: float) -> None:
        self._sign, self._turn = shaper_branch(self.phi, self._sign, self._turn, float(bank_signed_rad))
        self.target = bank_signed_rad + self._turn


    def _step(self) -> None:
        dt, a = self.dt, self.phidd
        self.phi += self.phid * dt + 0.5 * a * dt * dt
        self.phid += a * dt

    def evaluate(self, t_s: float) -> tuple[float, float, float]:
        if self._t is None:
            self._t = t_s
        n = int(round((t_s - self._t) / self.dt))
        for _ in range(max(0, n)):
            self._step()
        self._t += n * self.dt if n > 0 else 0.0
        self.phidd = shaper_accel(self.phi, self.phid, self.target, self.rate_limit_radps,
                                  self.accel_limit_radps2, self.dt)
        return self.phi, self.phid, self.phidd

    def transition_s(self, angle_rad: float) -> float:
        """Time [s] of a rest-to-rest turn through angle_rad within the rate and acceleration
        limits (trapezoidal rate, triangular when the rate limit is not reached)."""
        w, a, d = self.rate_limit_radps, self.accel_limit_radps2, abs(angle_rad)
        if w <= 0.0 or a <= 0.0:
            return math.inf
        return d / w + w / a if d >= w * w / a else 2.0 * math.sqrt(d / a)

    def reversal_s(self, mag_rad: float) -> float:
        """Time [s] of a reversal at bank magnitude mag_rad (the shorter way: through 0 below
        90 deg, through 180 above)."""
        return self.transition_s(2.0 * min(abs(mag_rad), math.pi - abs(mag_rad)))

    def replan(self, t_now: float, rate_limit_radps: float, accel_limit_radps2: float) -> bool:
        changed = (rate_limit_radps, accel_limit_radps2) != (self.rate_limit_radps, self.accel_limit_radps2)
        self.rate_limit_radps, self.accel_limit_radps2 = float(rate_limit_radps), float(accel_limit_radps2)
        return changed


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
    return c


def deploy_energy(scenario: Scenario, h_deploy_m: float) -> float:
    """e_f = mu/r - V^2/2 at the deploy condition, taken at altitude h_deploy_m."""
    pl = scenario.planet
    V = scenario.end_speed_mps if scenario.end_speed_mps is not None else \
        scenario.end_mach * atmosphere.speed_of_sound(h_deploy_m)
    return pl.mu_m3ps2 / (pl.radius_m + h_deploy_m) - 0.5 * V * V


class EntryGuidance:
    """Guidance mode ``npc``: one predictor-corrector cycle per call of ``cycle`` (the slow
    rate group), the bank command applied every control period by ``steer`` (density
    estimate, path limits, reversal sign, then the shaper).

    The correction runs on a worker thread (the predictor releases the GIL) and its
    answer is due ``apply_delay_s`` after the cycle's release. Lockstep and batch
    (``realtime`` False) wait for it at that moment if it is not there yet, so every run
    applies the same answer at the same step: deterministic, and the control ticks in
    between run while it computes. In real time the control loop never waits: an answer
    not there when due is an overrun (event; the previous command stays until it
    arrives), and a cycle released while the previous one still computes is skipped."""

    STATS = 4096
    FLOOR_STEP = math.radians(10.0)    # the floor search's march down from the range solution
    FLOOR_RES = math.radians(0.5)      # ... and its bisection's resolution

    def __init__(self, scenario: Scenario, params: dict, events: EventLog, dt_control_s: float,
                 realtime: bool = False, apply_delay_s: float = 0.5):
        if scenario.target_lat_rad is None:
            raise ValueError(f"{scenario.file}: target: guidance mode \"npc\" needs a [target]")
        # its own copy of the parameters: a ground set reaches it between corrections
        # (set_param, applied by the next cycle), never while the worker predicts
        self.scenario, self.params, self.events = scenario, dict(params), events
        self._pending: dict[str, float] = {}
        veh, pl = scenario.vehicle, scenario.planet
        self.c = predictor_constants(scenario, params)
        self.mu, self.R, self.omega = pl.mu_m3ps2, pl.radius_m, pl.omega_radps
        self.H = pl.scale_height_m
        self.ef = deploy_energy(scenario, params["npc.h_deploy_m"])
        self.bank_f = math.radians(params["npc.bank_final_deg"])
        self.bank_lo = math.radians(params["npc.bank_min_deg"])
        self.bank_hi = math.radians(params["npc.bank_max_deg"])
        self.p_lo, self.p_hi = profile_span(self.bank_lo, self.bank_hi, self.bank_f)
        self.target_u = unit_from_latlon(scenario.target_lat_rad, scenario.target_lon_rad)
        self.n_lim, self.q_lim = self.c[C_NLIM], self.c[C_QLIM]
        self.estimator = DensityEstimator(params, veh.S_ref_m2, veh.mass_kg, veh.aero.C_L, veh.aero.C_D)
        bank0 = scenario.bank_schedule[0][1]
        v_f = scenario.end_speed_mps or scenario.end_mach * atmosphere.speed_of_sound(params["npc.h_deploy_m"])
        self.lateral = LateralLogic(params, scenario.speed_rel_mps, v_f, sign0=bank0)
        self.shaper = BankShaper(bank0, scenario.bank_rate_limit_radps, scenario.bank_accel_limit_radps2,
                                 dt_control_s)
        self.dt_control_s = dt_control_s
        self.bank0 = abs(bank0)          # the range solution's parameter p (bank_profile: phi_0 within
                                         # the bounds): the next cycle's warm start
        self._p_e0 = math.nan            # energy at which bank0's profile starts
        self.bank0_cmd = abs(bank0)      # phi_0 commanded: the range solution, or the deploy-altitude floor's
        self._line = (math.nan, abs(bank0), abs(bank0))   # the answer's profile flown: (e0, phi_0 of the
                                         # line, phi_f), clipped to the phi_0 bounds as predicted
        self.floor_cycles = 0            # cycles whose answer traded range for the deploy-altitude floor
        self.held_cycles = 0             # cycles whose range solution holds a phi_0 bound (bank_profile)
        self.bank_cmd = abs(bank0)       # magnitude commanded now (after the path limits)
        self.miss_m = math.nan           # predicted range miss z of the last solution [m]
        self.range_to_go_m = math.nan
        self.pred_impact = np.full(2, math.nan)   # predicted deploy point (lat, lon) [rad]
        self.pred_h_m = math.nan
        self.t_go_s = math.inf           # predicted time to deploy (last solution, from its state)
        self._t_answer = math.nan        # release time of the last answer applied (its state's time)
        self.xr_keep_m = math.nan        # predicted deploy crossrange, sign kept [m, + left]
        self.xr_rev_m = math.nan         # ... reversed at the next cycle
        self._t_cycle = math.nan         # release time of the last cycle
        self.released = 0                # corrections handed to the worker
        self.cycles = 0                  # ... whose answers were applied
        self.no_root = 0
        self.overruns = 0
        self.faults = 0                  # corrections that raised (command kept)
        self.calls = np.zeros(self.STATS, np.int32)
        self.compute_ns = np.zeros(self.STATS, np.int64)
        self.k_rho_hist = np.zeros(self.STATS)
        self.t_hist = np.zeros(self.STATS)
        self.bank0_hist = np.zeros(self.STATS)
        self.miss_hist = np.zeros(self.STATS)
        self._x = np.zeros(6)
        self._shp = None
        self._out = np.zeros(N_O)
        self._frozen = False
        self.realtime = realtime
        self.apply_delay_s = apply_delay_s
        self._due_t = math.inf          # when the running correction's answer is due
        self._late = False
        self._result = None
        self._busy = False
        self._lock = threading.Lock()
        self._go = threading.Event()
        self._done = threading.Event()
        self._job = None
        self._correct = self.solve      # the worker's job (tests wrap it to inject delays)
        self._stop = False
        self._warm_up()
        self._thread = threading.Thread(target=self._worker, name="npc-guidance", daemon=True)
        self._thread.start()

    def _warm_up(self) -> None:
        """Compile (or load from numba's cache) every kernel with the argument types flight
        uses, here at construction: a first compile inside the first guidance cycle takes
        tens of seconds on a loaded machine (lockstep would wait that long; the plant gives
        up on a silent FSW after 10 s)."""
        c = self.c.copy()
        c[C_T_MAX] = 0.0                 # the initial derivative only
        x = np.array([self.R + 1e5, 0.0, 0.0, 0.0, 1e3, 0.0])
        predict(x, c, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, np.zeros(N_O), 0.0)
        predict_shaped(x, c, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, np.zeros(N_O), np.array([0.0, 0.0, 1.0, 0.0, 0.1, 0.01, 0.02, 1.0]),
                       1.0)
        path_limited_bank(1.0, 1e4, -1.0, 1.0, 1.0, 1.0, 1.0, self.H, 1.0, 0.0)
        shaper_accel(0.0, 0.0, 1.0, 1.0, 1.0, 0.02)
        shaper_branch(0.0, 1.0, 0.0, 1.0)

    # ------------------------------------------------------------------ prediction
    def _z(self, x, e0, s_togo, sign, t_switch=0.0):
        out = self._out

        def z(p):
            b0, bf = bank_profile(p, self.bank_lo, self.bank_hi, self.bank_f)
            self._predict(x, b0, bf, e0, sign, out, t_switch)
            if out[O_FLAG] == SKIPPED or out[O_FLAG] == TIMEOUT:
                # out of the atmosphere: far long. Its range so far says little, so the miss
                # is made 1000 km plus a slope towards more bank: the corrector then walks
                # out of the skip region instead of stalling on a flat function
                return 1e6 + (self.p_hi - p) * 1e6
            return central_angle(x[:3], out[:3]) * self.R - s_togo
        return z

    def _predict(self, x, b0, bf, e0, sign, out, t_switch=0.0):
        """The corrector's prediction: from the reference shaper's state when one is given
        (the transition in progress flown within the attitude chain's limits; a reversal to
        ``sign`` commanded at t_switch > 0), else the law from the start."""
        if self._shp is None:
            predict(x, self.c, b0, bf, e0, self.ef, sign, self.params["npc.dt_pred_s"], out, 0.0)
        else:
            predict_shaped(x, self.c, b0, bf, e0, self.ef, sign, self.params["npc.dt_pred_s"], out, self._shp,
                           float(t_switch))

    def _floor_bank(self, x, e0, s_togo, sign, h_floor, b_hi, h_hi):
        """(phi_0, predictions): the largest phi_0 below b_hi (whose prediction deploys below
        h_floor) whose predicted deploy altitude reaches h_floor, with the floor mode's
        profile (phi_0 held to the end when below phi_f). The deploy altitude is not monotonic
        in phi_0 (a steeper dive also slows the vehicle higher up), so no secant: steps of
        FLOOR_STEP down to the first phi_0 that reaches the floor, then bisection between it
        and the last that did not (the crossing nearest the range solution, least range
        given up). A phi_0 that skips out or whose predicted miss exceeds
        npc.floor_miss_max_m is refused, and so is everything below it (more lift up flies
        further); without a crossing above the refused, the phi_0 of the highest deploy seen,
        and NaN when no phi_0 tried deploys higher than the range solution (then the range
        solution stays: the floor's profile from b_hi is another flight, not a trade — a
        range solution beyond the phi_0 bound, flown as the floor's line from the bound,
        was predicted 61-104 km long for three cycles of a dispersed run). The miss bound
        keeps the trade from running away: flown long, the next range solution needs more
        lift down, which deploys lower still."""
        out = self._out
        tol, n_max = self.params["npc.tol_m"], int(self.params["npc.max_iter"])
        miss_max = self.params["npc.floor_miss_max_m"]
        b_bad, b_ok, b_lim, n = b_hi, math.nan, math.nan, 0
        best_b, best_h = b_hi, h_hi
        while n < n_max:
            if not math.isnan(b_ok):
                b = 0.5 * (b_ok + b_bad)
            elif not math.isnan(b_lim):
                b = 0.5 * (b_lim + b_bad)
            else:
                b = max(self.bank_lo, b_bad - self.FLOOR_STEP)
            self._predict(x, b, min(self.bank_f, b), e0, sign, out)
            n += 1
            if out[O_FLAG] == SKIPPED or out[O_FLAG] == TIMEOUT or \
                    abs(central_angle(x[:3], out[:3]) * self.R - s_togo) > miss_max:
                b_lim = b
            elif out[O_H] >= h_floor:
                b_ok = b
                if out[O_H] - h_floor <= tol:
                    break
            else:
                b_bad = b
                if out[O_H] > best_h:
                    best_b, best_h = b, out[O_H]
            if not math.isnan(b_ok):
                if b_bad - b_ok < self.FLOOR_RES:
                    break
            elif (not math.isnan(b_lim) and b_bad - b_lim < self.FLOOR_RES) or b <= self.bank_lo:
                break
        return (b_ok if not math.isnan(b_ok) else best_b if best_h > h_hi else math.nan), n

    def solve(self, x: np.ndarray, sign: float, k_rho: float, k_ld: float, t_flip: float = math.nan,
              shp: np.ndarray | None = None) -> dict:
        """One correction from the planet-fixed state x: phi_0 and the predicted deploy. With
        t_flip given, one more prediction: the same phi_0 with a reversal taking effect
        t_flip from now, for the lateral logic's final reversal (deploy crossranges with the
        sign kept and reversed). shp: the reference shaper's state at x (shaped_transition),
        None: the bank follows the law at once."""
        t0 = time.perf_counter_ns()
        self._shp = shp
        self.c[C_KRHO], self.c[C_KLD] = k_rho, k_ld
        r = math.sqrt(float(x[:3] @ x[:3]))
        e0 = self.mu / r - 0.5 * float(x[3:] @ x[3:])
        s_togo = central_angle(x[:3], self.target_u) * self.R
        dt = self.params["npc.dt_pred_s"]
        p_warm = self.bank0
        if math.isfinite(self._p_e0) and self.ef != self._p_e0:
            p_warm = profile_at(p_warm, self.bank_lo, self.bank_hi, self.bank_f,
                                (e0 - self._p_e0) / (self.ef - self._p_e0))
        tol, n_max = self.params["npc.tol_m"], int(self.params["npc.max_iter"])
        p, zb, n, ok = solve_bank(self._z(x, e0, s_togo, sign), self.p_lo, self.p_hi, p_warm, tol, n_max)
        turn = math.nan
        alt = None
        if shp is not None and not abs(zb) <= self.params["npc.floor_miss_max_m"]:
            alt = reversal_other_way(shp, sign)
        if alt is not None:
            # a reversal in progress whose way round costs more range than the guidance
            # trades anywhere (npc.floor_miss_max_m): the other way (the reference braked and
            # turned back, as the shaper would fly it) if that one's answer misses by less.
            # Not for less: the lateral decision timed the reversal for the way it began, and
            # turning round delays it (dispersed runs: 2-4 km across for < 1 km along)
            self._shp = alt
            pa, za, na, oka = solve_bank(self._z(x, e0, s_togo, sign), self.p_lo, self.p_hi, p_warm, tol, n_max)
            n += na
            if abs(za) < abs(zb) - tol:
                p, zb, ok, turn = pa, za, oka, float(alt[3])
            else:
                self._shp = shp
        b_range = p
        b0, bf = bank_profile(p, self.bank_lo, self.bank_hi, self.bank_f)
        held = not self.bank_lo <= p <= self.bank_hi
        # the prediction of the answer (the root-finder's last call may have been another)
        self._predict(x, b0, bf, e0, sign, self._out)
        floor = False
        h_floor = self.params["npc.h_floor_m"]
        if h_floor > 0.0 and self._out[O_FLAG] != SKIPPED and self._out[O_H] < h_floor and p > self.bank_lo:
            # the range solution deploys too low: trade range for altitude (more lift up, so
            # long). In this mode the profile holds phi_0 to the end when phi_0 < phi_f (the
            # fixed phi_f would otherwise take the lift-up away just where it counts), and
            # phi_0 is the largest bank whose predicted deploy altitude reaches the floor
            b_fl, nh = self._floor_bank(x, e0, s_togo, sign, h_floor, min(p, self.bank_hi), self._out[O_H])
            n += nh
            if math.isnan(b_fl):        # no trade deploys higher: the range solution's prediction again
                self._predict(x, b0, bf, e0, sign, self._out)
            else:
                floor = True
                b0, bf = b_fl, min(self.bank_f, b_fl)
                self._predict(x, b0, bf, e0, sign, self._out)
                zb = (central_angle(x[:3], self._out[:3]) * self.R - s_togo if self._out[O_FLAG] == REACHED
                      else math.nan)
                ok = False
        rf = self._out[:3].copy()
        # phi_0 commanded: the profile's bank now (the line clipped to the bounds, as predicted)
        res = {"bank0": min(self.bank_hi, max(self.bank_lo, b0)), "b_range": b_range, "e0": e0, "b_line": b0,
               "bank_f": bf, "floor": floor, "held": held and not floor, "miss_m": zb, "calls": n + 1, "turn": turn,
               "ok": ok or floor, "s_togo": s_togo,
               "lat": math.asin(rf[2] / math.sqrt(float(rf @ rf))), "lon": math.atan2(rf[1], rf[0]),
               "h_f": float(self._out[O_H]), "t_go": float(self._out[O_T]), "xr": math.nan, "xr_rev": math.nan}
        if self._out[O_FLAG] == REACHED and math.isfinite(t_flip):
            # the lateral decision's pair, "keep" and "reverse at t_flip", both flown with the
            # bank switching at once (the reversal at its shaped transition's mid-point) and
            # this phi_0. Flying the pair through the shaper instead (and re-solving phi_0 for
            # the reversed one) made the final rule fire at the first reversal, ~90 s, where the
            # load limit's lift up sent the swing through lift up: lofted 150-200 km long in
            # guided-case1/3/4 and 1 dispersed run of 24
            predict(x, self.c, b0, bf, e0, self.ef, sign, dt, self._out, 0.0)
            res["calls"] += 1
            if self._out[O_FLAG] == REACHED:
                res["xr"] = crossrange(x[:3], self.target_u, self._out[:3], self.R)
                predict(x, self.c, b0, bf, e0, self.ef, -sign, dt, self._out, t_flip)
                res["calls"] += 1
                if self._out[O_FLAG] == REACHED:
                    res["xr_rev"] = crossrange(x[:3], self.target_u, self._out[:3], self.R)
        res["ns"] = time.perf_counter_ns() - t0
        return res

    def _worker(self) -> None:
        rt.run_below_loop()
        while True:
            self._go.wait()
            self._go.clear()
            if self._stop:
                return
            x, sign, k_rho, k_ld, t_flip, shp, t_s = self._job
            try:
                res = self._correct(x, sign, k_rho, k_ld, t_flip, shp)
            except Exception as e:      # noqa: BLE001 -- a fault in the correction must not stall the FSW
                res = {"error": f"{type(e).__name__}: {e}"}
            res["t_s"], res["sign"] = t_s, sign
            with self._lock:
                self._result = res
                self._busy = False
            self._done.set()

    def close(self) -> None:
        self._stop = True
        self._go.set()
        self._thread.join(timeout=5.0)

    # ------------------------------------------------------------------ rate groups
    def cycle(self, nav, t_s: float) -> None:
        """The guidance cycle (slow rate group): lateral decision, then the correction."""
        if self._pending:
            self._take_params(t_s)
        x = planet_fixed(nav.r_N, nav.v_N, t_s, self.omega)
        dpsi, ang = heading_error(x, self.target_u)
        self.range_to_go_m = ang * self.R
        V = nav.V_rel_mps
        # the crossranges were predicted from the last cycle's state, the reversal in them
        # commanded one cycle later (now); the time to deploy is aged from the answer's own
        # release (a late answer's is older than the last cycle)
        t_go = self.t_go_s - (t_s - self._t_answer) if math.isfinite(self._t_answer) else math.inf
        if self.lateral.update(t_s, V, dpsi, self.xr_keep_m, self.xr_rev_m, t_go,
                               self.shaper.reversal_s(self.bank_cmd)):
            self.xr_keep_m = self.xr_rev_m = math.nan      # for the sign just left
            self.events.emit(t_s, Severity.INFO, "guidance", "bank_reversal",
                             f"BANK REVERSAL ({self.lateral.rules[-1].upper()}) DPSI {math.degrees(dpsi):+.1f} DEG")
        period = t_s - self._t_cycle if math.isfinite(self._t_cycle) else 1.0
        self._t_cycle = t_s
        if self._frozen:
            return
        with self._lock:
            busy = self._busy
            if not busy:
                self._busy = True
        if busy:        # real time only: lockstep has collected every answer by now
            self.overruns += 1
            self.events.emit(t_s, Severity.WARNING, "guidance", "guidance_overrun",
                             "GUIDANCE CYCLE SKIPPED: PREVIOUS STILL RUNNING", rate_limited=True)
            return
        self._due_t = t_s + self.apply_delay_s - 1e-9
        self._done.clear()
        sign = self.lateral.sign
        # a reversal decided at the next cycle, in effect laterally at its shaped transition's
        # mid-point (half-way the lateral lift has turned over)
        t_flip = period + 0.5 * self.shaper.reversal_s(self.bank_cmd)
        sh = self.shaper
        shp = np.array([sh.phi, sh.phid, sh._sign, sh._turn, sh.rate_limit_radps, sh.accel_limit_radps2, sh.dt,
                        self.bank_cmd])
        self._job = (x, sign, self.estimator.k_rho, self.estimator.k_ld, t_flip, shp, t_s)
        self.released += 1
        self._go.set()

    def _apply(self, res: dict) -> None:
        if "error" in res:              # the correction raised: the previous command stays
            self.faults += 1
            self.events.emit(res["t_s"], Severity.WARNING, "guidance", "guidance_fault",
                             f"GUIDANCE FAULT: {res['error']}"[:50], rate_limited=True)
            return
        i = self.cycles % self.STATS
        self.calls[i], self.compute_ns[i] = res["calls"], res["ns"]
        self.k_rho_hist[i], self.t_hist[i] = self.estimator.k_rho, res["t_s"]
        self.bank0_hist[i], self.miss_hist[i] = res["bank0"], res["miss_m"]
        self.cycles += 1
        self.bank0, self._p_e0 = res["b_range"], res["e0"]
        self.bank0_cmd = res["bank0"]
        self._line = (res["e0"], res["b_line"], res["bank_f"])
        if res["floor"]:
            if self.floor_cycles == 0:
                self.events.emit(res["t_s"], Severity.NOTICE, "guidance", "deploy_alt_floor",
                                 f"DEPLOY ALT FLOOR: RANGE TRADED {res['miss_m'] / 1e3:+.1f} KM"[:50])
            self.floor_cycles += 1
        self.held_cycles += bool(res["held"])
        self.miss_m = res["miss_m"]
        self.pred_impact[:] = (res["lat"], res["lon"])
        self.pred_h_m = res["h_f"]
        self.t_go_s, self._t_answer = res["t_go"], res["t_s"]
        sh = self.shaper
        if math.isfinite(res["turn"]) and res["sign"] == sh._sign and math.sin(sh.phi) * sh._sign < 0.0:
            # the reversal under way turned round (solve: no range solution the way it went)
            sh.target += res["turn"] - sh._turn
            sh._turn = res["turn"]
            self.events.emit(res["t_s"], Severity.INFO, "guidance", "reversal_way",
                             f"REVERSAL TURNED ROUND: MISS {res['miss_m'] / 1e3:+.1f} KM"[:50])
        if res["sign"] == self.lateral.sign:        # not for a sign left since the job started
            self.xr_keep_m, self.xr_rev_m = res["xr"], res["xr_rev"]
        if not res["ok"]:
            self.no_root += 1
            self.events.emit(res["t_s"], Severity.NOTICE, "guidance", "guidance_no_root",
                             f"NO RANGE SOLUTION: MISS {res['miss_m'] / 1e3:+.1f} KM", rate_limited=True)
        if res["t_go"] < self.params["npc.tgo_freeze_s"]:
            self._frozen = True         # too close to the deploy for the range to respond

    def steer(self, nav) -> None:
        """Every control period: the density estimate, the last answer's bank profile at today's
        energy, the path limits, then the shaper."""
        if nav.t_s >= self._due_t:
            if not self.realtime:
                self._done.wait()
            if self._result is None and not self._late:
                self._late = True
                self.overruns += 1
                self.events.emit(nav.t_s, Severity.WARNING, "guidance", "guidance_overrun",
                                 "GUIDANCE CYCLE OVERRUN: COMMAND KEPT", rate_limited=True)
            if self._result is not None:
                with self._lock:
                    res, self._result = self._result, None
                self._due_t = math.inf
                self._late = False
                self._apply(res)
        self.estimator.update(self.dt_control_s, nav.accel_B, nav.C_BN, nav.vrel_N, nav.rho_kgpm3)
        V = nav.V_rel_mps
        r = nav.r_N
        rn = math.sqrt(float(r @ r))
        hdot = float(nav.vrel_N @ r) / rn
        a = nav.accel_B
        n_g = math.sqrt(float(a @ a)) / self.c[C_G0]
        q = SUTTON_GRAVES_MARS * math.sqrt(max(nav.rho_kgpm3, 0.0) * self.estimator.k_rho / self.c[C_RN]) * V ** 3
        # the answer's profile at today's energy (the bank its prediction flew), not its start held
        # for the cycle: the next answer, re-anchored, is then the same profile (profile_at)
        e0, b_line, b_f = self._line
        mag = self.bank0_cmd
        if math.isfinite(e0) and self.ef != e0:
            e = self.mu / rn - 0.5 * V * V
            frac = min(1.0, max(0.0, (e - e0) / (self.ef - e0)))
            mag = min(self.bank_hi, max(self.bank_lo, b_line + (b_f - b_line) * frac))
        self.bank_cmd = path_limited_bank(mag, nav.h_m, hdot, n_g, q, self.n_lim, self.q_lim, self.H,
                                          self.params["npc.hdot_tau_s"], self.params["npc.hdot_gain"])
        self.shaper.command(self.lateral.sign * self.bank_cmd)

    # ------------------------------------------------------------------ parameters
    def set_param(self, name: str, value: float) -> None:
        """Owner's hook (fsw/params.py): a new npc.* value, bounds already checked, applied by
        the next guidance cycle once no correction is running. ValueError (nothing changed)
        when it would leave the phi_0 bounds empty."""
        lo = value if name == "npc.bank_min_deg" else self._pending.get("npc.bank_min_deg", self.params["npc.bank_min_deg"])
        hi = value if name == "npc.bank_max_deg" else self._pending.get("npc.bank_max_deg", self.params["npc.bank_max_deg"])
        if not lo < hi:
            raise ValueError(f"{name}: needs bank_min < bank_max ({lo:g}, {hi:g})")
        self._pending[name] = float(value)

    def _take_params(self, t_s: float) -> None:
        """Apply the pending sets where the construction put each value (the worker is idle:
        lockstep has its answer; in real time a cycle with a correction still running waits)."""
        with self._lock:
            if self._busy:
                return
        p, scn = self.params, self.scenario
        p.update(self._pending)
        names, self._pending = set(self._pending), {}
        self.bank_f = math.radians(p["npc.bank_final_deg"])
        self.bank_lo, self.bank_hi = math.radians(p["npc.bank_min_deg"]), math.radians(p["npc.bank_max_deg"])
        self.p_lo, self.p_hi = profile_span(self.bank_lo, self.bank_hi, self.bank_f)
        self.bank0 = min(self.p_hi, max(self.p_lo, self.bank0))      # the warm start within them
        if "npc.h_deploy_m" in names:
            self.ef = deploy_energy(scn, p["npc.h_deploy_m"])
            self.lateral.v_lo = scn.end_speed_mps or scn.end_mach * atmosphere.speed_of_sound(p["npc.h_deploy_m"])
        c = predictor_constants(scn, p)                 # path limits and their feedback
        c[C_KRHO], c[C_KLD] = self.c[C_KRHO], self.c[C_KLD]
        self.c[:] = c
        self.n_lim, self.q_lim = self.c[C_NLIM], self.c[C_QLIM]
        est = self.estimator
        est.tau_s, est.k_min, est.k_max, est.drag_min = p["npc.k_tau_s"], p["npc.k_min"], p["npc.k_max"], \
            p["npc.k_drag_min"]
        lat = self.lateral
        lat.dpsi_hi, lat.dpsi_lo = math.radians(p["npc.dpsi_hi_deg"]), math.radians(p["npc.dpsi_lo_deg"])
        lat.gap_s, lat.v_norev, lat.t_settle = p["npc.rev_gap_s"], p["npc.v_norev_mps"], p["npc.tgo_freeze_s"]
        for n in sorted(names):
            self.events.emit(t_s, Severity.INFO, "guidance", "npc_param", f"GUIDANCE {n.upper()} {p[n]:g}"[:50])

    def stats(self) -> dict:
        n = min(self.cycles, self.STATS)
        us = self.compute_ns[:n] / 1e3
        calls = self.calls[:n]

        def pct(a, q):
            return float(np.percentile(a, q)) if n else None
        return {"released": self.released, "cycles": self.cycles, "compute_p50_us": pct(us, 50), "compute_p99_us": pct(us, 99),
                "compute_max_us": float(us.max()) if n else None,
                "predictions_per_cycle_mean": float(calls.mean()) if n else None,
                "predictions_per_cycle_max": int(calls.max()) if n else None,
                "no_root": self.no_root, "floor_cycles": self.floor_cycles, "held_cycles": self.held_cycles,
                "overruns": self.overruns, "faults": self.faults,
                "reversal_times_s": list(self.lateral.reversals), "reversal_rules": list(self.lateral.rules),
                "k_rho_final": self.estimator.k_rho, "k_ld_final": self.estimator.k_ld,
                "bank0_final_deg": math.degrees(self.bank0_cmd)}
