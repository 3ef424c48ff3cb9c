"""The control law's stretch of the control cycle, after navigation up to the command handed to
the allocation, in one compiled call (docs/decisions.md, "The control law's stretch in one
compiled call"): the held trim (authority.py), the bank reference and the reference attitude
(guidance/reference.py), the bank error, the tracking failsafe (modes.py) and SAMI (control.py),
each rule in its owner's module. The Python shell (FlightSoftware._run_cycle) takes what the
kernel hands back: a failsafe due, another mode than ENTRY, the authority's answers."""
from __future__ import annotations

import math

from numba import njit

from .authority import held_trim
from .control import _D_BAD, _S_DIAG, _S_U, sami_kernel
from .guidance.reference import _guidance_kernel, profile_eval
from .modes import tracking_rule

# law_cycle's answers: SAMI ran / SAFE is due (the caller requests it) / not in ENTRY
LAW_DONE, LAW_SAFE_DUE, LAW_NOT_ENTRY = 0, 1, 2


@njit(cache=True)
def wrap_pi(a):
    """common/frames.py wrap_pi, compiled: the same arithmetic."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


@njit(cache=True)
def law_cycle(t_nav, qbar, bank, V_mps, rho, alpha, beta, entry, have_del, freeze,
              compiled, segs, phi0, phi, phid, phidd,
              trim, trim_off, alpha_trim, omega_planet, mu, r_N, v_N, vrel_N, C_WN, C_BN, accel_B, sigma_BN, omega,
              g_out, dt_s, fs, tau_del, kb, sb, chart, u_cal_B):
    """The control law's stretch of the cycle after navigation, in one compiled call (the
    Python it replaced, in order): the held trim (authority.py ``held_trim``, into ``trim_off``),
    the bank reference (``profile_eval`` on the scheduled profile's ``segs`` when ``compiled``,
    else the given ``phi``, ``phid``, ``phidd``), the reference attitude (guidance/reference.py
    ``_guidance_kernel``, into ``g_out``), the bank error wrapped to (-pi, pi], the tracking
    failsafe (modes.py ``tracking_rule`` on ``fs``) and, in ENTRY with no failsafe due, SAMI
    (``sami_kernel`` on ``kb``/``sb``; ``chart[0]`` its chart flag), its command copied to
    ``u_cal_B``. Returns (LAW_DONE: SAMI ran / LAW_SAFE_DUE / LAW_NOT_ENTRY, phi_r, phidot_r,
    phiddot_r, bank error): 1 and 2 leave the mode's branch to the caller."""
    if compiled:
        phi, phid, phidd = profile_eval(segs, phi0, t_nav)
    held_trim(trim, qbar, trim_off)
    _guidance_kernel(phi, phid, phidd, alpha_trim + trim_off[0], trim_off[1], omega_planet, mu, r_N, v_N, vrel_N,
                     C_WN, C_BN, accel_B, sigma_BN, g_out)
    err = wrap_pi(bank - phi)
    if tracking_rule(err, entry, dt_s, fs):
        return LAW_SAFE_DUE, phi, phid, phidd, err
    if not entry:
        return LAW_NOT_ENTRY, phi, phid, phidd, err
    sami_kernel(sigma_BN, omega, V_mps, rho, alpha, beta, g_out[0:3], g_out[9:12], g_out[12:15], tau_del, have_del,
                freeze, chart[0] != 0.0, kb, sb)
    if sb[_S_DIAG + _D_BAD] == 0.0:
        chart[0] = 1.0
    for i in range(3):
        u_cal_B[i] = sb[_S_U + i]
    return LAW_DONE, phi, phid, phidd, err
