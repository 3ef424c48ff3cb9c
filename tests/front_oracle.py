"""The control cycle's head as Python code, the way main flew it before it became one compiled
call (fsw/flightsoftware.py ``intake_cycle``): the sensor monitor's check with its sequence in
Python attributes, FDIR's update on the command in force looked up in Python, navigation's
own update. ``PythonFrontFlightSoftware`` is a FlightSoftware whose cycle starts with this
Python code (the truth the kernel is held to bit for bit, and the "before" of timing)."""
from __future__ import annotations

import numpy as np

from fsw.fdir import _T_EPS_S, _jet_monitor
from fsw.flightsoftware import FlightSoftware
from fsw.modes import FailsafeAction, Mode
from fsw.monitors import _F0, _K0, _N_F, SensorMonitor, _frame_kernel
from fsw.navigation import _nav_kernel, frame_vectors
from common.frames import wrap_pi
from interfaces.event_catalogue import EV
from interfaces.records import SENSORS


class PythonSensorMonitor(SensorMonitor):
    """main's SensorMonitor: the sequence in plain attributes (they shadow the properties)."""
    last_k = None
    accepted = 0
    missed = 0

    def restart_sequence(self) -> None:
        self.last_k = None

    def _no_fresh(self, t_s: float) -> None:
        self.missed += 1
        if not self.stale and self.missed >= self.stale_n:
            self.stale = True
            self.events.emit(t_s, EV.SENSORS_STALE, periods=self.missed)

    def check(self, t_s: float, frame) -> bool:
        fv = self._fviews
        if frame is fv[0] and frame.dtype is fv[1] and frame.shape == () and frame.flags.writeable:
            x, k = fv[2], int(fv[3][0])
        else:
            if not isinstance(frame, np.ndarray) or frame.dtype != SENSORS or frame.shape != () \
                    or not frame.flags.c_contiguous or not frame.flags.writeable:
                return self._reject(t_s, "format", EV.FRAME_FORMAT)
            x = np.ndarray((_N_F,), dtype=np.float64, buffer=frame, offset=_F0)
            ki = np.ndarray((1,), dtype=np.int64, buffer=frame, offset=_K0)
            self._fviews = (frame, frame.dtype, x, ki)
            k = int(ki[0])
        code = _frame_kernel(x, self._lims, 5, self._out) if k >= 0 else -1
        if code == -1:
            return self._reject(t_s, "range", EV.FRAME_RANGE, k=k)
        if 1 <= code <= 5:
            return self._reject(t_s, "nonfinite", EV.FRAME_NONFINITE, vector=code - 1)
        if code > 100:
            return self._reject(t_s, "range", EV.FRAME_RANGE, vector=code - 101, value=self._out[0])
        if self.last_k is not None and k <= self.last_k:
            if k == self.last_k:
                return self._reject(t_s, "duplicate", EV.FRAME_DUPLICATE, k=k)
            return self._reject(t_s, "out_of_order", EV.FRAME_OUT_OF_ORDER, k=k)
        if self._out[1] or self._out[2]:
            self._report_chamber(t_s)
        self.last_k = k
        self.accepted += 1
        self.missed = 0
        if self.stale:
            self.stale = False
            self.events.emit(t_s, EV.SENSORS_RECOVERED)
        return True


def python_fdir_update(fd, t_s: float, u, chamber: np.ndarray) -> bool:
    """main's Fdir.update for a uint8 command (or None) and float64 pressures."""
    if u is None:
        fd.unknown_command_periods += 1
        return fd._apply_due(t_s) if t_s + _T_EPS_S >= fd._next_apply else False
    if fd.oracle:
        n_new = n_bad = 0
    else:
        n_new, n_bad = _jet_monitor(u, chamber, fd.health_isolated.state, fd._cnt, fd._sum_dg,
                                    fd._thr, int(fd._persist[0]), fd._new_kind, fd._eta_new)
    if n_bad:
        fd._report_nonfinite(t_s, n_bad)
    if n_new:
        fd._declare(t_s)
    if t_s + _T_EPS_S >= fd._next_apply:
        return fd._apply_due(t_s)
    return False


