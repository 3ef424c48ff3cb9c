"""The duty-cycle LP's compiled solver (the LP: fsw/allocation/dutycycle.py), without allocating.

The LP has three rows and p + 6 bounded columns,

    minimise  c.d + w.(r+ + r-)   s.t.  C d - r+ + r- = u - b,   0 <= d <= 1,  r+, r- >= 0,

and only its right-hand side changes from cycle to cycle. So the previous cycle's optimal basis
stays dual feasible (reduced costs depend on the costs and the matrix alone) and a bounded dual
simplex from it needs a pivot or two; with every jet column boxed, the residual columns r-
alone are a dual feasible basis to start from cold (each d_k at the bound its reduced cost
picks). The LP is always feasible (d = 0, r = |u - b|) and bounded (c, w >= 0), so the dual
simplex ends at an optimum unless numerics stop it.

Each pivot recomputes the 3 x 3 basis inverse (Gauss-Jordan, partial pivoting), the duals, the
reduced costs and the basic values from the data, so no error builds up over pivots or over
cycles. Pricing picks the largest primal infeasibility scaled by its row of the inverse (dual
steepest edge, exact at this size); the ratio test is Harris's two passes (the largest pivot
among the near-ties), the textbook guard against the tiny pivots of dual degenerate bases.

``solve_duty_lp`` returns the number of pivots, or a negative code: ITERATION_LIMIT (cycling or
numerics; the caller falls back to another solver) or SINGULAR (a basis it cannot invert).
"""
from __future__ import annotations

import numpy as np
from numba import njit

AT_LOWER, AT_UPPER, BASIC = 0, 1, 2                     # column states
ITERATION_LIMIT, SINGULAR = -1, -2                      # failure codes
MAX_PIVOTS = 50           # a 3-row LP: far more than any non-cycling solve needs
TOL_PRIMAL = 1e-9         # bound violation accepted at the optimum [N m for r, - for d]
TOL_DUAL = 1e-9           # reduced-cost sign violation treated as zero [cost units]
TOL_DUAL_RESTART = 1e-7   # a residual column's violation beyond which the warm basis is dropped
                          # (Harris's ratio test leaves violations up to TOL_DUAL on purpose)
TOL_PIVOT = 1e-9          # smallest pivot element accepted by the ratio test
TOL_SINGULAR = 1e-12      # relative pivot below which a basis is taken as singular


@njit(cache=True)
def _invert_basis(A, basis, work, Binv):
    """Binv = B^-1, B the columns ``basis`` of A; False if B is (numerically) singular."""
    m = basis.shape[0]
    scale = 0.0
    for i in range(m):
        for k in range(m):
            v = A[i, basis[k]]
            work[i, k] = v
            work[i, m + k] = 1.0 if i == k else 0.0
            if abs(v) > scale:
                scale = abs(v)
    for k in range(m):
        piv = k
        for i in range(k + 1, m):
            if abs(work[i, k]) > abs(work[piv, k]):
                piv = i
        if abs(work[piv, k]) <= TOL_SINGULAR * scale:
            return False
        if piv != k:
            for j in range(2 * m):
                t = work[k, j]
                work[k, j] = work[piv, j]
                work[piv, j] = t
        f = 1.0 / work[k, k]
        for j in range(2 * m):
            work[k, j] *= f
        for i in range(m):
            if i != k:
                g = work[i, k]
                if g != 0.0:
                    for j in range(2 * m):
                        work[i, j] -= g * work[k, j]
    for i in range(m):
        for k in range(m):
            Binv[i, k] = work[i, m + k]
    return True


@njit(cache=True)
def _residual_basis(m, p, basis, state):
    """The cold start: r-_i basic in row i (column +e_i), every other column at its lower bound."""
    for j in range(state.shape[0]):
        state[j] = AT_LOWER
    for i in range(m):
        basis[i] = p + m + i
        state[p + m + i] = BASIC


