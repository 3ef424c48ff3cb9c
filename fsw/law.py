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
from .navigation import (_S_ACC, _S_ALPHA, _S_BANK, _S_BETA, _S_CBN, _S_CWN, _S_OMEGA, _S_QBAR, _S_R, _S_RHO,
                         _S_SIGMA, _S_T, _S_V, _S_VR, _S_VREL)

# law_cycle's answers: SAMI ran / SAFE is due (the caller requests it) / not in ENTRY
LAW_DONE, LAW_SAFE_DUE, LAW_NOT_ENTRY = 0, 1, 2

# law_cycle's two buffers, one argument each (numba's dispatch costs per array argument; the
# owners keep views under their own names, FlightSoftware.__init__ binds them): what it reads
# -- the guidance's constants, the held trim's state (AuthoritySupervisor.trim) -- and what it
# writes -- the tracking failsafe's state (Failsafes.state), SAMI's chart flag
# (SamiController.chart), the trim offsets (Guidance.trim_offset). The torques are the cycle's
# own buffer (FlightSoftware.torques, which the tail takes too): [0:3] SAMI's command u_cal_B
# (written), [3:6] the torque allocated last cycle tau_alloc_B (read).
LR_ALPHA_TRIM, LR_OMEGA, LR_MU, LR_DT, LR_TRIM, LR_N = 0, 1, 2, 3, 4, 9
LW_FS, LW_CHART, LW_TRIM_OFF, LW_N = 0, 4, 5, 7


@njit(cache=True)
def wrap_pi(a):
    """common/frames.py wrap_pi, compiled: the same arithmetic."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


@njit(cache=True)
def law_cycle(nav, entry, have_del, freeze, compiled, segs, phi0, phi, phid, phidd, lr, g_out, kb, sb, lw, torques):
    """The control law's stretch of the cycle after navigation, in one compiled call (the
    Python it replaced, in order): the held trim (authority.py ``held_trim``, into the trim
    offsets), the bank reference (``profile_eval`` on the scheduled profile's ``segs`` when
    ``compiled``, else the given ``phi``, ``phid``, ``phidd``), the reference attitude
    (guidance/reference.py ``_guidance_kernel``, into ``g_out``), the bank error wrapped to
    (-pi, pi], the tracking failsafe (modes.py ``tracking_rule``) and, in ENTRY with no
    failsafe due, SAMI (``sami_kernel`` on ``kb``/``sb``; the chart flag), its command copied
    to the command's slots of ``torques``. The navigation (time, scalars, arrays) is read from the
    NavState buffer ``nav`` (navigation.py's layout); ``lr``, ``lw`` as laid out above (LR_*, LW_*).
    Returns (LAW_DONE: SAMI ran / LAW_SAFE_DUE / LAW_NOT_ENTRY, phi_r, phidot_r, phiddot_r,
    bank error): 1 and 2 leave the mode's branch to the caller."""
    if compiled:
        phi, phid, phidd = profile_eval(segs, phi0, nav[_S_T])
    trim_off = lw[LW_TRIM_OFF:LW_TRIM_OFF + 2]
    held_trim(lr[LR_TRIM:LR_TRIM + 5], nav[_S_QBAR], trim_off)
    sigma_BN = nav[_S_SIGMA:_S_SIGMA + 3]
    _guidance_kernel(phi, phid, phidd, lr[LR_ALPHA_TRIM] + trim_off[0], trim_off[1], lr[LR_OMEGA], lr[LR_MU],
                     nav[_S_R:_S_R + 3], nav[_S_V:_S_V + 3], nav[_S_VREL:_S_VREL + 3],
                     nav[_S_CWN:_S_CWN + 9].reshape((3, 3)), nav[_S_CBN:_S_CBN + 9].reshape((3, 3)),
                     nav[_S_ACC:_S_ACC + 3], sigma_BN, g_out)
    err = wrap_pi(nav[_S_BANK] - phi)
    if tracking_rule(err, entry, lr[LR_DT], lw[LW_FS:LW_FS + 4]):
        return LAW_SAFE_DUE, phi, phid, phidd, err
    if not entry:
        return LAW_NOT_ENTRY, phi, phid, phidd, err
    sami_kernel(sigma_BN, nav[_S_OMEGA:_S_OMEGA + 3], nav[_S_VR], nav[_S_RHO], nav[_S_ALPHA], nav[_S_BETA],
                g_out[0:3], g_out[9:12], g_out[12:15], torques[3:6], have_del, freeze, lw[LW_CHART] != 0.0,
                kb, sb)
    if sb[_S_DIAG + _D_BAD] == 0.0:
        lw[LW_CHART] = 1.0
    for i in range(3):
        torques[i] = sb[_S_U + i]
    return LAW_DONE, phi, phid, phidd, err
