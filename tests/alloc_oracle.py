"""The allocation stage as Python code, the way main flew it before it became one compiled call
(fsw/allocation/dutycycle.py ``realise``): ``Allocator.solve``'s wrapper
and ``DutyCycleRealiser.solve`` step by step, the truth the compiled call is held to bit for bit.
``PythonAllocFlightSoftware`` is a FlightSoftware whose allocation runs this code and makes all
three event checks every cycle (also the "before" of the timing script in docs/changelog.md)."""
from __future__ import annotations

import time

import numpy as np

from fsw.allocation.allocator import _as_demand
from fsw.allocation.dutycycle import DutyCycleRealiser
from fsw.allocation.dutylp import duty_cycles_kernel, scatter_duty_cycles, sigma_delta
from fsw.allocation.model import N_AXES, TIE_REL, TOL_BOX_NM, TOL_PEN, TOL_TIE
from fsw.allocation.query import STATUS_DEGRADED, STATUS_REJECTED, ZERO3, solve_kernel, solve_scan_kernel, solve_tree_kernel
from fsw.flightsoftware import FlightSoftware


def python_allocator_solve(al, tau_d):
    """Allocator.solve as main (8e98865) has it (``objective`` is read from the query's output)."""
    if (type(tau_d) is not np.ndarray or tau_d.dtype != np.float64
            or tau_d.shape != (N_AXES,) or not tau_d.flags.c_contiguous):
        tau_d = _as_demand(tau_d)
    if al.reconfig_pending:
        al._try_switch()
    t = al._tables
    al.interim = al.reconfig_pending
    if t.spill_box:
        status = solve_tree_kernel(tau_d, t.w, t.spill, t.nlo, t.nhi, t.nminpen, t.nstart, t.nend,
                                   t.n_internal, t.tau, t.pen, t.pat, t.ties, t.scratch,
                                   al._forbid, al._delta if al._shifted else ZERO3,
                                   TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                                   al._stack_k, al._stack_lb, al.u, al.tau_B, al._obj)
    elif al.reconfig_pending and al._shifted:
        status = solve_scan_kernel(tau_d, t.w, t.spill, t.tau, t.pen, t.pat, t.scratch, al._forbid, al._delta,
                                   TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN, al.u, al.tau_B, al._obj)
    else:
        status = solve_kernel(tau_d, t.w, t.start, t.X, t.S, t.P, t.R, t.bstart, t.bmin, t.tau, t.pen, t.pat,
                              t.scratch, al._forbid, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN, al.u, al.tau_B, al._obj)
    if status == STATUS_REJECTED:
        if al.interim:
            np.add(t.bias, al._delta, out=al.tau_B)
        else:
            al.tau_B[:] = t.bias
        al.degraded = False
        al.rejected = True
    else:
        al.degraded = status == STATUS_DEGRADED
        al.rejected = False
    return al.u


class PythonRealiser(DutyCycleRealiser):
    """DutyCycleRealiser whose ``solve`` and ``rehearse`` are main's Python."""

    def solve(self, allocator, u_B):
        t0 = time.perf_counter_ns()
        u = self._python_solve(allocator, u_B)
        self.solve_ns = time.perf_counter_ns() - t0
        self.rare = True
        return u

    def _python_solve(self, allocator, u_B):
        jets = python_allocator_solve(allocator, u_B)
        self.demand_B[:] = u_B
        self.fell_back = False
        if (allocator.rejected or allocator.reconfig_pending or not allocator._tables.spill_box
                or not self._short(u_B, allocator.tau_B)):
            self.tau_B[:] = allocator.tau_B
            if self.modulated:
                self.acc[:] = 0.0
                self.modulated = False
            return jets
        if self._tables is not allocator._tables:
            self._build(allocator)
        pivots = duty_cycles_kernel(u_B, self._bias, self._idx, self._cols, self.d, self.avg_B, self._rhs, self._A,
                                    self._cost, self._upper, self._basis, self._state, self._x, self._Binv, self._y,
                                    self._dj, self._alpha, self._work, self._cold)
        self.pivots = pivots
        self.fell_back = pivots < 0
        if self.fell_back:
            self.fallbacks += 1
            self._solve_highs(u_B)
            scatter_duty_cycles(self._x, self._idx, self._cols, self._bias, self.d, self.avg_B)
        self._cold = self.fell_back
        u = self.u
        sigma_delta(self.d, self._idx, self.acc, u)
        self._uf[:] = u
        np.dot(self._cols, self._uf, out=self.tau_B)
        self.tau_B += self._bias
        self.modulated = True
        self.modulated_cycles += 1
        return u

    def rehearse(self, allocator, u_B):
        allocator.rehearse(u_B)
        if (not self.modulated or self._tables is not allocator._tables or allocator.reconfig_pending
                or type(u_B) is not np.ndarray or u_B.dtype != np.float64 or u_B.shape != (N_AXES,)):
            return
        self._basis_r[:] = self._basis
        self._state_r[:] = self._state
        self._acc_r[:] = self.acc
        if duty_cycles_kernel(u_B, self._bias, self._idx, self._cols, self._d_r, self._avg_r, self._rhs, self._A,
                              self._cost, self._upper, self._basis_r, self._state_r, self._x, self._Binv, self._y,
                              self._dj, self._alpha, self._work, self._cold) >= 0:
            sigma_delta(self._d_r, self._idx, self._acc_r, self._u_r)


def python_realiser(realiser: DutyCycleRealiser) -> DutyCycleRealiser:
    """The same realiser object, its solve and rehearsal main's Python from now on."""
    realiser.__class__ = PythonRealiser
    return realiser


class PythonAllocFlightSoftware(FlightSoftware):
    """A FlightSoftware whose allocation stage is main's Python (``PythonRealiser``)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        python_realiser(self.dutycycle)