@njit(cache=True)
def solve_duty_lp(rhs, A, cost, upper, basis, state, x, Binv, y, dj, alpha, work, cold):
    """The optimum of min cost.x s.t. A x = rhs, 0 <= x <= upper, A = [C, -I, I] (3 rows),
    upper 1 for the p duty cycles and inf for the 6 residuals, from the basis ``basis`` /
    ``state`` of the previous call (``cold``: from the residuals' basis). Writes x (every
    column), basis and state (the next call's warm start), the duals y and the reduced costs
    dj. Returns the pivots made, or ITERATION_LIMIT / SINGULAR. No allocation."""
    m, n = A.shape
    p = n - 2 * m
    if cold:
        _residual_basis(m, p, basis, state)
    restarted = cold
    for it in range(MAX_PIVOTS + 1):
        if not _invert_basis(A, basis, work, Binv):
            if restarted:
                return SINGULAR
            _residual_basis(m, p, basis, state)
            restarted = True
            continue
        for i in range(m):                                   # y = c_B B^-1
            s = 0.0
            for k in range(m):
                s += cost[basis[k]] * Binv[k, i]
            y[i] = s
        dual_ok = True
        for j in range(n):                                   # reduced costs
            if state[j] == BASIC:
                dj[j] = 0.0
                continue
            s = cost[j]
            for i in range(m):
                s -= y[i] * A[i, j]
            dj[j] = s
            # a boxed column sits at the bound its reduced cost picks (a flip keeps the basis
            # dual feasible); an unbounded one cannot: then the warm basis is no start
            if s < -TOL_DUAL and state[j] == AT_LOWER:
                if upper[j] < np.inf:
                    state[j] = AT_UPPER
                elif s < -TOL_DUAL_RESTART:
                    dual_ok = False
            elif s > TOL_DUAL and state[j] == AT_UPPER:
                state[j] = AT_LOWER
        if not dual_ok:
            if restarted:
                return ITERATION_LIMIT
            _residual_basis(m, p, basis, state)
            restarted = True
            continue
        for i in range(m):                                   # rhs - N x_N
            s = rhs[i]
            for j in range(n):
                if state[j] == AT_UPPER:
                    s -= A[i, j] * upper[j]
            work[i, 0] = s
        for j in range(n):
            x[j] = upper[j] if state[j] == AT_UPPER else 0.0
        r = -1
        best = 0.0
        delta_r = 0.0
        for k in range(m):                                   # x_B and the leaving row
            v = 0.0
            for i in range(m):
                v += Binv[k, i] * work[i, 0]
            j = basis[k]
            x[j] = v
            if v < -TOL_PRIMAL:
                delta = v
            elif v > upper[j] + TOL_PRIMAL:
                delta = v - upper[j]
            else:
                continue
            norm2 = Binv[k, 0] * Binv[k, 0] + Binv[k, 1] * Binv[k, 1] + Binv[k, 2] * Binv[k, 2]
            score = delta * delta / norm2
            if score > best:
                best, r, delta_r = score, k, delta
        if r < 0:
            return it
        if it == MAX_PIVOTS:
            return ITERATION_LIMIT
        # the pivot row alpha = (row r of B^-1) A_N, signed so that candidates have alpha > 0
        # at their lower bound and alpha < 0 at their upper bound
        sgn = -1.0 if delta_r < 0.0 else 1.0
        theta_max = np.inf
        for j in range(n):
            if state[j] == BASIC:
                alpha[j] = 0.0
                continue
            a = 0.0
            for i in range(m):
                a += Binv[r, i] * A[i, j]
            a *= sgn
            alpha[j] = a
            if (state[j] == AT_LOWER and a > TOL_PIVOT) or (state[j] == AT_UPPER and a < -TOL_PIVOT):
                t = (abs(dj[j]) + TOL_DUAL) / abs(a)
                if t < theta_max:
                    theta_max = t
        q = -1
        for j in range(n):                                   # Harris: largest pivot within theta_max
            if state[j] == BASIC:
                continue
            a = alpha[j]
            if (state[j] == AT_LOWER and a > TOL_PIVOT) or (state[j] == AT_UPPER and a < -TOL_PIVOT):
                if abs(dj[j]) / abs(a) <= theta_max and (q < 0 or abs(a) > abs(alpha[q])):
                    q = j
        if q < 0:                                            # dual unbounded: never for this LP
            return ITERATION_LIMIT
        state[basis[r]] = AT_LOWER if delta_r < 0.0 else AT_UPPER
        state[q] = BASIC
        basis[r] = q
    return ITERATION_LIMIT


