"""The duty-cycle LP's average realised over control cycles (sigma-delta per jet).

One cycle's allocation picks one jet pattern, the exact optimum for that cycle's demand. Once
failures leave no pattern that gives bank torque without pitch/yaw spill, the same pattern wins
cycle after cycle and the bank axis gets a fraction of what the jets hold on average: averaged
over cycles an on/off jet acts as its duty cycle d_j in [0, 1] (fsw/controllability.py), and the
average torque b + C d can be one no single pattern gives (campaign 2026 run 82: the weak way
needs patterns that spill pitch/yaw held by the trim's aerodynamic moment).

While the bank axis is short by the FSW's own rule (FlightSoftware._check_bank_shortfall: a
demand above two of the largest bank-axis jet increments of which the exact answer delivers
less than 1 - control.shortfall_frac), each cycle solves the continuous relaxation of the
allocator's own problem without its per-cycle box,

    minimise   sum_i w_i |u_i - (b + C d)_i| + sum_k c_k d_k   over 0 <= d <= 1,

C the usable jets' columns eta_k T_k, b the stuck-on bias, w and c the allocator's weights and
penalties (a bounded dual simplex compiled for this 3-row LP, fsw/allocation/dutylp.py, warm from
the previous cycle's basis; HiGHS solves the cycle's LP if the kernel fails, an event),
and fires each jet by a first-order sigma-delta on its duty cycle:
acc_k += d_k; fire when acc_k >= 1/2; acc_k -= fired. The accumulator stays in [-1/2, 1/2), so
over any run of N short cycles the jets' mean firing equals the mean d within 1/N per jet, and
the mean torque b + C mean(d) within sum_k |C_k| / N. A cycle that is not short flies the exact
allocator's answer and clears the accumulators (a new run of short cycles starts from zero).

Why that gate and not any shortfall beyond rounding to the finest jet: that wider gate
modulates a third to a half of the cycles of a many-fault case, flying its reversals on the
LP's weighted optimum (short in roll, exact in pitch and yaw), and the tracking suffers; the
FSW's own rule modulates only the cycles where one pattern cannot deliver the bank axis. A
demand one pattern delivers within that rule is left to the attitude loop, which integrates the
rest (docs/decisions.md keeps the figures).

Cost: one kernel call per modulated cycle (a pivot or two from the previous basis), the LP's
arrays built at the first short cycle after a change of tables.

The paper's sign box (allocator.spill_jets 0) is flown as before: no modulation. While an
asynchronous reconfiguration is pending (real time: the interim model) neither.
"""
from __future__ import annotations

import time

import numpy as np

from .dutylp import duty_cycles_kernel, scatter_duty_cycles, sigma_delta, warm_kernel
from .model import N_AXES


