"""main's cycle head and law stretch before their arguments were packed (fsw/flightsoftware.py
``intake_cycle``, fsw/law.py ``law_cycle`` at 8de80e2): the two compiled calls with one argument
per array (24 and 37), and the nine NavState scalars the law took as floats. ``MainHeadLawFlightSoftware``
flies them (and rehearses them) on the same arrays the packed calls use, so a test compares the
two cycles bit for bit and a timing script measures old against new in one process."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from fsw.authority import held_trim
from fsw.control import _D_BAD, _S_DIAG, _S_U, sami_kernel
from fsw.fdir import jet_step
from fsw.flightsoftware import _NO_SEGS, FlightSoftware
from fsw.guidance.reference import _guidance_kernel, profile_eval
from fsw.law import LAW_DONE, LAW_NOT_ENTRY, LAW_SAFE_DUE, wrap_pi
from fsw.modes import Mode, tracking_rule
from fsw.monitors import frame_check
from fsw.navigation import _nav_kernel
from interfaces.event_catalogue import EV


@njit(cache=True)
def main_intake_cycle(x, ki, stale, next_apply, lims, out, seq, sent, sent_k, zero_u, oracle,
                 iso_state, cnt, sum_dg, thr, persist, new_kind, eta_new,
                 omega_planet, radius_m, model, rho0, H_m, nav_buf):
    """The control cycle's head in one compiled call, on a SENSORS record's floats ``x`` and
    its (k, t_ns, u_k) ``ki``: the frame check (monitors.py ``frame_check``: ``lims`` ..
    ``seq``, ``stale``), FDIR's jet monitor on the command in force (fdir.py ``jet_step``:
    ``sent`` .. ``eta_new``, ``next_apply``) and navigation (navigation.py ``_nav_kernel``:
    the planet's constants, the NavState buffer). Returns (code, t_s, k, V_rel, h, alpha,
    beta, bank, rho, qbar, mach): code < 0 a rejected frame (``frame_check``'s code; nothing
    past the check ran, the navigation figures are zeros), else frame_check's flags plus 4
    times jet_step's (0: nothing for the Python caller to report or apply)."""
    k = ki[0]
    t_s = float(ki[1]) * 1e-9
    code = frame_check(x, k, lims, out, seq, stale)
    if code < 0:
        return code, t_s, k, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    step = jet_step(ki[2], sent, sent_k, zero_u, x[15:], oracle, t_s, next_apply, iso_state, cnt, sum_dg, thr,
                    persist, new_kind, eta_new)
    V, h, alpha, beta, bank, rho, qbar, mach = _nav_kernel(x, omega_planet, radius_m, model, rho0, H_m, nav_buf)
    return code + 4 * step, t_s, k, V, h, alpha, beta, bank, rho, qbar, mach


