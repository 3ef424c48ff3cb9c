"""Reference solvers of the allocation problem (fsw/allocation/model.py), for tests,
benchmarks and the batch runner's offline optimality check. Nothing in the flight
software calls them.

- ``solve_highs``: the problem as a mixed-integer program solved by HiGHS to a zero gap.
- ``solve_enumeration`` / ``solve_enumeration_many``: the oracle, brute force over all 2^p
  patterns of the usable jets with the spec's tie-break (itself checked against a naive
  loop in tests/test_allocation_exact.py).
"""
from __future__ import annotations

from collections import OrderedDict

import numpy as np
from numba import njit

from fsw.lp import set_colwise_matrix, solve_or_none

from .model import N_AXES, TIE_REL, TOL_BOX_NM, TOL_PEN, TOL_TIE, effective_model, validate_problem


def _spill3(spill) -> np.ndarray:
    e = np.zeros(N_AXES) if spill is None else np.asarray(spill, dtype=float)
    if e.shape != (N_AXES,) or not np.all(np.isfinite(e)) or np.any(e < 0):
        raise ValueError(f"spill: expected 3 finite values >= 0 [N m], got {spill!r}")
    return e


def solve_highs(T, thrust, health, w, c, tau_d, fault_tolerance=True, spill=None):
    """Reference MILP via HiGHS (mip_rel_gap = 0, mip_abs_gap = 0, feasibility
    tolerances = TOL_BOX_NM). ``c`` is the penalty per newton (c_k = c * thrust_k);
    ``spill`` (3,) the box's allowance [N m] (None: the sign box).
    Returns (u uint8[n], objective, degraded); objective evaluated from the returned u."""
    import highspy

    T, thrust, w, c = validate_problem(T, thrust, w, c)
    tau_d = np.asarray(tau_d, dtype=float)
    if tau_d.shape != (N_AXES,) or not np.all(np.isfinite(tau_d)):
        raise ValueError(f"tau_d: expected 3 finite values, got {tau_d!r}")
    spill = _spill3(spill)
    usable, cols, b, ck = effective_model(T, thrust, health, c, fault_tolerance)
    idx = np.flatnonzero(usable)
    A = cols[:, idx]
    p = len(idx)

    def run(box: bool):
        h = highspy.Highs()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("mip_rel_gap", 0.0)
        h.setOptionValue("mip_abs_gap", 0.0)
        h.setOptionValue("mip_feasibility_tolerance", TOL_BOX_NM)
        h.setOptionValue("primal_feasibility_tolerance", TOL_BOX_NM)
        h.setOptionValue("threads", 1)
        inf = highspy.kHighsInf
        lp = highspy.HighsLp()
        lp.num_col_ = p + N_AXES
        # columns: u_k (binary), e_i >= |tau_d,i - tau_i|
        lp.col_cost_ = np.concatenate([ck[idx], w])
        lp.col_lower_ = np.zeros(p + N_AXES)
        lp.col_upper_ = np.concatenate([np.ones(p), np.full(N_AXES, inf)])
        rows, lower, upper = [], [], []
        for i in range(N_AXES):
            e = np.zeros(N_AXES)
            e[i] = 1.0
            rows.append(np.concatenate([A[i], e]))      # e_i + tau_i - b_i >= tau_d,i - b_i
            lower.append(tau_d[i] - b[i])
            upper.append(inf)
            rows.append(np.concatenate([-A[i], e]))     # e_i - tau_i + b_i >= b_i - tau_d,i
            lower.append(b[i] - tau_d[i])
            upper.append(inf)
            if box:                                     # box on tau_i = b_i + A_i u
                lo_i, hi_i = min(tau_d[i], 0.0) - spill[i], max(tau_d[i], 0.0) + spill[i]
                rows.append(np.concatenate([A[i], np.zeros(N_AXES)]))
                lower.append(lo_i - b[i])
                upper.append(hi_i - b[i])
        M = np.array(rows)
        lp.num_row_ = M.shape[0]
        lp.row_lower_ = np.array(lower)
        lp.row_upper_ = np.array(upper)
        set_colwise_matrix(lp, M)
        lp.integrality_ = [highspy.HighsVarType.kInteger] * p + [highspy.HighsVarType.kContinuous] * N_AXES
        x = solve_or_none(h, lp)
        return None if x is None else np.round(x[:p]).astype(np.uint8)

    degraded = False
    uu = run(box=True)
    if uu is None:
        degraded = True
        uu = run(box=False)
    u = np.zeros(T.shape[1], dtype=np.uint8)
    u[idx] = uu
    tau = b + cols @ u
    obj = float(np.sum(w * np.abs(tau_d - tau)) + ck @ u)
    return u, obj, degraded


_ENUM_CACHE: OrderedDict = OrderedDict()


