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
from numba import njit

from .dutylp import duty_cycles_kernel, scatter_duty_cycles, sigma_delta, warm_kernel
from .allocator import allocator_views
from .model import N_AXES, TIE_REL, TOL_BOX_NM, TOL_PEN, TOL_TIE
from .query import STATUS_DEGRADED, STATUS_REJECTED, ZERO3, solve_kernel, solve_tree_kernel
from .tables import H_NINT, H_NODES, table_views

# what the compiled cycle (``realise``) returns: the query's status in
# the low bits, then flags, then the LP's pivots + PIVOT_BIAS from bit 8
STATUS_MASK = 3
MODULATED = 4             # the answer flown is the sigma-delta's (realiser's ``u``)
NEED_LP = 8               # short, but the LP is not built for these tables: the caller builds it
LP_FAILED = 16            # the LP kernel failed: the caller solves it by HiGHS
RARE = STATUS_DEGRADED | STATUS_REJECTED | NEED_LP | LP_FAILED
PIVOT_SHIFT = 8
PIVOT_BIAS = 16           # > the kernel's failure codes' magnitude


@njit(cache=True)
def bank_axis_short(axis, u_B, tau_B, short_min_Nm, short_frac, round_Nm):
    """The realiser's gate (DutyCycleRealiser's docstring): the bank torque ``tau_B`` delivers
    less of a demand above ``short_min_Nm`` than the rule allows (the larger of ``round_Nm``
    and ``short_frac`` of the demand)."""
    d = axis[0] * u_B[0] + axis[1] * u_B[1] + axis[2] * u_B[2]
    got = axis[0] * tau_B[0] + axis[1] * tau_B[1] + axis[2] * tau_B[2]
    if abs(d) <= short_min_Nm:
        return False
    lim = round_Nm
    v = short_frac * abs(d)
    if v > lim:
        lim = v
    return ((d - got) if d >= 0.0 else (got - d)) > lim


@njit(cache=True)
def _flown_exact(tau_q, tau_B, acc):
    """A cycle flown on the exact answer: its torque, and the accumulators cleared (they are
    zero already unless the cycle before was modulated)."""
    for i in range(3):
        tau_B[i] = tau_q[i]
    for k in range(acc.shape[0]):
        acc[k] = 0.0


@njit(cache=True)
def modulate(u_B, cold, bias, jets, cols, d, avg_B, rhs, A, cost, upper, basis, state, x, Binv, y, dj, alpha, work,
             acc, u, uf, tau_B):
    """A modulated cycle: the LP (``duty_cycles_kernel``), the sigma-delta into ``u`` and its
    modelled torque ``tau_B`` = cols u + bias (np.dot: the BLAS product NumPy's own is, bit
    for bit). Returns the LP's pivots, or its failure code with nothing after the LP done."""
    pivots = duty_cycles_kernel(u_B, bias, jets, cols, d, avg_B, rhs, A, cost, upper, basis, state, x, Binv, y, dj,
                                alpha, work, cold)
    if pivots < 0:
        return pivots
    modulated_torque(d, jets, acc, u, uf, cols, bias, tau_B)
    return pivots


@njit(cache=True)
def modulated_torque(d, jets, acc, u, uf, cols, bias, tau_B):
    """The sigma-delta on duty cycles ``d`` into ``u`` and the torque of ``u``."""
    sigma_delta(d, jets, acc, u)
    for k in range(u.shape[0]):
        uf[k] = u[k]
    np.dot(cols, uf, tau_B)
    for i in range(3):
        tau_B[i] += bias[i]


# The realiser's arrays are views into two buffers, the floats ``rf`` and the int64s ``ri``, so the
# compiled stage takes the realiser in two arguments (each array argument costs ~40 ns of
# dispatch); ``realiser_views`` is the one layout. rf: the gate's scalars and axis, then 3-vectors,
# the LP's inverse and work, the rehearsal's 3-vectors; n-vectors (the rehearsal's too); the jets'
# columns; the LP's columns (room for every jet). ri: sizes and flags, the bases, the usable jets,
# then as bytes the LP's column states and the answers flown (the rehearsal's after each).
RF_SHORT_FRAC, RF_SHORT_MIN, RF_ROUND, RF_AXIS = 0, 1, 2, 3
RF_TAU, RF_DEMAND, RF_AVG, RF_RHS, RF_BIAS, RF_Y = 6, 9, 12, 15, 18, 21
RF_BINV, RF_WORK, RF_TAU_R, RF_DEMAND_R, RF_AVG_R, RF_N = 24, 33, 51, 54, 57, 60
RI_N, RI_P, RI_COLD, RI_LP, RI_MOD, RI_BASIS, RI_BASIS_R, RI_IDX = 0, 1, 2, 3, 4, 5, 8, 11