class PythonFrontFlightSoftware(FlightSoftware):
    """FlightSoftware whose cycle starts with main's Python head (and continues as main's cycle
    did; the tail is FlightSoftware's own ``_finish``)."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.monitor.__class__ = PythonSensorMonitor
        self._py_views: tuple = (None,)

    def _command_in_force(self, u_k: int):
        if u_k == -1:
            return self._zero_u
        i = u_k % self._ring
        return self._sent[i] if self._sent_k[i] == u_k else None

    def _rehearse_intake(self, fv) -> None:
        """main's rehearsal of the three stages, on copies (their answers discarded)."""
        pv = self._py_views
        if pv[0] is not fv[0]:
            return
        np.copyto(self.monitor._r_x, fv[2])
        _frame_kernel(self.monitor._r_x, self.monitor._lims, 5, self.monitor._out)
        u = self._command_in_force(int(fv[0]["u_k"]))
        fd = self.fdir
        if not fd.oracle and u is not None:
            fd.rehearsal_copy()
            _jet_monitor(u, pv[2], fd.health_isolated.state, *fd.step_arrays(scratch=True)[1:4],
                         int(fd._persist[0]), fd._r_kind, fd._r_eta)
        self.nav.rehearsal_copy()
        _nav_kernel(pv[1], *self.nav.kernel_args(self.nav._r_buf))

    def _run_cycle(self, frame) -> np.ndarray:
        self.cycles += 1
        self._count_torque()
        t_s = float(frame["t_ns"]) * 1e-9
        ok = self.monitor.check(t_s, frame)
        if not ok or self.monitor.stale:
            return self._held_off(t_s)
        fv = self._py_views
        if fv[0] is not frame:
            fv = self._py_views = (frame, frame_vectors(frame), frame["chamber"])
        self.k = self.monitor.last_k
        self.t_s = t_s
        reconfigured = python_fdir_update(self.fdir, t_s, self._command_in_force(int(frame["u_k"])), fv[2])
        if reconfigured:
            self.allocator.set_health(self.fdir.health_active)
            self.reconfig_times.append(t_s)
        nav = self.nav.update_packed(t_s, fv[1])
        # main's cycle after navigation
        self.authority.step(t_s, reconfigured)
        if self.entry is not None:
            self.entry.steer(nav)
            self.entry.shaper.observe(nav.bank_rad)
        if self.deploy is not None:
            self.deploy.update(nav, t_s, self.entry.estimator.k_rho if self.entry is not None else 1.0)
        self.authority.hold_trim(nav.qbar_pa)
        self.guidance.update(nav)
        self.bank_err_rad = wrap_pi(nav.bank_rad - self.guidance.phi_r)
        if self.failsafes.evaluate(t_s, self.dt_s, sensors_stale=False,
                                   tracking_error_rad=self.bank_err_rad) == FailsafeAction.HOLD_JETS_OFF:
            return self._held_off(t_s)
        mode = self.modes.mode
        if mode == Mode.ENTRY:
            self.control.freeze = not self.modes.adaptation_enabled or self.fdir.reconfig_pending
            u_cal = self.control.update(nav, self.guidance, self.tau_alloc_B if self._have_prev else None)
        elif mode == Mode.SAFE:
            self.control.freeze = True
            u_cal = self.control.safe_torque(nav)
        else:
            u_cal = self._zero3
        self.u_cal_B[:] = u_cal
        return python_allocation_stage(self, t_s)


def python_allocation_stage(fsw, t_s: float) -> np.ndarray:
    """Main's allocation stage as it was in Python before the compiled call, then the tail
    (FlightSoftware's own ``_finish``): the oracles' shared end of the cycle."""
    fsw.dutycycle.short_frac = fsw.params["control.shortfall_frac"]
    u_alloc = fsw.dutycycle.solve(fsw.allocator, fsw.u_cal_B)
    fsw.alloc_ns = fsw.dutycycle.solve_ns
    if fsw.allocator.tables_version != fsw._tables_version:
        fsw._tables_version = fsw.allocator.tables_version
        fsw.dutycycle.reset()
        fsw.events.emit(t_s, EV.RECONFIGURED, rebuild_ms=fsw.allocator.rebuild_time_s * 1e3)
    if fsw.allocator.degraded:
        fsw.events.emit(t_s, EV.ALLOC_DEGRADED)
    if fsw.dutycycle.fell_back:
        fsw.events.emit(t_s, EV.ALLOC_LP_FALLBACK)
    return fsw._finish(t_s, u_alloc)