def _enumeration_table(T, thrust, health, c, fault_tolerance):
    """All 2^p patterns over the usable jets: torques, penalties, global bit patterns."""
    key = (T.tobytes(), thrust.tobytes(), None if health is None else health.key(), c,
           bool(fault_tolerance))
    hit = _ENUM_CACHE.get(key)
    if hit is not None:
        return hit
    usable, cols, b, ck = effective_model(T, thrust, health, c, fault_tolerance)
    idx = np.flatnonzero(usable)
    p = len(idx)
    m = np.arange(2 ** p, dtype=np.int64)
    U = ((m[:, None] >> np.arange(p)[None, :]) & 1).astype(float)     # (2^p, p)
    tau = b[None, :] + U @ cols[:, idx].T
    pen = U @ ck[idx]
    pat = (U.astype(np.int64) << idx[None, :].astype(np.int64)).sum(axis=1)
    hit = (np.ascontiguousarray(tau), pen, pat)
    _ENUM_CACHE[key] = hit
    while len(_ENUM_CACHE) > 4:
        _ENUM_CACHE.popitem(last=False)
    return hit


@njit(cache=True)
def _enumeration_kernel(tau, pen, pat, w, spill, D, tol_box, tol_tie, tie_rel, tol_pen,
                        out_pat, out_obj, out_deg):
    """Brute force per demand over every pattern: feasible set (the box of allowance
    spill), min objective, ties by penalty then pattern; if nothing is feasible, the same
    without the box."""
    m = pen.shape[0]
    obj = np.empty(m)
    feas = np.empty(m, dtype=np.bool_)
    for q in range(D.shape[0]):
        d = D[q]
        tol = tol_tie + tie_rel * (w[0] * abs(d[0]) + w[1] * abs(d[1]) + w[2] * abs(d[2]))
        any_feas = False
        for r in range(m):
            ok = True
            for i in range(3):
                if d[i] >= 0.0:
                    ok = ok and (-spill[i] - tol_box <= tau[r, i] <= d[i] + spill[i] + tol_box)
                else:
                    ok = ok and (d[i] - spill[i] - tol_box <= tau[r, i] <= spill[i] + tol_box)
            feas[r] = ok
            any_feas = any_feas or ok
            obj[r] = (w[0] * abs(d[0] - tau[r, 0]) + w[1] * abs(d[1] - tau[r, 1])
                      + w[2] * abs(d[2] - tau[r, 2]) + pen[r])
        if not any_feas:
            feas[:] = True
        best = np.inf
        for r in range(m):
            if feas[r] and obj[r] < best:
                best = obj[r]
        min_pen = np.inf
        for r in range(m):
            if feas[r] and obj[r] <= best + tol and pen[r] < min_pen:
                min_pen = pen[r]
        chosen = -1
        for r in range(m):
            if feas[r] and obj[r] <= best + tol and pen[r] <= min_pen + tol_pen:
                if chosen < 0 or pat[r] < pat[chosen]:
                    chosen = r
        out_pat[q] = pat[chosen]
        out_obj[q] = obj[chosen]
        out_deg[q] = not any_feas


def solve_enumeration_many(T, thrust, health, w, c, tau_d, fault_tolerance=True, spill=None):
    """The oracle for many demands tau_d (n, 3): (U uint8[n, jets], objective[n], degraded[n])."""
    T, thrust, w, c = validate_problem(T, thrust, w, c)
    spill = _spill3(spill)
    D = np.ascontiguousarray(np.atleast_2d(np.asarray(tau_d, dtype=float)))
    if D.shape[1] != N_AXES or not np.all(np.isfinite(D)):
        raise ValueError("tau_d: expected finite demands of shape (n, 3)")
    tau, pen, pat = _enumeration_table(T, thrust, health, c, fault_tolerance)
    n = D.shape[0]
    out_pat = np.empty(n, dtype=np.int64)
    out_obj = np.empty(n)
    out_deg = np.empty(n, dtype=np.bool_)
    _enumeration_kernel(tau, pen, pat, w, spill, D, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                        out_pat, out_obj, out_deg)
    U = ((out_pat[:, None] >> np.arange(T.shape[1])[None, :]) & 1).astype(np.uint8)
    return U, out_obj, out_deg


def solve_enumeration(T, thrust, health, w, c, tau_d, fault_tolerance=True, spill=None):
    """The oracle: brute force over all 2^p patterns of the usable jets.
    ``c`` is the penalty per newton, ``spill`` the box's allowance (None: the sign box).
    Returns (u uint8[n], objective, degraded)."""
    U, obj, deg = solve_enumeration_many(T, thrust, health, w, c,
                                         np.asarray(tau_d, dtype=float).reshape(1, N_AXES),
                                         fault_tolerance, spill)
    return U[0], float(obj[0]), bool(deg[0])
