"""The control law's stretch of the cycle (after navigation, up to the command handed to the
allocation) as Python code, the way main flew it before it became one compiled call
(fsw/law.py ``law_cycle``): the truth the kernel is held to bit for bit.
``PythonLawFlightSoftware`` is a FlightSoftware whose cycle runs this Python code with its own
Python state (the failsafe's persistence, the held trim's offsets, SAMI's chart flag), so
nothing of the compiled path is shared but the kernels main already had (``_guidance_kernel``,
``sami_kernel``). Also the "before" of the timing script in docs/benchmarks.md."""
from __future__ import annotations

import bisect
import math

import numpy as np

from fsw.control import _D_BAD, sami_kernel
from fsw.flightsoftware import FlightSoftware, intake_cycle
from fsw.guidance.reference import BankProfile, _eval_quintic, _guidance_kernel
from fsw.modes import FailsafeAction, Mode
from tests.front_oracle import python_allocation_stage


def python_wrap_pi(a: float) -> float:
    """common/frames.py wrap_pi as main had it."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


def python_profile_evaluate(prof: BankProfile, t_s: float) -> tuple[float, float, float]:
    """BankProfile.evaluate on its list of segments (main's)."""
    i = bisect.bisect_right(prof._starts, t_s) - 1
    if i < 0:
        return prof.phi0_rad, 0.0, 0.0
    t0, T, c, _, b, _, rest = prof._segs[i]
    x = (t_s - t0) / T
    if x >= 1.0 and rest:
        return b, 0.0, 0.0
    return _eval_quintic(c, T, x)


def python_hold_trim(auth, qbar_pa: float) -> tuple[float, float]:
    """AuthoritySupervisor.hold_trim as main had it: the (alpha, beta) offset."""
    tr = auth._trim_ref
    if tr is None:
        return 0.0, 0.0
    k = tr[2] / qbar_pa if qbar_pa > 0.0 and math.isfinite(qbar_pa) else math.inf
    k = min(k, math.radians(auth.params["guidance.trim_max_deg"]) / max(abs(tr[0]), abs(tr[1])))
    return tr[0] * k, tr[1] * k


class PythonFailsafes:
    """Failsafes.evaluate's rule 2 with fresh sensors as main had it (its own Python state)."""

    def __init__(self, fs):
        self.fs = fs
        self.above_s = 0.0
        self.last_rule = ""

    def evaluate(self, t_s: float, dt_s: float, tracking_error_rad: float) -> FailsafeAction:
        fs = self.fs
        beyond = not (math.isfinite(tracking_error_rad) and abs(tracking_error_rad) <= fs.limit_rad)
        if fs.modes.mode == Mode.ENTRY and beyond:
            self.above_s += dt_s
            if self.above_s >= fs.persist_s - 1e-9:
                self.above_s = 0.0
                self.last_rule = "tracking_error"
                fs.modes.request(t_s, Mode.SAFE, "track err")
                return FailsafeAction.SAFE
        else:
            self.above_s = 0.0
        self.last_rule = ""
        return FailsafeAction.NONE


class PythonLawFlightSoftware(FlightSoftware):
    """A FlightSoftware whose control law's stretch is main's Python."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self._py_fs = PythonFailsafes(self.failsafes)
        self._py_chart = False
        self.trim_offsets: list[tuple[float, float]] = []      # each cycle's, to prove a trim was flown

    def _run_cycle(self, frame) -> np.ndarray:      # main's (its compiled head), the law's stretch in Python
        self.cycles += 1
        self._count_torque()
        v = self.monitor.views(frame)
        if v is None:
            return self._rejected_format(frame)
        code, t_s, k, V, h, alpha, beta, bank, rho, qbar, mach = intake_cycle(
            v[0], v[1], self.monitor.stale, self.fdir._next_apply, *self._intake_args)
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
        self.authority.step(t_s, reconfigured)
        if self.entry is not None:
            self.entry.steer(nav)
            self.entry.shaper.observe(nav.bank_rad)
        if self.deploy is not None:
            self.deploy.update(nav, t_s, self.entry.estimator.k_rho if self.entry is not None else 1.0)
        g = self.guidance
        da, db = python_hold_trim(self.authority, nav.qbar_pa)
        self.trim_offsets.append((da, db))
        prof = g.profile
        ph = python_profile_evaluate(prof, nav.t_s) if isinstance(prof, BankProfile) else prof.evaluate(nav.t_s)
        g.phi_r, g.phidot_r, g.phiddot_r = ph
        _guidance_kernel(g.phi_r, g.phidot_r, g.phiddot_r, g.alpha_trim_rad + da, db, g.omega_planet_radps,
                         g.mu_m3ps2, nav.r_N, nav.v_N, nav.vrel_N, nav.C_WN, nav.C_BN, nav.accel_B, nav.sigma_BN,
                         g._out)
        g.trim_offset[:] = (da, db)         # where the branch keeps them (RG3's reassess reads them)
        self.bank_err_rad = python_wrap_pi(nav.bank_rad - g.phi_r)
        self._py_fs.evaluate(t_s, self.dt_s, self.bank_err_rad)
        ctl = self.control
        mode = self.modes.mode
        if mode == Mode.ENTRY:
            ctl.freeze = not self.modes.adaptation_enabled or self.fdir.reconfig_pending
            have_del = self._have_prev
            sami_kernel(nav.sigma_BN, nav.omega_BN_B, nav.V_rel_mps, nav.rho_kgpm3, nav.alpha_rad, nav.beta_rad,
                        g.sigma_RN, g.omega_RN_R, g.domega_RN_R, self.tau_alloc_B if have_del else ctl._zero3,
                        have_del, ctl.freeze, self._py_chart, ctl._kb, ctl._sb)
            if ctl._diag[_D_BAD] == 0.0:
                self._py_chart = True
            u_cal = ctl.u_cal_B
        elif mode == Mode.SAFE:
            ctl.freeze = True
            u_cal = ctl.safe_torque(nav)
        else:
            u_cal = self._zero3
        self.u_cal_B[:] = u_cal
        return python_allocation_stage(self, t_s)


def law_state(fsw) -> np.ndarray:
    """What the law's stretch leaves for the rest of the flight, as one array: SAMI's state and
    command, the reference, the trim offsets, the FSW's command to the allocation and bank error."""
    g, ctl = fsw.guidance, fsw.control
    return np.concatenate([ctl._sb[:31], g._out, g.trim_offset, fsw.u_cal_B,
                           [g.phi_r, g.phidot_r, g.phiddot_r, fsw.bank_err_rad, float(ctl.freeze)]])
