"""Guidance: the smoothed bank-angle reference and the reference attitude (docs/fsw/index.md,
"Guidance: the reference bank-angle trajectory").

BankProfile turns the scenario's bank steps into a twice-differentiable reference that
respects the rate and acceleration limits. Guidance turns phi_r into the reference
attitude C_RN = R2(alpha_trim) R1(phi_r) C_WN (beta_r = 0) with its MRP sigma_RN and the
derivatives SAMI needs, including the wind frame's own angular velocity omega_WN.
"""
from __future__ import annotations

import bisect
import math
from typing import Sequence

import numpy as np
from numba import njit

from common.model import load_planet
from common.mrp import from_dcm_into, nearest_set_into, sigma_derivatives

# Minimum-jerk (quintic) blend s(x) = 10x^3 - 15x^4 + 6x^5 on x in [0, 1]:
# max s' = 15/8 at x = 1/2; max |s''| = 10/sqrt(3) at x = 1/2 -+ sqrt(3)/6.
_S1_MAX = 15.0 / 8.0
_S2_MAX = 10.0 / math.sqrt(3.0)
_SEG_W = 10          # columns of BankProfile.seg_array


def _quintic(phi0: float, v0: float, a0: float, phi1: float, T: float) -> tuple:
    """Coefficients c0..c5 in x = (t - t0)/T of the minimum-jerk quintic from (phi0, v0, a0)
    to phi1 at rest (rate and acceleration zero at x = 1)."""
    d, v, a = phi1 - phi0, v0 * T, a0 * T * T
    return (phi0, v, 0.5 * a, 10.0 * d - 6.0 * v - 1.5 * a, -15.0 * d + 8.0 * v + 1.5 * a,
            6.0 * d - 3.0 * v - 0.5 * a)


def _eval_quintic(c: tuple, T: float, x: float) -> tuple[float, float, float]:
    c0, c1, c2, c3, c4, c5 = c
    phi = c0 + x * (c1 + x * (c2 + x * (c3 + x * (c4 + x * c5))))
    d1 = (c1 + x * (2.0 * c2 + x * (3.0 * c3 + x * (4.0 * c4 + x * 5.0 * c5)))) / T
    d2 = (2.0 * c2 + x * (6.0 * c3 + x * (12.0 * c4 + x * 20.0 * c5))) / (T * T)
    return phi, d1, d2


def _bang_bang(phi0: float, v0: float, phi1: float, rate_limit: float, accel_limit: float) -> list:
    """Pieces (T, phi, phidot, phiddot) of constant acceleration: the time-optimal path from the
    moving state (phi0, v0) to phi1 at rest with |phiddot| = accel_limit, the rate held within
    rate_limit (a state already faster first brakes to it). Accelerate (or brake) to the peak
    rate, cruise if the rate limit caps it, brake to rest on phi1; when the state cannot stop
    before phi1 (v0^2 / 2A beyond it) the path passes phi1 by exactly that much and comes back.
    The rate is continuous; the acceleration steps between the pieces (and from the state's
    own at the start)."""
    A, R = accel_limit, rate_limit
    d = phi1 - phi0
    e = d - v0 * abs(v0) / (2.0 * A)          # distance left after braking at once
    if e == 0.0 and v0 == 0.0:
        return []
    sg = math.copysign(1.0, e) if e != 0.0 else math.copysign(1.0, v0)
    # peak rate of accelerate-then-brake (accel sg*A, then -sg*A): 2 vp^2 - v0^2 = 2 sg A d
    vp = sg * math.sqrt(max(sg * A * d + 0.5 * v0 * v0, 0.0))
    cruise = abs(vp) > R
    if cruise:
        vp = sg * R
    pieces = []
    phi, v = phi0, v0
    if vp != v0:
        a1 = math.copysign(A, vp - v0)
        T1 = abs(vp - v0) / A
        pieces.append((T1, phi, v, a1))
        phi, v = phi + v * T1 + 0.5 * a1 * T1 * T1, vp
    T3 = abs(vp) / A
    if cruise:
        Tc = ((phi1 - phi) - 0.5 * vp * T3) / vp   # >= 0 by the choice of sg
        if Tc > 0.0:
            pieces.append((Tc, phi, vp, 0.0))
            phi = phi + vp * Tc
    if T3 > 0.0:
        pieces.append((T3, phi, vp, -math.copysign(A, vp)))
    return pieces