def realiser_buffers(n: int) -> tuple[np.ndarray, np.ndarray]:
    nc = n + 2 * N_AXES
    ri = np.zeros(RI_IDX + n + -(-(2 * nc + 2 * n) // 8), dtype=np.int64)
    ri[RI_N] = n
    ri[RI_COLD] = 1
    return np.zeros(RF_N + 9 * n + 8 * nc), ri


@njit(cache=True)
def realiser_views(rf, ri, warm):
    """(axis, tau_B, demand_B, avg_B, rhs, bias, y, Binv, work, d, acc, uf, cols, cost, upper, x, dj,
    alpha, A, basis, jets, state, u) of the buffers ``realiser_buffers`` made, the LP's for its
    ``ri[RI_P]`` usable jets; the rehearsal's tau_B, demand_B, avg_B, d, acc, uf, basis, state, u
    if ``warm``."""
    n, p = ri[RI_N], ri[RI_P]
    nc, ncol = n + 2 * N_AXES, p + 2 * N_AXES
    o3 = RF_TAU_R - RF_TAU if warm else 0
    on = RF_N + (3 * n if warm else 0)
    oc = RF_N + 9 * n
    b = ri.view(np.uint8)
    ob = (RI_IDX + n) * 8
    ou = ob + 2 * nc + (n if warm else 0)
    os = ob + (nc if warm else 0)
    obas = RI_BASIS_R if warm else RI_BASIS
    return (rf[RF_AXIS:RF_AXIS + 3], rf[RF_TAU + o3:RF_TAU + o3 + 3], rf[RF_DEMAND + o3:RF_DEMAND + o3 + 3],
            rf[RF_AVG + o3:RF_AVG + o3 + 3], rf[RF_RHS:RF_RHS + 3], rf[RF_BIAS:RF_BIAS + 3], rf[RF_Y:RF_Y + 3],
            rf[RF_BINV:RF_BINV + 9].reshape((N_AXES, N_AXES)),
            rf[RF_WORK:RF_WORK + 18].reshape((N_AXES, 2 * N_AXES)),
            rf[on:on + n], rf[on + n:on + 2 * n], rf[on + 2 * n:on + 3 * n],
            rf[RF_N + 6 * n:RF_N + 9 * n].reshape((N_AXES, n)),
            rf[oc:oc + ncol], rf[oc + nc:oc + nc + ncol], rf[oc + 2 * nc:oc + 2 * nc + ncol],
            rf[oc + 3 * nc:oc + 3 * nc + ncol], rf[oc + 4 * nc:oc + 4 * nc + ncol],
            rf[oc + 5 * nc:oc + 5 * nc + N_AXES * ncol].reshape((N_AXES, ncol)),
            ri[obas:obas + 3], ri[RI_IDX:RI_IDX + p], b[os:os + ncol].view(np.int8), b[ou:ou + n])


@njit(cache=True)
def _realise_tree(u_B, tf, ti, af, ai, rf, ri, warm):
    """One cycle of DutyCycleRealiser.solve on spill-box tables with no reconfiguration pending:
    the allocator's query (``solve_tree_kernel`` into its u, tau_B, objective), the gate
    (``bank_axis_short``), then either the exact answer's torque or, if the LP is built for these
    tables (ri[RI_LP]), the modulated cycle (``modulate``). ``warm``: the rehearsal, every output
    to the buffers' scratch copies, the LP's start and the accumulators copied there first, the
    LP only after a modulated cycle. Returns the code (STATUS_MASK, MODULATED, NEED_LP,
    LP_FAILED, the pivots from PIVOT_SHIFT)."""
    (w, spill, tbias, cand_tau, cand_pen, tie_obj, nlo, nhi, nminpen, _, _, _, _, _, cand_pat, ties, nstart, nend,
     _, _, _) = table_views(tf, ti)
    stack_k, stack_lb, u_q, tau_q, obj = allocator_views(af, ai, ri[RI_N], warm)
    (axis, tau_B, demand_B, avg_B, rhs, bias, y, Binv, work, d, acc, uf, cols, cost, upper, x, dj, alpha, A, basis,
     jets, state, u) = realiser_views(rf, ri, warm)
    lp_ready = ri[RI_LP] != 0
    if warm:
        lp_ready = lp_ready and ri[RI_MOD] != 0
        (_, _, _, _, _, _, _, _, _, _, acc0, _, _, _, _, _, _, _, _, basis0, _, state0, _) = realiser_views(rf, ri,
                                                                                                           False)
        basis[:] = basis0
        state[:] = state0
        acc[:] = acc0
    status = solve_tree_kernel(u_B, w, spill, nlo, nhi, nminpen, nstart, nend, ti[H_NINT], cand_tau, cand_pen,
                               cand_pat, ties, tie_obj, 0, ZERO3, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                               stack_k, stack_lb, u_q, tau_q, obj)
    for i in range(3):
        demand_B[i] = u_B[i]
    if status == STATUS_REJECTED:
        for i in range(3):
            tau_q[i] = tbias[i]
    if status == STATUS_REJECTED or not bank_axis_short(axis, u_B, tau_q, rf[RF_SHORT_MIN], rf[RF_SHORT_FRAC],
                                                        rf[RF_ROUND]):
        _flown_exact(tau_q, tau_B, acc)
        if not warm:
            ri[RI_MOD] = 0
        return status
    if not lp_ready:
        return status | NEED_LP
    pivots = modulate(u_B, ri[RI_COLD] != 0, bias, jets, cols, d, avg_B, rhs, A, cost, upper, basis, state, x, Binv,
                      y, dj, alpha, work, acc, u, uf, tau_B)
    if pivots < 0:
        return status | LP_FAILED | ((pivots + PIVOT_BIAS) << PIVOT_SHIFT)
    if not warm:
        ri[RI_MOD] = 1
        ri[RI_COLD] = 0
    return status | MODULATED | ((pivots + PIVOT_BIAS) << PIVOT_SHIFT)


@njit(cache=True)
def _realise_sign(u_B, tf, ti, af, ai, rf, ri, warm):
    """One cycle of DutyCycleRealiser.solve on the paper's sign-box tables (never modulated) with
    no reconfiguration pending: the query (``solve_kernel``) and the answer's torque; ``warm`` as
    ``_realise_tree``'s."""
    (w, _, tbias, cand_tau, cand_pen, scratch, _, _, _, X, S, P, bmin, _, cand_pat, _, _, _, start, R,
     bstart) = table_views(tf, ti)
    _, _, u_q, tau_q, obj = allocator_views(af, ai, ri[RI_N], warm)
    (_, tau_B, demand_B, _, _, _, _, _, _, _, acc, _, _, _, _, _, _, _, _, _, _, _, _) = realiser_views(rf, ri, warm)
    status = solve_kernel(u_B, w, start, X, S, P, R, bstart, bmin, cand_tau, cand_pen, cand_pat, scratch,
                          0, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN, u_q, tau_q, obj)
    for i in range(3):
        demand_B[i] = u_B[i]
    if status == STATUS_REJECTED:
        for i in range(3):
            tau_q[i] = tbias[i]
    _flown_exact(tau_q, tau_B, acc)
    if not warm:
        ri[RI_MOD] = 0
    return status


@njit(cache=True)
def realise(u_B, tf, ti, af, ai, rf, ri):
    """One cycle of DutyCycleRealiser.solve's common path, in one call: the table set (tf, ti),
    the allocator's (af, ai) and the realiser's (rf, ri) buffers; the tree's or the sign box's."""
    if ti[H_NODES] > 0:
        return _realise_tree(u_B, tf, ti, af, ai, rf, ri, False)
    return _realise_sign(u_B, tf, ti, af, ai, rf, ri, False)


@njit(cache=True)
def rehearse_stage(u_B, tf, ti, af, ai, rf, ri):
    """``realise`` for the rehearsal: the same reads, every output to scratch."""
    if ti[H_NODES] > 0:
        return _realise_tree(u_B, tf, ti, af, ai, rf, ri, True)
    return _realise_sign(u_B, tf, ti, af, ai, rf, ri, True)


_F64 = np.dtype(np.float64)
_SHAPE3 = (N_AXES,)


class DutyCycleRealiser:
    """Wraps one allocator's answer; arrays preallocated (per model: at its first short cycle)."""

    def __init__(self, bank_axis_B: np.ndarray, torque_matrix_Nm: np.ndarray, thrust_N: np.ndarray) -> None:
        T = np.asarray(torque_matrix_Nm, dtype=float)
        n = T.shape[1]
        # every array below a view into two buffers (``realiser_views``)
        self._rf, self._ri = realiser_buffers(n)
        self._views()
        self.axis[:] = np.asarray(bank_axis_B, dtype=float)
        self._axis = tuple(self.axis.tolist())
        inc = np.abs(self.axis @ T)
        # the bank shortfall that rounding to the finest jet explains: half its increment
        self.round_Nm = 0.5 * float(np.min(inc[inc > 0.0]))
        self._rf[RF_ROUND] = self.round_Nm
        # the FSW's own rule for a short bank axis (FlightSoftware._check_bank_shortfall, which
        # sets both): a demand above short_min_Nm that gets less than (1 - short_frac) of
        # itself; 0, 0 (stand-alone use): any shortfall beyond rounding
        self.short_min_Nm = 0.0
        self.short_frac = 0.0
        self._thrust = np.asarray(thrust_N, dtype=float)
        # u: the answer flown (modulated cycles); tau_B: its modelled torque [N m]; demand_B: the
        # demand it was solved for [N m]; avg_B: b + C d of the last LP [N m]; d: duty cycles of
        # the last LP (0 for unusable jets); acc: sigma-delta accumulators; _idx: usable jets
        # (the LP's first columns); _basis .. _work: the kernel's work arrays (fsw/allocation/dutylp.py);
        # the _r arrays: the rehearsal's copies of what a solve reads and its scratch outputs
        self.modulated = False                    # the last answer came from the modulator
        self.modulated_cycles = 0
        self.solve_ns = 0                         # compute time of the last ``solve`` [ns]
        self._rows = np.arange(N_AXES, dtype=np.int32)
        self.fell_back = False                    # the last LP was solved by HiGHS (the kernel failed)
        self.fallbacks = 0
        self._tables = None                       # the allocator tables the LP was built for
        self._h = None
        self.pivots = 0                           # pivots of the last LP (from the previous basis)
        warm_kernel()
        self.rare = True                          # the last solve may call for events (``solve``)
        self._version = -1                        # allocator.tables_version the compiled call's arguments are of
        self._args = ()

    def _views(self) -> None:
        """The attributes as views into the buffers (again after the LP's size changes)."""
        (self.axis, self.tau_B, self.demand_B, self.avg_B, self._rhs, self._bias, self._y, self._Binv, self._work,
         self.d, self.acc, self._uf, self._cols, self._cost, self._upper, self._x, self._dj, self._alpha, self._A,
         self._basis, self._idx, self._state, self.u) = realiser_views(self._rf, self._ri, False)
        (_, self._tau_r, self._demand_r, self._avg_r, _, _, _, _, _, self._d_r, self._acc_r, self._uf_r, _, _, _, _,
         _, _, _, self._basis_r, _, self._state_r, self._u_r) = realiser_views(self._rf, self._ri, True)

    @property
    def short_min_Nm(self) -> float:
        return float(self._rf[RF_SHORT_MIN])

    @short_min_Nm.setter
    def short_min_Nm(self, value: float) -> None:
        self._rf[RF_SHORT_MIN] = value

    @property
    def short_frac(self) -> float:
        return float(self._rf[RF_SHORT_FRAC])

    @short_frac.setter
    def short_frac(self, value: float) -> None:
        self._rf[RF_SHORT_FRAC] = value

    @property
    def _cold(self) -> bool:
        """The next LP starts from the residuals' basis (the compiled call clears it)."""
        return bool(self._ri[RI_COLD])

    @_cold.setter
    def _cold(self, value: bool) -> None:
        self._ri[RI_COLD] = value

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
        idx = np.flatnonzero(t.usable)
        p = len(idx)
        self._ri[RI_P] = p
        self._views()
        self._idx[:] = idx
        self._cols[:] = t.cols
        self._bias[:] = t.bias
        self.u[:] = 0
        self.acc[:] = 0.0
        self._A[:] = 0.0
        self._A[:, :p] = t.cols[:, self._idx]
        self._A[:, p:p + N_AXES] = -np.eye(N_AXES)
        self._A[:, p + N_AXES:] = np.eye(N_AXES)
        self._cost[:] = np.concatenate([allocator.penalty_per_N * self._thrust[self._idx], t.w, t.w])
        self._upper[:] = np.concatenate([np.ones(p), np.full(2 * N_AXES, np.inf)])
        for a in (self._x, self._state, self._state_r, self._dj, self._alpha):
            a[:] = 0
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
        self._lp_done(u_B, pivots)
        return self.d

    def _lp_done(self, u_B: np.ndarray, pivots: int) -> None:
        """After the LP kernel: its pivots noted, HiGHS's answer if it failed, the next start."""
        self.pivots = pivots
        self.fell_back = pivots < 0
        if self.fell_back:
            self.fallbacks += 1
            self._solve_highs(u_B)
            scatter_duty_cycles(self._x, self._idx, self._cols, self._bias, self.d, self.avg_B)
        self._cold = self.fell_back            # a failed basis is no warm start

    def solve(self, allocator, u_B: np.ndarray) -> np.ndarray:
        """The jets array to fly for demand ``u_B`` [N m]: the allocator's exact answer, or while
        the bank axis is short the sigma-delta of the LP's duty cycles. ``tau_B`` is the
        modelled torque of the answer flown; ``solve_ns`` the time this call took; ``rare``
        whether the caller has events to look for (a switch of tables, a degraded answer, a
        fallback to HiGHS): False on the compiled path's ordinary answers.

        The common case (the tables bound here, no reconfiguration pending, a demand of three
        floats) is one compiled call (``realise``) on the buffers bound once per tables
        (``_bind``); the rest is ``_solve``, the allocator's ``solve`` and the
        steps after it one by one."""
        t0 = time.perf_counter_ns()
        if (allocator.tables_version == self._version and not allocator.reconfig_pending and type(u_B) is np.ndarray
                and u_B.dtype is _F64 and u_B.shape == _SHAPE3):
            code = realise(u_B, *self._args)
            if code & RARE:
                u = self._after_rare(allocator, u_B, code)
            else:
                if self.rare:                     # the flags the last, rare, answer left
                    self.rare = False
                    self.fell_back = False
                    allocator.interim = False
                    allocator.note_status(0)
                if code & MODULATED:
                    self.pivots = (code >> PIVOT_SHIFT) - PIVOT_BIAS
                    self.modulated = True
                    self.modulated_cycles += 1
                    u = self.u
                else:
                    self.modulated = False
                    u = allocator.u
        else:
            u = self._solve(allocator, u_B)
            self.rare = True
            if not allocator.reconfig_pending:
                self._bind(allocator)
        self.solve_ns = time.perf_counter_ns() - t0
        return u

    def _after_rare(self, allocator, u_B: np.ndarray, code: int) -> np.ndarray:
        """The compiled call's rare endings: a degraded or rejected answer (noted on the
        allocator), a short cycle whose LP is to be built (then solved as ``duty_cycles``
        does), an LP the kernel failed (HiGHS solves it); the steps after as ``_solve``."""
        self.rare = True
        allocator.interim = False
        allocator.note_status(code & STATUS_MASK)
        self.fell_back = False
        if not code & (NEED_LP | LP_FAILED | MODULATED):
            self.modulated = False
            return allocator.u
        if code & NEED_LP:
            self.duty_cycles(allocator, u_B)
            self._bind(allocator)
        elif code & LP_FAILED:
            self._lp_done(u_B, (code >> PIVOT_SHIFT) - PIVOT_BIAS)
        else:
            self.pivots = (code >> PIVOT_SHIFT) - PIVOT_BIAS
            self._cold = False
        if code & (NEED_LP | LP_FAILED):
            modulated_torque(self.d, self._idx, self.acc, self.u, self._uf, self._cols, self._bias, self.tau_B)
        self.modulated = True
        self._ri[RI_MOD] = 1                      # the compiled call notes its own modulated cycles
        self.modulated_cycles += 1
        return self.u

    def _bind(self, allocator) -> None:
        """The compiled call's arguments for the allocator's active tables: the buffers, and
        whether the LP is built for these tables."""
        t = allocator._tables
        self._version = allocator.tables_version
        self._ri[RI_LP] = self._tables is t
        self._ri[RI_MOD] = self.modulated
        self._args = (t.tf, t.ti, allocator._af, allocator._ai, self._rf, self._ri)

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
        modulated_torque(self.d, self._idx, self.acc, self.u, self._uf, self._cols, self._bias, self.tau_B)
        self.modulated = True
        self.modulated_cycles += 1
        return self.u

    def rehearse(self, allocator, u_B: np.ndarray) -> None:
        """Real time, just before a release: the cycle's compiled call for a demand near the
        next one, the answer discarded, so the kernels, the tables and (after a modulated
        cycle) the LP's model the next cycle reads are in the caches. Changes nothing an
        answer depends on: the warm-start basis and the accumulators are copied, every output
        goes to scratch, and the work arrays (the query's ties and stacks, the LP's) are
        rewritten by every solve before they are read. Off the compiled path (tables not bound
        here, a reconfiguration pending): the allocator's own rehearsal."""
        if type(u_B) is not np.ndarray or u_B.dtype != np.float64 or u_B.shape != (N_AXES,):
            return
        if allocator.tables_version != self._version or allocator.reconfig_pending:
            allocator.rehearse(u_B)
            return
        rehearse_stage(u_B, *self._args)

    def reset(self) -> None:
        self.acc[:] = 0.0
        self.modulated = False
        self._ri[RI_MOD] = 0