@njit(cache=True)
def duty_cycles_kernel(u_B, bias, jets, cols, d, avg_B, rhs, A, cost, upper, basis, state, x, Binv, y, dj, alpha,
                       work, cold):
    """The realiser's LP for demand u_B: rhs = u_B - bias, ``solve_duty_lp``, then the duty
    cycles d (n jets: column q of the LP is jet jets[q], clipped to [0, 1]; 0 for the others) and
    avg_B = bias + cols d. Returns what ``solve_duty_lp`` returns; on a failure d and avg_B are
    left to the caller's fallback."""
    for i in range(rhs.shape[0]):
        rhs[i] = u_B[i] - bias[i]
    pivots = solve_duty_lp(rhs, A, cost, upper, basis, state, x, Binv, y, dj, alpha, work, cold)
    if pivots < 0:
        return pivots
    scatter_duty_cycles(x, jets, cols, bias, d, avg_B)
    return pivots


@njit(cache=True)
def scatter_duty_cycles(x, jets, cols, bias, d, avg_B):
    """d[jets[q]] = x[q] clipped to [0, 1], 0 for the other jets; avg_B = bias + cols d."""
    for k in range(d.shape[0]):
        d[k] = 0.0
    for q in range(jets.shape[0]):
        v = x[q]
        d[jets[q]] = 0.0 if v < 0.0 else (1.0 if v > 1.0 else v)
    for i in range(avg_B.shape[0]):
        s = bias[i]
        for k in range(d.shape[0]):
            s += cols[i, k] * d[k]
        avg_B[i] = s


@njit(cache=True)
def sigma_delta(d, jets, acc, u):
    """One cycle of the first-order sigma-delta on duty cycles d: acc_k += d_k; jet k fires
    (u_k = 1) when acc_k >= 1/2, and then acc_k -= 1. Only jets ``jets`` fire; the others' u_k
    is left as it is."""
    for k in range(acc.shape[0]):
        acc[k] += d[k]
    for q in range(jets.shape[0]):
        k = jets[q]
        if acc[k] >= 0.5:
            u[k] = 1
            acc[k] -= 1.0
        else:
            u[k] = 0


def warm_kernel() -> None:
    """Compile (or load from the cache) the kernels and run their branches once (cold start, a
    pivot, a warm start), on a one-jet LP, so the first short cycle in flight meets no JIT."""
    A = np.array([[1.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0],
                  [0.5, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0],
                  [0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0]])
    cost = np.array([0.1, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    upper = np.array([1.0, np.inf, np.inf, np.inf, np.inf, np.inf, np.inf])
    n = A.shape[1]
    basis, state = np.zeros(3, dtype=np.int64), np.zeros(n, dtype=np.int8)
    x, dj, alpha = np.zeros(n), np.zeros(n), np.zeros(n)
    Binv, y, work = np.zeros((3, 3)), np.zeros(3), np.zeros((3, 6))
    jets, cols, bias = np.zeros(1, dtype=np.int64), A[:, :2].copy(), np.zeros(3)
    d, acc, avg_B, rhs = np.zeros(2), np.zeros(2), np.zeros(3), np.zeros(3)
    u = np.zeros(2, dtype=np.uint8)
    for u_B, cold in ((np.array([2.0, 1.0, -1.0]), True), (np.array([-0.5, 0.2, 0.0]), False)):
        duty_cycles_kernel(u_B, bias, jets, cols, d, avg_B, rhs, A, cost, upper, basis, state, x, Binv, y, dj,
                           alpha, work, cold)
        sigma_delta(d, jets, acc, u)
    scatter_duty_cycles(x, jets, cols, bias, d, avg_B)