class BankProfile:
    """Bank-angle reference from a schedule of (t_s, bank_rad) steps.

    The reference starts at schedule[0]'s bank. Each later step becomes a minimum-jerk
    quintic transition from the previous target to the new one, with duration
    T = max(15/8 |d| / rate_limit, sqrt(10/sqrt(3) |d| / accel_limit)), so the peak rate
    and the peak acceleration are both within their limits; each transition starts and
    ends at rest (zero rate and acceleration), so the reference is C2 everywhere.

    Steps are taken literally (no wrapping): 85 deg -> -85 deg reverses through 0 (lift up),
    as entry guidance intends.

    A step that arrives while a transition is still running is queued: its transition
    starts when the running one ends (so the limits hold exactly and the reference stays
    C2; the price is a lag, reported by ``lag_s``).

    ``replan`` gives new limits to the transitions not yet started and to the one running: that
    one continues from its current bank and rate to the same target by the time-optimal path
    under the new limits (``_bang_bang``), so a transition begun before an actuator failure is
    not flown on limits the vehicle no longer has. Such a continuation is C1: its acceleration
    steps at the re-plan and between its pieces. (No single quintic can do this: from a fast
    state with a much lower acceleration limit, every quintic to rest at the target either
    overshoots far beyond it or breaks the limits.)
    """

    def __init__(self, schedule: Sequence[tuple[float, float]], rate_limit_radps: float,
                 accel_limit_radps2: float):
        for name, v in (("rate_limit_radps", rate_limit_radps), ("accel_limit_radps2", accel_limit_radps2)):
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"BankProfile.{name}: must be a finite number > 0, got {v!r}")
        if schedule is None or len(schedule) == 0:
            raise ValueError("BankProfile.schedule: must be a non-empty list of (t_s, bank_rad)")
        steps = []
        for i, pair in enumerate(schedule):
            try:
                t, b = float(pair[0]), float(pair[1])
            except (TypeError, ValueError, IndexError):
                raise ValueError(f"BankProfile.schedule: entry {i + 1} must be (t_s, bank_rad), got {pair!r}") from None
            if not (math.isfinite(t) and math.isfinite(b)):
                raise ValueError(f"BankProfile.schedule: entry {i + 1} must be finite, got {pair!r}")
            if abs(b) > math.pi + 1e-12:
                raise ValueError(f"BankProfile.schedule: entry {i + 1}: bank {b:g} rad outside [-pi, pi]")
            if steps and t <= steps[-1][0]:
                raise ValueError(f"BankProfile.schedule: entry {i + 1}: times must increase")
            steps.append((t, b))
        if steps[0][0] != 0.0:
            raise ValueError(f"BankProfile.schedule: the first step must be at t = 0, got {steps[0][0]:g}")
        self.schedule = tuple(steps)
        self.rate_limit_radps = float(rate_limit_radps)
        self.accel_limit_radps2 = float(accel_limit_radps2)
        self.phi0_rad = steps[0][1]
        # segments: (t_start, duration, quintic coefficients in x = (t - t_start)/duration,
        # phi_from, phi_to, transition index, ends at rest on phi_to); a transition is one
        # segment, or several when continued after a re-plan (only the last ends at rest)
        self._starts, self._segs = [], []
        self.lag_s = 0.0   # largest delay of a transition start behind its step time
        self._plan(0.0)

    def _plan(self, t_keep: float, continue_running: bool = False) -> None:
        """(Re)build the transitions: those that started before ``t_keep`` are kept as they
        are (with ``continue_running``, the one still running at ``t_keep`` gets a continuation
        from its state at ``t_keep``); every later step gets a transition shaped by the current
        limits. Transition j always belongs to the j-th step whose target differs from the
        previous target."""
        kept = [seg for seg in self._segs if seg[0] < t_keep]
        lag = self.lag_s if kept else 0.0
        if continue_running and kept and (kept[-1][0] + kept[-1][1] > t_keep or not kept[-1][6]):
            t0, T, c, _, b, j, _ = kept[-1]
            phi, v, _ = _eval_quintic(c, T, (t_keep - t0) / T)
            pieces = _bang_bang(phi, v, b, self.rate_limit_radps, self.accel_limit_radps2)
            if not pieces:        # exactly at rest on the target: hold it
                pieces = [(1e-3, b, 0.0, 0.0)]
            ts = t_keep
            for i, (Tp, p0, v0, a0) in enumerate(pieces):
                kept.append((ts, Tp, (p0, v0 * Tp, 0.5 * a0 * Tp * Tp, 0.0, 0.0, 0.0), phi, b, j,
                             i == len(pieces) - 1))
                ts += Tp
        starts, segs = [seg[0] for seg in kept], list(kept)
        t_free = kept[-1][0] + kept[-1][1] if kept else 0.0
        n_kept = kept[-1][5] + 1 if kept else 0
        phi, j = self.schedule[0][1], 0
        for t, b in self.schedule[1:]:
            d = b - phi
            if d == 0.0:
                continue
            if j < n_kept:            # already flown or flying: keep it
                j += 1
                phi = b
                continue
            T = max(_S1_MAX * abs(d) / self.rate_limit_radps, math.sqrt(_S2_MAX * abs(d) / self.accel_limit_radps2))
            t0 = max(t, t_free, t_keep if kept or t_keep > 0 else 0.0)
            lag = max(lag, t0 - t)
            starts.append(t0)
            segs.append((t0, T, _quintic(phi, 0.0, 0.0, b, T), phi, b, j, True))
            t_free, phi = t0 + T, b
            j += 1
        self._starts = starts
        self._segs = segs
        self.lag_s = lag
        # the same segments as one array for the compiled cycle (``profile_eval``): t_start,
        # duration, c0..c5, phi_to, 1.0 when it ends at rest
        arr = np.zeros((len(segs), _SEG_W))
        for i, (t0, T, c, _, b, _, rest) in enumerate(segs):
            arr[i, 0], arr[i, 1], arr[i, 8], arr[i, 9] = t0, T, b, 1.0 if rest else 0.0
            arr[i, 2:8] = c
        self.seg_array = arr

    def replan(self, t_now: float, rate_limit_radps: float, accel_limit_radps2: float) -> bool:
        """New limits from ``t_now``: for every transition that has not started and for the one
        running, continued from its state at ``t_now`` (the reference stays C2). True if
        anything changed."""
        for name, v in (("rate_limit_radps", rate_limit_radps), ("accel_limit_radps2", accel_limit_radps2)):
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"BankProfile.replan: {name} must be a finite number > 0, got {v!r}")
        if (rate_limit_radps, accel_limit_radps2) == (self.rate_limit_radps, self.accel_limit_radps2):
            return False
        self.rate_limit_radps, self.accel_limit_radps2 = float(rate_limit_radps), float(accel_limit_radps2)
        self._plan(t_now, continue_running=True)
        return True

    def transitions(self) -> list[tuple[float, float, float, float]]:
        """(t_start, duration, phi_from, phi_to) of each transition (a continuation after a
        re-plan is listed as its own entry, from the bank it continued from)."""
        out, first = [], None
        for seg in self._segs:
            first = first or seg
            if seg[6]:
                out.append((first[0], seg[0] + seg[1] - first[0], first[3], seg[4]))
                first = None
        return out

    def evaluate(self, t_s: float) -> tuple[float, float, float]:
        """(phi_r [rad], phidot_r [rad/s], phiddot_r [rad/s^2]) at time t_s."""
        i = bisect.bisect_right(self._starts, t_s) - 1
        if i < 0:
            return self.phi0_rad, 0.0, 0.0
        t0, T, c, _, b, _, rest = self._segs[i]
        x = (t_s - t0) / T
        if x >= 1.0 and rest:
            return b, 0.0, 0.0
        return _eval_quintic(c, T, x)