@njit(cache=True)
def main_law_cycle(t_nav, qbar, bank, V_mps, rho, alpha, beta, entry, have_del, freeze,
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


class MainHeadLawFlightSoftware(FlightSoftware):
    """A FlightSoftware whose head and law stretch are main's many-argument calls."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        # main's argument tuples, from the attributes (views of the packed buffers now)
        mon, fd, nav = self.monitor, self.fdir, self.nav
        ring = (self._sent, self._sent_k, self._zero_u, fd.oracle)
        self._m_intake_args = (mon._lims, mon._out, mon._seq, *ring, *fd.step_arrays(), *nav.kernel_args())
        self._m_intake_scratch = (mon._lims, mon._out, *ring, *fd.step_arrays(scratch=True),
                                  *nav.kernel_args(nav._r_buf))
        nav_s, g, ctl = self.nav.state, self.guidance, self.control
        fixed_in = (g.alpha_trim_rad, g.omega_planet_radps, g.mu_m3ps2, nav_s.r_N, nav_s.v_N, nav_s.vrel_N,
                    nav_s.C_WN, nav_s.C_BN, nav_s.accel_B, nav_s.sigma_BN, nav_s.omega_BN_B)
        self._m_law_args = (self.authority.trim, g.trim_offset, *fixed_in, g._out, self.dt_s, self.failsafes.state,
                            self.tau_alloc_B, ctl._kb, ctl._sb, ctl.chart, self.u_cal_B)
        self._m_law_scratch = (np.zeros(2), np.zeros(18), np.zeros(4), ctl._rb, np.zeros(1), np.zeros(3))
        sc = self._m_law_scratch
        self._m_law_rehearse_args = (self.authority.trim, sc[0], *fixed_in, sc[1], self.dt_s, sc[2],
                                     self.tau_alloc_B, ctl._kb, sc[3], sc[4], sc[5])

    def _run_cycle(self, frame) -> np.ndarray:
        self.cycles += 1
        self._count_torque()
        v = self.monitor.views(frame)
        if v is None:
            return self._rejected_format(frame)
        code, t_s, k, V, h, alpha, beta, bank, rho, qbar, mach = main_intake_cycle(
            v[0], v[1], self.monitor.stale, self.fdir._next_apply, *self._m_intake_args)
        if code < 0:
            self.monitor.settle(t_s, code, k)
            return self._held_off(t_s)
        self.k = k
        self.t_s = t_s
        reconfigured = code != 0 and self._intake_reports(t_s, code, k)
        nav = self.nav.state
        nav.t_s = t_s
        nav.V_rel_mps = V
        nav.h_m = h
        nav.alpha_rad = alpha
        nav.beta_rad = beta
        nav.bank_rad = bank
        nav.rho_kgpm3 = rho
        nav.qbar_pa = qbar
        nav.mach = mach
        if reconfigured or self.authority.due(t_s):
            self.authority.step(t_s, reconfigured)      # assessed with this cycle's navigation
        if self.entry is not None:
            self.entry.steer(nav)
            self.entry.shaper.observe(nav.bank_rad)
        if self.deploy is not None:
            self.deploy.update(nav, t_s, self.entry.estimator.k_rho if self.entry is not None else 1.0)
        # the held trim, the reference, the bank error, the tracking failsafe and SAMI in one
        # compiled call (law.py ``law_cycle``); a failsafe due or another mode than ENTRY
        # comes back here. No learning while FDIR holds a detection not yet reconfigured: the
        # torque commanded through the faulty jets is not what the tracking error saw.
        g = self.guidance
        entry = self.modes.mode is Mode.ENTRY
        pending = self.fdir.reconfig_pending
        if g.compiled_profile:
            prof = g.profile
            law, g.phi_r, g.phidot_r, g.phiddot_r, self.bank_err_rad = main_law_cycle(
                nav.t_s, nav.qbar_pa, nav.bank_rad, nav.V_rel_mps, nav.rho_kgpm3, nav.alpha_rad, nav.beta_rad,
                entry, self._have_prev, pending, True, prof.seg_array, prof.phi0_rad, 0.0, 0.0, 0.0, *self._m_law_args)
        else:
            law, g.phi_r, g.phidot_r, g.phiddot_r, self.bank_err_rad = main_law_cycle(
                nav.t_s, nav.qbar_pa, nav.bank_rad, nav.V_rel_mps, nav.rho_kgpm3, nav.alpha_rad, nav.beta_rad,
                entry, self._have_prev, pending, False, _NO_SEGS, 0.0, *g.profile.evaluate(nav.t_s), *self._m_law_args)
        if law == LAW_DONE:
            self.control.freeze = pending
        else:
            if law == LAW_SAFE_DUE:
                self.failsafes.enter_safe(t_s)
            mode = self.modes.mode
            if mode == Mode.ENTRY:
                self.control.freeze = not self.modes.adaptation_enabled or pending
                u_cal = self.control.update(nav, g, self.tau_alloc_B if self._have_prev else None)
            elif mode == Mode.SAFE:
                self.control.freeze = True
                u_cal = self.control.safe_torque(nav)
            else:
                u_cal = self._zero3
            self.u_cal_B[:] = u_cal
        self.dutycycle.short_frac = self.params["control.shortfall_frac"]
        dc = self.dutycycle
        u_alloc = dc.solve(self.allocator, self.u_cal_B)
        self.alloc_ns = dc.solve_ns
        if dc.rare:                  # the compiled path's ordinary answers call for no event
            if self.allocator.tables_version != self._tables_version:      # new tables in use
                self._tables_version = self.allocator.tables_version
                dc.reset()
                self.events.emit(t_s, EV.RECONFIGURED, rebuild_ms=self.allocator.rebuild_time_s * 1e3)
            if self.allocator.degraded:
                self.events.emit(t_s, EV.ALLOC_DEGRADED)
            if dc.fell_back:
                self.events.emit(t_s, EV.ALLOC_LP_FALLBACK)
        return self._finish(t_s, u_alloc)

    def _rehearse_intake(self, fv: tuple) -> None:
        """``intake_cycle`` on the rehearsal's copies of the record's floats ``fv[2]``, the
        monitor's sequence (as if the frame were new), FDIR's counters and the navigation
        state; its answers discarded."""
        x, seq = self.monitor.rehearsal_copy(fv[2])
        self.fdir.rehearsal_copy()
        self.nav.rehearsal_copy()
        a = self._m_intake_scratch
        main_intake_cycle(x, fv[3], False, self.fdir._next_apply, a[0], a[1], seq, *a[2:])

    def _rehearse_law(self) -> None:
        """``law_cycle`` on scratch copies of the state it writes (failsafes, SAMI, chart), with
        the last cycle's navigation and reference inputs; nothing the next cycle reads changes."""
        nav, g, sc, ctl = self.nav.state, self.guidance, self._m_law_scratch, self.control
        np.copyto(sc[2], self.failsafes.state)
        np.copyto(sc[3], ctl._sb)
        np.copyto(sc[4], ctl.chart)
        compiled = g.compiled_profile
        main_law_cycle(nav.t_s, nav.qbar_pa, nav.bank_rad, nav.V_rel_mps, nav.rho_kgpm3, nav.alpha_rad, nav.beta_rad,
                  self.modes.mode is Mode.ENTRY, self._have_prev, ctl.freeze, compiled,
                  g.profile.seg_array if compiled else _NO_SEGS, g.profile.phi0_rad if compiled else 0.0,
                  g.phi_r, g.phidot_r, g.phiddot_r, *self._m_law_rehearse_args)
