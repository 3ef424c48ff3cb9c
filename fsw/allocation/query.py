"""The allocator's query kernels: one allocation over one configuration's tables
(fsw/allocation/tables.py), without allocating. The method and its exactness argument are
in fsw/allocation/allocator.py's docstring.

- ``solve_kernel``: the sign box over the octant tables sorted by score.
- ``solve_tree_kernel``: the spill box, a branch and bound over the candidates' tree.
- ``solve_scan_kernel``: an exhaustive scan with a stuck-on bias the tables were not built
  with (the interim model of an asynchronous reconfiguration in the sign box).

Each returns STATUS_OK, STATUS_DEGRADED (no candidate in the box: the unconstrained
optimum) or STATUS_REJECTED (a non-finite demand: u = 0, objective NaN).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .model import N_AXES
from .build import BLOCK

STATUS_OK, STATUS_DEGRADED, STATUS_REJECTED = 0, 1, 2
ZERO3 = np.zeros(N_AXES)
TREE_STACK = 128          # >= 2 x the tree's depth + 2 (depth <= 16 for 2^18 candidates)


@njit(cache=True)
def _in_box(X, j, hi0, hi1, hi2):
    # the lower bounds x_i >= -tol_box hold for every member of an octant by construction
    # bitwise & (not `and`): one well-predicted branch instead of three unpredictable ones
    return (X[j, 0] <= hi0) & (X[j, 1] <= hi1) & (X[j, 2] <= hi2)


@njit(cache=True)
def _write_answer(r, d0, d1, d2, w, cand_tau, cand_pen, cand_pat, delta, u_out, tau_out, obj_out):
    tau_out[0] = cand_tau[r, 0] + delta[0]
    tau_out[1] = cand_tau[r, 1] + delta[1]
    tau_out[2] = cand_tau[r, 2] + delta[2]
    obj_out[0] = (w[0] * abs(d0 - tau_out[0]) + w[1] * abs(d1 - tau_out[1])
                  + w[2] * abs(d2 - tau_out[2]) + cand_pen[r])
    pat = cand_pat[r]
    for k in range(u_out.shape[0]):
        u_out[k] = (pat >> k) & 1


@njit(cache=True)
def _reject(u_out, obj_out):
    for k in range(u_out.shape[0]):
        u_out[k] = 0
    obj_out[0] = np.nan
    return 2


@njit(cache=True)
def _tie_break(scratch, lim, cand_pen, cand_pat, tol_pen):
    """Of the candidates whose objective (scratch) is at most lim: the smallest penalty
    (within tol_pen), then the smallest bit pattern; its index."""
    m = cand_pen.shape[0]
    min_pen = np.inf
    for r in range(m):
        if scratch[r] <= lim and cand_pen[r] < min_pen:
            min_pen = cand_pen[r]
    chosen = -1
    for r in range(m):
        if scratch[r] <= lim and cand_pen[r] <= min_pen + tol_pen:
            if chosen < 0 or cand_pat[r] < cand_pat[chosen]:
                chosen = r
    return chosen


@njit(cache=True)
def solve_kernel(tau_d, w, start, X, S, P, R, bstart, bmin, cand_tau, cand_pen, cand_pat, scratch,
                  forbid, tol_box, tol_tie, tie_rel, tol_pen, u_out, tau_out, obj_out):
    """One allocation over the candidates whose pattern has no bit of ``forbid`` (0: all).
    Writes u_out (n jets), tau_out (3,), obj_out[0]; returns STATUS_OK / STATUS_DEGRADED /
    STATUS_REJECTED. No allocation."""
    d0, d1, d2 = tau_d[0], tau_d[1], tau_d[2]
    if not (np.isfinite(d0) and np.isfinite(d1) and np.isfinite(d2)):
        return _reject(u_out, obj_out)
    o = 0
    if d0 < 0.0:
        o |= 1
    if d1 < 0.0:
        o |= 2
    if d2 < 0.0:
        o |= 4
    hi0 = abs(d0) + tol_box
    hi1 = abs(d1) + tol_box
    hi2 = abs(d2) + tol_box
    tol = tol_tie + tie_rel * (w[0] * abs(d0) + w[1] * abs(d1) + w[2] * abs(d2))
    first, stop = start[o], start[o + 1]
    best = -1
    # first allowed candidate inside the sign box = max score; skip blocks whose
    # component-wise minimum already leaves the box
    for blk in range(bstart[o], bstart[o + 1]):
        if (bmin[blk, 0] > hi0) | (bmin[blk, 1] > hi1) | (bmin[blk, 2] > hi2):
            continue
        j0 = first + (blk - bstart[o]) * BLOCK
        for j in range(j0, min(j0 + BLOCK, stop)):
            if _in_box(X, j, hi0, hi1, hi2) and (forbid == 0 or (cand_pat[R[j]] & forbid) == 0):
                best = j
                break
        if best >= 0:
            break
    status = 0
    chosen = -1
    if best >= 0:
        lim = S[best] - tol
        end = best + 1
        while end < stop and S[end] >= lim:
            end += 1
        min_pen = P[best]
        for j in range(best + 1, end):    # score ties: smallest penalty ...
            if (P[j] < min_pen and _in_box(X, j, hi0, hi1, hi2)
                    and (forbid == 0 or (cand_pat[R[j]] & forbid) == 0)):
                min_pen = P[j]
        for j in range(best, end):        # ... then smallest bit pattern
            if (P[j] <= min_pen + tol_pen and _in_box(X, j, hi0, hi1, hi2)
                    and (forbid == 0 or (cand_pat[R[j]] & forbid) == 0)):
                r = R[j]
                if chosen < 0 or cand_pat[r] < cand_pat[chosen]:
                    chosen = r
    else:                                 # empty sign box: unconstrained exhaustive scan
        status = 1
        m = cand_pen.shape[0]
        best_obj = np.inf
        for r in range(m):
            if forbid != 0 and (cand_pat[r] & forbid) != 0:
                scratch[r] = np.inf
                continue
            v = (w[0] * abs(d0 - cand_tau[r, 0]) + w[1] * abs(d1 - cand_tau[r, 1])
                 + w[2] * abs(d2 - cand_tau[r, 2]) + cand_pen[r])
            scratch[r] = v
            if v < best_obj:
                best_obj = v
        chosen = _tie_break(scratch, best_obj + tol, cand_pen, cand_pat, tol_pen)
    _write_answer(chosen, d0, d1, d2, w, cand_tau, cand_pen, cand_pat, ZERO3, u_out, tau_out, obj_out)
    return status


@njit(cache=True)
def _node_bound(k, nlo, nhi, nminpen, d0, d1, d2, w, delta, lo0, hi0, lo1, hi1, lo2, hi2):
    """A lower bound of the objective over the candidates under tree node k whose torque
    (+ delta) lies in the box [lo, hi]; inf if none can. Rounding is monotone, so the bound
    never exceeds an objective computed as in the leaves."""
    a0, b0 = max(nlo[k, 0] + delta[0], lo0), min(nhi[k, 0] + delta[0], hi0)
    a1, b1 = max(nlo[k, 1] + delta[1], lo1), min(nhi[k, 1] + delta[1], hi1)
    a2, b2 = max(nlo[k, 2] + delta[2], lo2), min(nhi[k, 2] + delta[2], hi2)
    if (a0 > b0) | (a1 > b1) | (a2 > b2):
        return np.inf
    e0 = a0 - d0 if d0 < a0 else (d0 - b0 if d0 > b0 else 0.0)
    e1 = a1 - d1 if d1 < a1 else (d1 - b1 if d1 > b1 else 0.0)
    e2 = a2 - d2 if d2 < a2 else (d2 - b2 if d2 > b2 else 0.0)
    return w[0] * e0 + w[1] * e1 + w[2] * e2 + nminpen[k]


@njit(cache=True)
def solve_tree_kernel(tau_d, w, spill, nlo, nhi, nminpen, nstart, nend, n_internal, cand_tau,
                       cand_pen, cand_pat, ties, tie_obj, forbid, delta, tol_box, tol_tie, tie_rel,
                       tol_pen, stack_k, stack_lb, u_out, tau_out, obj_out):
    """One allocation in the spill box over the candidates with no bit of ``forbid`` whose
    torque is cand_tau + delta (allocator.py docstring, spill box): depth-first branch and bound
    over the candidates' tree, nearer child first, a node pruned when its bound exceeds the best
    objective found + the tie tolerance; every candidate within that tolerance is kept
    (ties, tie_obj: work buffers of n rows) for the tie-break (model.py). With no candidate in the
    box, the same search without it (degraded). Same outputs as solve_kernel; stack_k,
    stack_lb: work buffers of >= 2 x tree depth + 2 entries. No allocation."""
    d0, d1, d2 = tau_d[0], tau_d[1], tau_d[2]
    if not (np.isfinite(d0) and np.isfinite(d1) and np.isfinite(d2)):
        return _reject(u_out, obj_out)
    tol = tol_tie + tie_rel * (w[0] * abs(d0) + w[1] * abs(d1) + w[2] * abs(d2))
    status = 0
    best = np.inf
    nt = 0
    for attempt in range(2):              # 0: inside the box; 1: anywhere (degraded)
        if attempt == 0:
            lo0, hi0 = min(d0, 0.0) - spill[0] - tol_box, max(d0, 0.0) + spill[0] + tol_box
            lo1, hi1 = min(d1, 0.0) - spill[1] - tol_box, max(d1, 0.0) + spill[1] + tol_box
            lo2, hi2 = min(d2, 0.0) - spill[2] - tol_box, max(d2, 0.0) + spill[2] + tol_box
        else:
            status = 1
            lo0 = lo1 = lo2 = -np.inf
            hi0 = hi1 = hi2 = np.inf
        best = np.inf
        nt = 0
        sp = 0
        lb = _node_bound(0, nlo, nhi, nminpen, d0, d1, d2, w, delta, lo0, hi0, lo1, hi1, lo2, hi2)
        if lb < np.inf:
            stack_k[0] = 0
            stack_lb[0] = lb
            sp = 1
        while sp > 0:
            sp -= 1
            if stack_lb[sp] > best + tol:
                continue
            k = stack_k[sp]
            if k >= n_internal:
                for j in range(nstart[k], nend[k]):
                    if forbid != 0 and (cand_pat[j] & forbid) != 0:
                        continue
                    t0 = cand_tau[j, 0] + delta[0]
                    t1 = cand_tau[j, 1] + delta[1]
                    t2 = cand_tau[j, 2] + delta[2]
                    if not ((lo0 <= t0) & (t0 <= hi0) & (lo1 <= t1) & (t1 <= hi1)
                            & (lo2 <= t2) & (t2 <= hi2)):
                        continue
                    v = w[0] * abs(d0 - t0) + w[1] * abs(d1 - t1) + w[2] * abs(d2 - t2) + cand_pen[j]
                    if v <= best + tol:
                        ties[nt] = j
                        tie_obj[nt] = v
                        nt += 1
                        if v < best:
                            best = v
                continue
            c1 = 2 * k + 1
            l1 = _node_bound(c1, nlo, nhi, nminpen, d0, d1, d2, w, delta, lo0, hi0, lo1, hi1, lo2, hi2)
            l2 = _node_bound(c1 + 1, nlo, nhi, nminpen, d0, d1, d2, w, delta, lo0, hi0, lo1, hi1, lo2, hi2)
            near, far, l_near, l_far = (c1, c1 + 1, l1, l2) if l1 <= l2 else (c1 + 1, c1, l2, l1)
            lim = best + tol
            if l_far <= lim:
                stack_k[sp] = far
                stack_lb[sp] = l_far
                sp += 1
            if l_near <= lim:
                stack_k[sp] = near
                stack_lb[sp] = l_near
                sp += 1
        if nt > 0:
            break
    lim = best + tol                      # ties: smallest penalty, then smallest bit pattern
    min_pen = np.inf
    for q in range(nt):
        if tie_obj[q] <= lim and cand_pen[ties[q]] < min_pen:
            min_pen = cand_pen[ties[q]]
    chosen = -1
    for q in range(nt):
        j = ties[q]
        if tie_obj[q] <= lim and cand_pen[j] <= min_pen + tol_pen and (chosen < 0 or cand_pat[j] < cand_pat[chosen]):
            chosen = j
    _write_answer(chosen, d0, d1, d2, w, cand_tau, cand_pen, cand_pat, delta, u_out, tau_out, obj_out)
    return status


@njit(cache=True)
def solve_scan_kernel(tau_d, w, spill, cand_tau, cand_pen, cand_pat, scratch, forbid, delta,
                       tol_box, tol_tie, tie_rel, tol_pen, u_out, tau_out, obj_out):
    """One allocation over the candidates with no bit of ``forbid``, whose torque is
    cand_tau + delta (delta: a stuck-on bias the tables were not built with, else 0):
    exhaustive scan with the box of allowance ``spill`` (3,), else without it (degraded).
    Same tie-break and outputs as solve_kernel."""
    d0, d1, d2 = tau_d[0], tau_d[1], tau_d[2]
    if not (np.isfinite(d0) and np.isfinite(d1) and np.isfinite(d2)):
        return _reject(u_out, obj_out)
    lo0, hi0 = min(d0, 0.0) - spill[0] - tol_box, max(d0, 0.0) + spill[0] + tol_box
    lo1, hi1 = min(d1, 0.0) - spill[1] - tol_box, max(d1, 0.0) + spill[1] + tol_box
    lo2, hi2 = min(d2, 0.0) - spill[2] - tol_box, max(d2, 0.0) + spill[2] + tol_box
    tol = tol_tie + tie_rel * (w[0] * abs(d0) + w[1] * abs(d1) + w[2] * abs(d2))
    m = cand_pen.shape[0]
    status = 0
    for attempt in range(2):              # 0: inside the box; 1: anywhere (degraded)
        best_obj = np.inf
        for r in range(m):
            scratch[r] = np.inf
            if (cand_pat[r] & forbid) != 0:
                continue
            t0 = cand_tau[r, 0] + delta[0]
            t1 = cand_tau[r, 1] + delta[1]
            t2 = cand_tau[r, 2] + delta[2]
            if attempt == 0 and not ((lo0 <= t0) & (t0 <= hi0) & (lo1 <= t1) & (t1 <= hi1)
                                     & (lo2 <= t2) & (t2 <= hi2)):
                continue
            v = w[0] * abs(d0 - t0) + w[1] * abs(d1 - t1) + w[2] * abs(d2 - t2) + cand_pen[r]
            scratch[r] = v
            if v < best_obj:
                best_obj = v
        if best_obj < np.inf:
            break
        status = 1
    chosen = _tie_break(scratch, best_obj + tol, cand_pen, cand_pat, tol_pen)
    _write_answer(chosen, d0, d1, d2, w, cand_tau, cand_pen, cand_pat, delta, u_out, tau_out, obj_out)
    return status