@njit(cache=True)
def profile_eval(segs, phi0, t_s):
    """BankProfile.evaluate on its ``seg_array`` (``phi0``: the schedule's first bank): the same
    bisection (bisect_right) and the same quintic arithmetic, compiled."""
    lo, hi = 0, segs.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if t_s < segs[mid, 0]:
            hi = mid
        else:
            lo = mid + 1
    i = lo - 1
    if i < 0:
        return phi0, 0.0, 0.0
    T = segs[i, 1]
    x = (t_s - segs[i, 0]) / T
    if x >= 1.0 and segs[i, 9] != 0.0:
        return segs[i, 8], 0.0, 0.0
    c0, c1, c2, c3, c4, c5 = segs[i, 2], segs[i, 3], segs[i, 4], segs[i, 5], segs[i, 6], segs[i, 7]
    phi = c0 + x * (c1 + x * (c2 + x * (c3 + x * (c4 + x * c5))))
    d1 = (c1 + x * (2.0 * c2 + x * (3.0 * c3 + x * (4.0 * c4 + x * 5.0 * c5)))) / T
    d2 = (2.0 * c2 + x * (6.0 * c3 + x * (12.0 * c4 + x * 20.0 * c5))) / (T * T)
    return phi, d1, d2


@njit(cache=True)
def wind_rate(r_N, v_N, vrel_N, C_WN, a_N, omega_planet, out_W):
    """Angular velocity of W relative to N, in W components [rad/s].

    W: w1 = v_rel/|v_rel|, w2 = (v_rel x r)/|.|, w3 = w1 x w2 (docs/plant.md). With
    d(v_rel)/dt = a - Omega x v (a = inertial acceleration, v = dr/dt) and h = v_rel x r:
    omega1 = hdot.w3/|h|, omega2 = -vrel_dot.w3/V, omega3 = vrel_dot.w2/V
    (from dw1/dt = omega x w1 and dw2/dt = omega x w2).
    """
    vd0 = a_N[0] + omega_planet * v_N[1]
    vd1 = a_N[1] - omega_planet * v_N[0]
    vd2 = a_N[2]
    V = math.sqrt(vrel_N[0] ** 2 + vrel_N[1] ** 2 + vrel_N[2] ** 2)
    h0 = vrel_N[1] * r_N[2] - vrel_N[2] * r_N[1]
    h1 = vrel_N[2] * r_N[0] - vrel_N[0] * r_N[2]
    h2 = vrel_N[0] * r_N[1] - vrel_N[1] * r_N[0]
    hn = math.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    if V < 1e-6 or hn < 1e-6:
        out_W[0] = 0.0
        out_W[1] = 0.0
        out_W[2] = 0.0
        return
    # hdot = vrel_dot x r + vrel x v
    hd0 = vd1 * r_N[2] - vd2 * r_N[1] + vrel_N[1] * v_N[2] - vrel_N[2] * v_N[1]
    hd1 = vd2 * r_N[0] - vd0 * r_N[2] + vrel_N[2] * v_N[0] - vrel_N[0] * v_N[2]
    hd2 = vd0 * r_N[1] - vd1 * r_N[0] + vrel_N[0] * v_N[1] - vrel_N[1] * v_N[0]
    out_W[0] = (hd0 * C_WN[2, 0] + hd1 * C_WN[2, 1] + hd2 * C_WN[2, 2]) / hn
    out_W[1] = -(vd0 * C_WN[2, 0] + vd1 * C_WN[2, 1] + vd2 * C_WN[2, 2]) / V
    out_W[2] = (vd0 * C_WN[1, 0] + vd1 * C_WN[1, 1] + vd2 * C_WN[1, 2]) / V