class DutyCycleRealiser:
    """Wraps one allocator's answer; arrays preallocated (per model: at its first short cycle)."""

    def __init__(self, bank_axis_B: np.ndarray, torque_matrix_Nm: np.ndarray, thrust_N: np.ndarray) -> None:
        T = np.asarray(torque_matrix_Nm, dtype=float)
        self.axis = np.asarray(bank_axis_B, dtype=float).copy()
        self._axis = tuple(self.axis.tolist())
        inc = np.abs(self.axis @ T)
        # the bank shortfall that rounding to the finest jet explains: half its increment
        self.round_Nm = 0.5 * float(np.min(inc[inc > 0.0]))
        # the FSW's own rule for a short bank axis (FlightSoftware._check_bank_shortfall, which
        # sets both): a demand above short_min_Nm that gets less than (1 - short_frac) of
        # itself; 0, 0 (stand-alone use): any shortfall beyond rounding
        self.short_min_Nm = 0.0
        self.short_frac = 0.0
        self._thrust = np.asarray(thrust_N, dtype=float)
        n = T.shape[1]
        self.u = np.zeros(n, dtype=np.uint8)      # the answer flown (modulated cycles)
        self.tau_B = np.zeros(N_AXES)             # modelled torque of the answer flown [N m]
        self.demand_B = np.zeros(N_AXES)          # the demand it was solved for [N m]
        self.avg_B = np.zeros(N_AXES)             # b + C d of the last LP [N m]
        self.d = np.zeros(n)                      # duty cycles of the last LP (0 for unusable jets)
        self.acc = np.zeros(n)                    # sigma-delta accumulators
        self.modulated = False                    # the last answer came from the modulator
        self.modulated_cycles = 0
        self.solve_ns = 0                         # compute time of the last ``solve`` [ns]
        self._uf = np.zeros(n)
        self._rhs = np.zeros(N_AXES)
        self._rows = np.arange(N_AXES, dtype=np.int32)
        self.fell_back = False                    # the last LP was solved by HiGHS (the kernel failed)
        self.fallbacks = 0
        self._tables = None                       # the allocator tables the LP was built for
        self._h = None
        self._idx = np.zeros(0, dtype=np.int64)   # usable jets (the LP's first columns)
        # the kernel's work arrays (fsw/allocation/dutylp.py); the per-model ones in _build
        self._basis = np.zeros(N_AXES, dtype=np.int64)
        self._Binv = np.zeros((N_AXES, N_AXES))
        self._y = np.zeros(N_AXES)
        self._work = np.zeros((N_AXES, 2 * N_AXES))
        self.pivots = 0                           # pivots of the last LP (from the previous basis)
        # the rehearsal's copies of what a solve reads and its scratch outputs
        self._basis_r = np.zeros(N_AXES, dtype=np.int64)
        self._state_r = np.zeros(0, dtype=np.int8)
        self._acc_r = np.zeros(n)
        self._d_r = np.zeros(n)
        self._avg_r = np.zeros(N_AXES)
        self._u_r = np.zeros(n, dtype=np.uint8)
        warm_kernel()
        self._cols = np.zeros((N_AXES, n))
        self._bias = np.zeros(N_AXES)

    def _short(self, u_B: np.ndarray, tau_B: np.ndarray) -> bool:
        # in Python floats (the same operations as on NumPy scalars, a fraction of their cost)
        a0, a1, a2 = self._axis
        u0, u1, u2 = u_B.tolist()
        t0, t1, t2 = tau_B.tolist()
        d = a0 * u0 + a1 * u1 + a2 * u2
        got = a0 * t0 + a1 * t1 + a2 * t2
        if abs(d) <= self.short_min_Nm:
            return False
        return ((d - got) if d >= 0.0 else (got - d)) > max(self.round_Nm, self.short_frac * abs(d))

    def _build(self, allocator) -> None:
        """The LP of the allocator's active tables: columns [d (p), r+ (3), r- (3)],
        rows C d - r+ + r- = u - b; the next solve starts cold."""
        t = allocator._tables
        self._tables = t
        self._idx = np.flatnonzero(t.usable)
        self._cols[:] = t.cols
        self._bias[:] = t.bias
        self.u[:] = 0
        self.acc[:] = 0.0
        p = len(self._idx)
        ncol = p + 2 * N_AXES
        self._A = np.zeros((N_AXES, ncol))
        self._A[:, :p] = t.cols[:, self._idx]
        self._A[:, p:p + N_AXES] = -np.eye(N_AXES)
        self._A[:, p + N_AXES:] = np.eye(N_AXES)
        self._cost = np.concatenate([allocator.penalty_per_N * self._thrust[self._idx], t.w, t.w])
        self._upper = np.concatenate([np.ones(p), np.full(2 * N_AXES, np.inf)])
        self._x = np.zeros(ncol)
        self._state = np.zeros(ncol, dtype=np.int8)
        self._state_r = np.zeros(ncol, dtype=np.int8)
        self._dj = np.zeros(ncol)
        self._alpha = np.zeros(ncol)
        self._cold = True
        self._h = None                            # HiGHS, built at a first fallback

    def _solve_highs(self, u_B: np.ndarray) -> None:
        """The fallback: the same LP through HiGHS (single-threaded), into ``_x``."""
        np.subtract(u_B, self._bias, out=self._rhs)
        if self._h is None:
            import highspy
            from fsw.lp import set_colwise_matrix
            ncol = self._A.shape[1]
            lp = highspy.HighsLp()
            lp.num_col_ = ncol
            lp.num_row_ = N_AXES
            lp.col_cost_ = self._cost.copy()
            lp.col_lower_ = np.zeros(ncol)
            lp.col_upper_ = np.where(np.isfinite(self._upper), self._upper, highspy.kHighsInf)
            lp.row_lower_ = self._rhs.copy()
            lp.row_upper_ = self._rhs.copy()
            set_colwise_matrix(lp, self._A)
            h = highspy.Highs()
            h.setOptionValue("output_flag", False)
            h.setOptionValue("threads", 1)
            h.passModel(lp)
            self._h = h
        self._h.changeRowsBounds(N_AXES, self._rows, self._rhs, self._rhs)
        self._h.run()
        self._x[:] = self._h.getSolution().col_value

    def duty_cycles(self, allocator, u_B: np.ndarray) -> np.ndarray:
        """d (n jets; 0 for unusable ones): the LP's optimum for demand ``u_B`` on the
        allocator's active model (fsw/allocation/dutylp.py's kernel, warm from the last
        cycle's basis; HiGHS if it fails, counted in ``fallbacks``). Sets ``avg_B`` = b + C d."""
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
        self._cold = self.fell_back            # a failed basis is no warm start
        return self.d

    def solve(self, allocator, u_B: np.ndarray) -> np.ndarray:
        """The jets array to fly for demand ``u_B`` [N m]: the allocator's exact answer, or while
        the bank axis is short the sigma-delta of the LP's duty cycles. ``tau_B`` is the
        modelled torque of the answer flown; ``solve_ns`` the time this call took."""
        t0 = time.perf_counter_ns()
        u = self._solve(allocator, u_B)
        self.solve_ns = time.perf_counter_ns() - t0
        return u

    def _solve(self, allocator, u_B: np.ndarray) -> np.ndarray:
        jets = allocator.solve(u_B)
        self.demand_B[:] = u_B
        self.fell_back = False
        if (allocator.rejected or allocator.reconfig_pending or not allocator._tables.spill_box
                or not self._short(u_B, allocator.tau_B)):
            self.tau_B[:] = allocator.tau_B
            if self.modulated:
                self.acc[:] = 0.0
                self.modulated = False
            return jets
        self.duty_cycles(allocator, u_B)
        u = self.u
        sigma_delta(self.d, self._idx, self.acc, u)
        self._uf[:] = u
        np.dot(self._cols, self._uf, out=self.tau_B)
        self.tau_B += self._bias
        self.modulated = True
        self.modulated_cycles += 1
        return u

    def rehearse(self, allocator, u_B: np.ndarray) -> None:
        """Real time, just before a release, after a modulated cycle: the LP and the sigma-delta
        for a demand near the next one, the answer discarded, so the kernels and the model the
        next modulated cycle reads are in the caches. Changes nothing an answer depends on: the
        warm-start basis and the accumulators are copied, the duty cycles and jets go to scratch,
        and the kernel's work arrays are rewritten by every solve before they are read."""
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

    def reset(self) -> None:
        self.acc[:] = 0.0
        self.modulated = False