@njit(cache=True)
def _guidance_kernel(phi, phid, phidd, alpha, beta, omega_planet, mu, r_N, v_N, vrel_N, C_WN, C_BN,
                     accel_B, sigma_BN, out):
    """out[0:3] sigma_RN, [3:6] sigma_r_dot, [6:9] sigma_r_ddot, [9:12] omega_RN_R,
    [12:15] domega_RN_R, [15:18] omega_WN_W."""
    # inertial acceleration = sensed (body -> N) + FSW gravity (point mass)
    rn = math.sqrt(r_N[0] ** 2 + r_N[1] ** 2 + r_N[2] ** 2)
    g = -mu / (rn * rn * rn) if rn > 0.0 else 0.0
    a_N = np.empty(3)
    for i in range(3):
        a_N[i] = C_BN[0, i] * accel_B[0] + C_BN[1, i] * accel_B[1] + C_BN[2, i] * accel_B[2] + g * r_N[i]
    wW = out[15:18]
    wind_rate(r_N, v_N, vrel_N, C_WN, a_N, omega_planet, wW)
    # C_RW = R2(alpha) R3(-beta) R1(phi) (common/frames.py)
    ca, sa = math.cos(alpha), math.sin(alpha)
    cb, sb = math.cos(beta), math.sin(beta)
    cp, sp = math.cos(phi), math.sin(phi)
    C_RW = np.empty((3, 3))
    C_RW[0, 0] = ca * cb
    C_RW[0, 1] = -ca * sb * cp + sa * sp
    C_RW[0, 2] = -ca * sb * sp - sa * cp
    C_RW[1, 0] = sb
    C_RW[1, 1] = cb * cp
    C_RW[1, 2] = cb * sp
    C_RW[2, 0] = sa * cb
    C_RW[2, 1] = -sa * sb * cp - ca * sp
    C_RW[2, 2] = -sa * sb * sp + ca * cp
    C_RN = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C_RN[i, j] = C_RW[i, 0] * C_WN[0, j] + C_RW[i, 1] * C_WN[1, j] + C_RW[i, 2] * C_WN[2, j]
    sr = out[0:3]
    from_dcm_into(C_RN, sr)
    nearest_set_into(sr, sigma_BN)      # eps = sigma - sigma_r never jumps
    # omega_RN = omega_WN + phidot w1; its N-derivative (omegadot_WN neglected) in W comps:
    # phiddot w1 + phidot (omega_WN x w1) = [phiddot, phidot wW3, -phidot wW2]
    w_W = np.array([wW[0] + phid, wW[1], wW[2]])
    dw_W = np.array([phidd, phid * wW[2], -phid * wW[1]])
    oR = out[9:12]
    doR = out[12:15]
    for i in range(3):
        oR[i] = C_RW[i, 0] * w_W[0] + C_RW[i, 1] * w_W[1] + C_RW[i, 2] * w_W[2]
        doR[i] = C_RW[i, 0] * dw_W[0] + C_RW[i, 1] * dw_W[1] + C_RW[i, 2] * dw_W[2]
    sigma_derivatives(sr, oR, doR, out[3:6], out[6:9])


class Guidance:
    """Reference attitude from the bank profile and the navigation state.

    After ``update(nav)``: phi_r, phidot_r, phiddot_r [rad, rad/s, rad/s^2]; sigma_RN,
    sigma_r_dot, sigma_r_ddot (3) [-, 1/s, 1/s^2]; omega_RN_R, domega_RN_R (3)
    [rad/s, rad/s^2] in R components; omega_WN_W (3) [rad/s] the wind frame's own rate.

    The wind frame's rate comes from r, v_rel and the inertial acceleration (sensed
    nav.accel_B rotated to N plus the FSW's point-mass gravity -mu r/|r|^3; J2 is
    neglected, ~1e-3 of g). Its derivative (~1e-5 rad/s^2) is neglected in domega_RN_R.
    ``mu_m3ps2`` defaults to the planet file's value (data/planets/mars.toml).
    """

    def __init__(self, profile: BankProfile, alpha_trim_rad: float, omega_planet_radps: float,
                 mu_m3ps2: float | None = None):
        if mu_m3ps2 is None:
            mu_m3ps2 = load_planet("mars").mu_m3ps2
        for name, v in (("alpha_trim_rad", alpha_trim_rad), ("omega_planet_radps", omega_planet_radps),
                        ("mu_m3ps2", mu_m3ps2)):
            if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
                raise ValueError(f"Guidance.{name}: must be a finite number, got {v!r}")
        if mu_m3ps2 < 0:
            raise ValueError(f"Guidance.mu_m3ps2: must be >= 0, got {mu_m3ps2!r}")
        if not (callable(getattr(profile, "evaluate", None)) and callable(getattr(profile, "replan", None))):
            raise ValueError("Guidance.profile: must have evaluate(t) and replan(t, rate, accel) (a BankProfile)")
        self.profile = profile
        self.alpha_trim_rad = float(alpha_trim_rad)
        # offsets of the reference's alpha and beta from the aerodynamic trim: the attitude at
        # which the aerodynamic moment absorbs a stuck-on bias the jets cannot cancel
        # (one array the compiled cycle writes: fsw/authority.py ``held_trim``)
        self.trim_offset = np.zeros(2)
        self.omega_planet_radps = float(omega_planet_radps)
        self.mu_m3ps2 = float(mu_m3ps2)
        self._out = np.zeros(18)
        self.sigma_RN = self._out[0:3]
        self.sigma_r_dot = self._out[3:6]
        self.sigma_r_ddot = self._out[6:9]
        self.omega_RN_R = self._out[9:12]
        self.domega_RN_R = self._out[12:15]
        self.omega_WN_W = self._out[15:18]
        self.phi_r, self.phidot_r, self.phiddot_r = profile.evaluate(0.0)
        # a scheduled profile is evaluated inside the compiled cycle (``profile_eval``); any
        # other (the npc shaper) by its own evaluate
        self.compiled_profile = isinstance(profile, BankProfile)

    @property
    def trim_offset_alpha_rad(self) -> float:
        return float(self.trim_offset[0])

    @trim_offset_alpha_rad.setter
    def trim_offset_alpha_rad(self, v: float) -> None:
        self.trim_offset[0] = v

    @property
    def trim_offset_beta_rad(self) -> float:
        return float(self.trim_offset[1])

    @trim_offset_beta_rad.setter
    def trim_offset_beta_rad(self, v: float) -> None:
        self.trim_offset[1] = v

    def update(self, nav) -> None:
        """Fill the reference for nav.t_s (nav: fsw.navigation.NavState)."""
        self.phi_r, self.phidot_r, self.phiddot_r = self.profile.evaluate(nav.t_s)
        _guidance_kernel(self.phi_r, self.phidot_r, self.phiddot_r,
                         self.alpha_trim_rad + self.trim_offset_alpha_rad, self.trim_offset_beta_rad,
                         self.omega_planet_radps, self.mu_m3ps2, nav.r_N, nav.v_N, nav.vrel_N, nav.C_WN,
                         nav.C_BN, nav.accel_B, nav.sigma_BN, self._out)
