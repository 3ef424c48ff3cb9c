"""Fault-tolerant discrete control allocation (spec 20-fsw.md "Fault-tolerant discrete
control allocation"; paper section 3).

Problem, per control cycle, for demand tau_d (3,) [N m]:

    minimise   sum_i w_i |tau_d,i - tau_i| + sum_k c_k u_k          (c_k = penalty_per_N * F_k)
    over       u in {0,1}^p  (usable jets: nominal, or degraded with column eta_k T_k)
    where      tau = b + sum_k eta_k T_k u_k,  b = sum_{stuck-on} T_k
    subject to 0 <= tau_i <= tau_d,i (tau_d,i >= 0),  tau_d,i <= tau_i <= 0 (tau_d,i < 0)

If no u satisfies the sign box (possible only with a stuck-on bias) the same objective is
minimised without it and the answer is flagged ``degraded``. Ties (objectives within
``tie_tol``) are broken by the smaller penalty sum, then by the smaller jet-bit pattern
sum_k u_k 2^(k-1) (jet 1 = bit 0). The constant penalty of stuck-on jets is not part of
the objective (it does not change the argmin).

Method (exact by construction, see tests/test_allocation_*.py):
  1. Per health configuration, jets with identical effective columns are grouped; every
     multiplicity vector over the groups is enumerated (choosing the cheapest, then
     lowest-numbered members of a group), and identical torque vectors are merged keeping
     the smallest (penalty, pattern). Nominal matrix: 46,656 combinations -> ~13,000
     distinct achievable torques.
  2. Inside the sign box the objective is linear: with s_i = sign(tau_d,i) (+1 for 0),
     objective = sum_i w_i |tau_d,i| - score,  score = sum_i w_i s_i tau_i - c.
     score does not depend on the demand, only on its octant, so for each of the 8
     octants the candidates that can lie in it (s_i tau_i >= 0 on every axis) are sorted
     by score once. A query is the first candidate in that order inside the box
     |tau_i| <= |tau_d,i| (blocks of BLOCK rows whose component-wise minimum is outside
     are skipped), followed by a short scan of the score ties.
  3. If none is inside the box: an exhaustive scan of all candidates for the
     unconstrained objective (degraded).

Tolerances (module constants): a torque is inside the box if it overshoots a bound by at
most TOL_BOX_NM; two objectives tie if they differ by at most tie_tol(w, tau_d) =
TOL_TIE + TIE_REL * sum_i w_i |tau_d,i| (the relative term covers rounding of huge
demands); two penalties tie within TOL_PEN. Torque vectors are merged when they agree
to KEY_QUANTUM_NM on every axis (distinct achievable torques are far further apart).

Non-finite demand: ``solve`` returns u = 0 (all usable jets off), sets ``rejected`` and
leaves ``objective`` = NaN; it never raises in the cycle.

Fault tolerance off (paper figure 5): the allocator assumes every jet nominal (usable,
eta = 1, nothing stuck, nothing inhibited) whatever the health says; the jet driver still
applies the ground inhibit mask.
"""
from __future__ import annotations

import threading
import time
import weakref
from collections import OrderedDict, deque

import numpy as np
from numba import njit

from fsw.health import DEGRADED, FAILED_OFF, STUCK_ON, JetHealth
from fsw.params import Param

N_AXES = 3
N_OCTANTS = 8
TOL_BOX_NM = 1e-9          # allowed overshoot of a sign-box bound [N m]
TOL_TIE = 1e-9             # absolute objective tie tolerance [N m]
TIE_REL = 32 * np.finfo(float).eps   # per unit of sum_i w_i |tau_d,i|: rounding of huge demands
TOL_PEN = 1e-9             # penalty tie tolerance [N m]
KEY_QUANTUM_NM = 1e-7      # grid on which identical torque vectors are merged [N m]
BLOCK = 16                 # rows per block of the block-skipping scan
CACHE_MAX_CONFIGS = 16     # health configurations whose tables are kept
STATUS_OK, STATUS_DEGRADED, STATUS_REJECTED = 0, 1, 2
ZERO3 = np.zeros(N_AXES)


PARAMS: list[Param] = [
    Param("allocator.w_roll", 0.0, 1e3, "-", "weight of the roll-torque error in the objective"),
    Param("allocator.w_pitch", 0.0, 1e3, "-", "weight of the pitch-torque error in the objective"),
    Param("allocator.w_yaw", 0.0, 1e3, "-", "weight of the yaw-torque error in the objective"),
    Param("allocator.penalty_per_N", 0.0, 10.0, "N m/N",
          "firing penalty per newton of jet thrust: c_k = penalty_per_N * thrust_k"),
    Param("allocator.fault_tolerance", 0.0, 1.0, "-",
          "1: allocate with the FDIR jet health; 0: assume every jet nominal (paper fig. 5)",
          integer=True),
]


def tie_tol(w: np.ndarray, tau_d: np.ndarray) -> float:
    """Objective tie tolerance [N m] for demand tau_d (see module docstring)."""
    return TOL_TIE + TIE_REL * float(np.sum(np.abs(w) * np.abs(tau_d)))


# ---------------------------------------------------------------- the model from health
def effective_model(T: np.ndarray, thrust: np.ndarray, health: JetHealth | None,
                    penalty_per_N: float, fault_tolerance: bool = True):
    """The allocation model for a health configuration (spec 20-fsw.md):
    (usable bool[n], columns eta_k T_k (3, n) with zeros for unusable jets,
    stuck-on bias b (3,), per-jet penalty c (n,)). Health is ignored when fault
    tolerance is off or health is None."""
    T = np.asarray(T, dtype=float)
    thrust = np.asarray(thrust, dtype=float)
    n = T.shape[1]
    c = float(penalty_per_N) * thrust
    if not fault_tolerance or health is None:
        return np.ones(n, dtype=bool), T.copy(), np.zeros(N_AXES), c
    if len(health.state) != n:
        raise ValueError(f"health: {len(health.state)} jets, torque matrix has {n}")
    usable = health.usable()
    eta = np.where(health.state == DEGRADED, health.eta, 1.0)
    cols = np.where(usable[None, :], T * eta[None, :], 0.0)
    stuck = health.state == STUCK_ON
    b = T[:, stuck].sum(axis=1) if stuck.any() else np.zeros(N_AXES)
    return usable, cols, b, c


def _validate_problem(T, thrust, w, penalty_per_N):
    T = np.asarray(T, dtype=float)
    thrust = np.asarray(thrust, dtype=float)
    if T.ndim != 2 or T.shape[0] != N_AXES or T.shape[1] > 62:
        raise ValueError(f"torque_matrix_Nm: expected shape (3, n<=62), got {T.shape}")
    if thrust.shape != (T.shape[1],):
        raise ValueError(f"thrust_N: expected shape ({T.shape[1]},), got {thrust.shape}")
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(thrust))):
        raise ValueError("torque_matrix_Nm/thrust_N: must be finite")
    if np.any(thrust < 0):
        raise ValueError("thrust_N: must be >= 0")
    w = np.asarray(w, dtype=float)
    if w.shape != (N_AXES,) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"w: expected 3 finite weights >= 0, got {w!r}")
    if not np.isscalar(penalty_per_N) or not np.isfinite(penalty_per_N) or penalty_per_N < 0:
        raise ValueError(f"c (penalty per N): expected a finite scalar >= 0, got {penalty_per_N!r}")
    return T, thrust, w, float(penalty_per_N)


# ---------------------------------------------------------------- table construction
# The tables are rebuilt on every new health configuration, by nogil numba kernels over
# preallocated work buffers (a background thread can run them while the control thread
# keeps solving):
#  - group identical columns;
#  - enumerate the multiplicity vectors group by group, keeping the list of distinct
#    partial torques sorted by phi = a . tau (a generic direction): adding j times a group
#    column shifts phi by a constant, so each group is a sequential merge of sorted lists,
#    and torques equal on the KEY_QUANTUM_NM grid, whose phi differ by less than a small
#    window, are found (and merged) by comparing the keys of the few phi-neighbours;
#  - per octant a stable sort by score: one counting pass into about 2 buckets per row
#    (a monotone fixed-point image of the score), each bucket then finished exactly by an
#    insertion sort on the float score (buckets hold ~1 row; a crowded one is merge sorted).
PHI_DIR = (1.0, 0.7548776662466927, 0.5698402909980532)   # generic direction for phi = a . tau
SORT_BUCKETS_MAX = 1 << 17  # buckets of the octant tables' one-pass bucket sort
WORKSPACE_ROWS = 49152     # initial work buffers: >= the nominal 46,656 combinations, so the
                           # paper's configurations (<= 39,936 distinct torques) never grow them
ROW = np.dtype([("t0", np.float64), ("t1", np.float64), ("t2", np.float64),
                ("pen", np.float64), ("pat", np.int64), ("phi", np.float64)])   # one candidate


@njit(cache=True, nogil=True)
def _group_columns(cols, usable, c, quantum):
    """Groups of identical effective columns (equal on the quantum grid) in order of their
    lowest jet; the members of a group sorted by (penalty, jet) so that j members on are
    the j cheapest, lowest-numbered. Zero columns (eta = 0) never help and are left out.
    Returns g_col (G, 3), g_m (G,), g_cum_pen (G, m_max + 1), g_cum_pat (G, m_max + 1)."""
    n = cols.shape[1]
    key = np.zeros((n, 3), dtype=np.int64)
    gid = -np.ones(n, dtype=np.int64)
    lead = np.empty(n, dtype=np.int64)
    G = 0
    for k in range(n):
        if not usable[k]:
            continue
        for i in range(3):
            key[k, i] = np.int64(np.rint(cols[i, k] / quantum))
        if key[k, 0] == 0 and key[k, 1] == 0 and key[k, 2] == 0:
            continue
        for g in range(G):
            ld = lead[g]
            if key[ld, 0] == key[k, 0] and key[ld, 1] == key[k, 1] and key[ld, 2] == key[k, 2]:
                gid[k] = g
                break
        if gid[k] < 0:
            lead[G] = k
            gid[k] = G
            G += 1
    g_m = np.zeros(G, dtype=np.int64)
    for k in range(n):
        if gid[k] >= 0:
            g_m[gid[k]] += 1
    m_max = 0
    for g in range(G):
        m_max = max(m_max, g_m[g])
    g_col = np.zeros((G, 3))
    g_cum_pen = np.zeros((G, m_max + 1))
    g_cum_pat = np.zeros((G, m_max + 1), dtype=np.int64)
    members = np.empty(m_max, dtype=np.int64)
    for g in range(G):
        m = 0
        for k in range(n):                 # ascending jet, then a stable sort by penalty
            if gid[k] == g:
                q = m
                while q > 0 and c[members[q - 1]] > c[k]:
                    members[q] = members[q - 1]
                    q -= 1
                members[q] = k
                m += 1
        for i in range(3):
            g_col[g, i] = cols[i, members[0]]
        for j in range(1, m + 1):
            k = members[j - 1]
            g_cum_pen[g, j] = g_cum_pen[g, j - 1] + c[k]
            g_cum_pat[g, j] = g_cum_pat[g, j - 1] | (np.int64(1) << k)
    return g_col, g_m, g_cum_pen, g_cum_pat


@njit(cache=True, nogil=True)
def _same_key(a, b, inv_q):
    return (np.floor(a.t0 * inv_q + 0.5) == np.floor(b.t0 * inv_q + 0.5)
            and np.floor(a.t1 * inv_q + 0.5) == np.floor(b.t1 * inv_q + 0.5)
            and np.floor(a.t2 * inv_q + 0.5) == np.floor(b.t2 * inv_q + 0.5))


@njit(cache=True, nogil=True)
def _merge_shifted(cur, ncur, base, nbase, c0, c1, c2, dpen, dpat, dphi, out, inv_q, tol_pen, win):
    """out = cur merged with (base + the shift), both sorted by phi; a row whose key equals
    that of an earlier output row within the phi window is merged into it (smallest
    (penalty, pattern) kept; the earlier row keeps its phi, so the output stays sorted).
    Returns the output length, or -1 if out is too short."""
    i = 0
    k = 0
    n = 0
    cap = out.shape[0]
    while i < ncur or k < nbase:
        if n >= cap:
            return -1                       # the caller grows the buffers and retries
        if k >= nbase or (i < ncur and cur[i].phi <= base[k].phi + dphi):
            out[n] = cur[i]
            i += 1
        else:
            out[n].t0 = base[k].t0 + c0
            out[n].t1 = base[k].t1 + c1
            out[n].t2 = base[k].t2 + c2
            out[n].pen = base[k].pen + dpen
            out[n].pat = base[k].pat | dpat
            out[n].phi = base[k].phi + dphi
            k += 1
        e = out[n]
        lim = e.phi - win
        o = n - 1
        dup = False
        while o >= 0 and out[o].phi >= lim:
            if _same_key(out[o], e, inv_q):
                d = e.pen - out[o].pen
                if d < -tol_pen or (d <= tol_pen and e.pat < out[o].pat):
                    out[o].t0 = e.t0
                    out[o].t1 = e.t1
                    out[o].t2 = e.t2
                    out[o].pen = e.pen
                    out[o].pat = e.pat
                dup = True
                break
            o -= 1
        if not dup:
            n += 1
    return n


@njit(cache=True, nogil=True)
def _enumerate_merged(g_col, g_m, g_cum_pen, g_cum_pat, bias, quantum, tol_pen,
                      ra, rb, rc, tau, pen, pat):
    """Every distinct torque b + sum_g j_g g_col[g] (0 <= j_g <= g_m[g]) with the smallest
    (penalty, pattern) of the multiplicity vectors giving it (group g, j members on: penalty
    g_cum_pen[g, j], bits g_cum_pat[g, j]). Torques are equal when equal on the quantum
    grid. Writes the n candidates to tau/pen/pat[:n]; returns (number of multiplicity
    vectors, n), n = -1 if the buffers are too short. Work buffers ra, rb, rc (ROW) and
    tau/pen/pat need n rows (the list of distinct partial sums never shrinks)."""
    G = g_col.shape[0]
    a0, a1, a2 = PHI_DIR
    asum = abs(a0) + abs(a1) + abs(a2)
    span = abs(a0 * bias[0]) + abs(a1 * bias[1]) + abs(a2 * bias[2])
    M = 1
    for g in range(G):
        M *= g_m[g] + 1
        span += g_m[g] * (abs(a0 * g_col[g, 0]) + abs(a1 * g_col[g, 1]) + abs(a2 * g_col[g, 2]))
    # equal keys: |tau_i - tau'_i| < quantum, so |phi - phi'| < quantum * asum per row, plus
    # one such error per group for the kept phi of merged rows, plus rounding of phi sums
    win = 4.0 * (G + 2) * quantum * asum + 1e-12 * (1.0 + span) * (G + 2)
    inv_q = 1.0 / quantum
    ra[0].t0 = bias[0]
    ra[0].t1 = bias[1]
    ra[0].t2 = bias[2]
    ra[0].pen = 0.0
    ra[0].pat = 0
    ra[0].phi = a0 * bias[0] + a1 * bias[1] + a2 * bias[2]
    bufs = (ra, rb, rc)
    ib = 0                                  # buffer of the distinct torques so far
    nbase = 1
    for g in range(G):
        ic = ib                             # adding j = 1, 2, ... members: cur, then out
        ncur = nbase
        o1 = (ib + 1) % 3
        o2 = (ib + 2) % 3
        io = o1
        for j in range(1, g_m[g] + 1):
            c0 = j * g_col[g, 0]
            c1 = j * g_col[g, 1]
            c2 = j * g_col[g, 2]
            dphi = a0 * c0 + a1 * c1 + a2 * c2
            ncur = _merge_shifted(bufs[ic], ncur, bufs[ib], nbase, c0, c1, c2, g_cum_pen[g, j],
                                  g_cum_pat[g, j], dphi, bufs[io], inv_q, tol_pen, win)
            if ncur < 0:
                return M, -1
            ic = io
            io = o2 if io == o1 else o1
        ib = ic
        nbase = ncur
    base = bufs[ib]
    if nbase > tau.shape[0]:
        return M, -1
    for r in range(nbase):
        tau[r, 0] = base[r].t0
        tau[r, 1] = base[r].t1
        tau[r, 2] = base[r].t2
        pen[r] = base[r].pen
        pat[r] = base[r].pat
    return M, nbase


@njit(cache=True, nogil=True)
def _bucket_sort(ka, ia, lo, hi, kmin, kmax, kb, ib, count):
    """Stable ascending sort of rows lo:hi of (key ka, payload ia) into kb/ib[lo:hi]: one
    counting pass on the bucket floor((k - kmin) * scale), which is monotone in k, so only
    rows of one bucket can be out of order; an insertion sort finishes exactly (a merge sort
    if the buckets turn out crowded)."""
    m = hi - lo
    if m <= 0:
        return
    nb = 2
    while nb < m and nb < SORT_BUCKETS_MAX:
        nb *= 2
    top = nb - 1
    scale = top / (kmax - kmin) if kmax > kmin else 0.0
    if not np.isfinite(scale):
        scale = 0.0
    for d in range(nb + 1):
        count[d] = 0
    for i in range(lo, hi):
        count[min(np.int64((ka[i] - kmin) * scale), top) + 1] += 1
    for d in range(nb):
        count[d + 1] += count[d]
    for i in range(lo, hi):
        b = min(np.int64((ka[i] - kmin) * scale), top)
        j = lo + count[b]
        count[b] += 1
        kb[j] = ka[i]
        ib[j] = ia[i]
    budget = 8 * m + 64                     # element moves before giving up on insertion
    for q in range(lo + 1, hi):             # stable insertion sort (strict >)
        kq = kb[q]
        if kb[q - 1] <= kq:
            continue
        iq = ib[q]
        p = q
        while p > lo and kb[p - 1] > kq:
            kb[p] = kb[p - 1]
            ib[p] = ib[p - 1]
            p -= 1
        kb[p] = kq
        ib[p] = iq
        budget -= q - p
        if budget < 0:                      # crowded buckets: merge sort the rest
            order = np.argsort(ka[lo:hi], kind="mergesort")
            for t in range(m):
                kb[lo + t] = ka[lo + order[t]]
                ib[lo + t] = ia[lo + order[t]]
            return


@njit(cache=True, nogil=True)
def _octant_members(tau, n, tol_box, octm):
    """Octant membership of candidates 0:n: a candidate belongs to octant o (bit i set:
    tau_d,i < 0, s_i = -1) if it can lie in that octant's sign box, s_i tau_i >= -tol_box
    on every axis; one with no (numerically) zero component belongs to exactly one.
    Writes octm[r] (its octant, or -1 if several) and returns start (9,): octant o gets
    rows start[o]:start[o+1] of the tables."""
    start = np.zeros(9, dtype=np.int64)
    for r in range(n):
        t0, t1, t2 = tau[r, 0], tau[r, 1], tau[r, 2]
        if abs(t0) > tol_box and abs(t1) > tol_box and abs(t2) > tol_box:
            o = np.int64(t0 < 0.0) | (np.int64(t1 < 0.0) << 1) | (np.int64(t2 < 0.0) << 2)
            octm[r] = o
            start[o + 1] += 1
        else:                               # on or near a coordinate plane: several octants
            octm[r] = -1
            for o in range(8):
                a0 = -t0 >= -tol_box if (o & 1) else t0 >= -tol_box
                a1 = -t1 >= -tol_box if (o & 2) else t1 >= -tol_box
                a2 = -t2 >= -tol_box if (o & 4) else t2 >= -tol_box
                if a0 and a1 and a2:
                    start[o + 1] += 1
    for o in range(8):
        start[o + 1] += start[o]
    return start


@njit(cache=True, nogil=True)
def _octant_fill(tau, pen, pat, n, w, tol_box, octm, start, ka, ia, kb, ib, count,
                 tau_out, pen_out, pat_out, X, S, P, R, bstart, bmin):
    """The tables of one configuration from its n distinct candidates (tau, pen, pat) and
    their octant membership (_octant_members): candidates copied to tau/pen/pat_out, and
    per octant o, rows start[o]:start[o+1] of X (x = s * tau), S (score), P (penalty) and
    R (index into the candidates) sorted by descending score sum_i w_i s_i tau_i - pen
    (stable: ties keep candidate order); bmin[bstart[o] + b] is the component-wise minimum
    of x over block b (BLOCK rows) of octant o. Work buffers: ka, kb (float64) and ia, ib
    (int64) of >= start[8] rows, count (int64) of SORT_BUCKETS_MAX + 1. The outputs are
    allocated by the caller (numpy memory is recycled, fresh pages cost more than the
    sort)."""
    for r in range(n):
        tau_out[r, 0] = tau[r, 0]
        tau_out[r, 1] = tau[r, 1]
        tau_out[r, 2] = tau[r, 2]
        pen_out[r] = pen[r]
        pat_out[r] = pat[r]
    pos = start[:8].copy()
    kmin = np.full(8, np.inf)
    kmax = np.full(8, -np.inf)
    for r in range(n):                      # key = -score, per octant in candidate order
        t0, t1, t2 = tau[r, 0], tau[r, 1], tau[r, 2]
        o1 = octm[r]
        if o1 >= 0:
            o = np.int64(o1)                # signs by arithmetic: no unpredictable branches
            s0 = 1.0 - 2.0 * (o & 1)
            s1 = 1.0 - (o & 2)
            s2 = 1.0 - 0.5 * (o & 4)
            k = pen[r] - (w[0] * s0 * t0 + w[1] * s1 * t1 + w[2] * s2 * t2)
            j = pos[o]
            pos[o] = j + 1
            ka[j] = k
            ia[j] = r
            kmin[o] = min(kmin[o], k)
            kmax[o] = max(kmax[o], k)
            continue
        for o in range(8):
            a0 = -t0 >= -tol_box if (o & 1) else t0 >= -tol_box
            a1 = -t1 >= -tol_box if (o & 2) else t1 >= -tol_box
            a2 = -t2 >= -tol_box if (o & 4) else t2 >= -tol_box
            if a0 and a1 and a2:
                k = pen[r] - (w[0] * (-1.0 if (o & 1) else 1.0) * t0 + w[1] * (-1.0 if (o & 2) else 1.0) * t1
                              + w[2] * (-1.0 if (o & 4) else 1.0) * t2)
                j = pos[o]
                pos[o] = j + 1
                ka[j] = k
                ia[j] = r
                kmin[o] = min(kmin[o], k)
                kmax[o] = max(kmax[o], k)
    for o in range(8):
        _bucket_sort(ka, ia, start[o], start[o + 1], kmin[o], kmax[o], kb, ib, count)
    for o in range(8):
        s0 = -1.0 if (o & 1) else 1.0
        s1 = -1.0 if (o & 2) else 1.0
        s2 = -1.0 if (o & 4) else 1.0
        m0 = m1 = m2 = np.inf
        blk = bstart[o]
        for j in range(start[o], start[o + 1]):
            r = ib[j]
            x0 = s0 * tau[r, 0]
            x1 = s1 * tau[r, 1]
            x2 = s2 * tau[r, 2]
            X[j, 0] = x0
            X[j, 1] = x1
            X[j, 2] = x2
            S[j] = -kb[j]
            P[j] = pen[r]
            R[j] = r
            # blocks of BLOCK consecutive rows with their component-wise minimum of x
            m0 = min(m0, x0)
            m1 = min(m1, x1)
            m2 = min(m2, x2)
            if (j - start[o]) % BLOCK == BLOCK - 1 or j == start[o + 1] - 1:
                bmin[blk, 0] = m0
                bmin[blk, 1] = m1
                bmin[blk, 2] = m2
                blk += 1
                m0 = m1 = m2 = np.inf


class _Workspace:
    """Work buffers of the table build, kept between builds (grown on demand), so a rebuild
    touches memory that is already mapped. One per building thread."""

    def __init__(self, rows: int = WORKSPACE_ROWS) -> None:
        self.rows = 0
        self.octrows = 0
        self.count = np.zeros(SORT_BUCKETS_MAX + 1, dtype=np.int64)
        self.grow(rows)

    def grow(self, rows: int) -> None:
        """Room for ``rows`` distinct candidates (and 5/4 as many octant rows)."""
        if rows <= self.rows:
            return
        rows = max(rows, 2 * self.rows)
        self.ra = np.zeros(rows, dtype=ROW)
        self.rb = np.zeros(rows, dtype=ROW)
        self.rc = np.zeros(rows, dtype=ROW)
        self.tau = np.zeros((rows, N_AXES))
        self.pen = np.zeros(rows)
        self.pat = np.zeros(rows, dtype=np.int64)
        self.octm = np.zeros(rows, dtype=np.int8)
        for a in (self.ra, self.rb, self.rc, self.tau, self.pen, self.pat, self.octm, self.count):
            a.fill(0)                         # map the pages now, not inside a timed build
        self.rows = rows
        self.grow_octants(rows + rows // 4)

    def grow_octants(self, rows: int) -> None:
        """Room for ``rows`` octant rows (sort keys and payloads)."""
        if rows <= self.octrows:
            return
        rows = max(rows, 2 * self.octrows)
        self.ka = np.zeros(rows)
        self.kb = np.zeros(rows)
        self.ia = np.zeros(rows, dtype=np.int64)
        self.ib = np.zeros(rows, dtype=np.int64)
        for a in (self.ka, self.kb, self.ia, self.ib):
            a.fill(0)
        self.octrows = rows

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.ra, self.rb, self.rc, self.tau, self.pen, self.pat,
                                      self.octm, self.ka, self.kb, self.ia, self.ib, self.count))


class _Tables:
    """Candidate tables of one configuration: the health model they were built for
    (usable, cols, bias), the objective (w, per-jet penalty c) and the octant tables."""
    __slots__ = ("tau", "pen", "pat", "start", "X", "S", "P", "R", "bstart", "bmin", "scratch",
                 "bias", "usable", "cols", "w", "n_raw", "build_s")

    def __init__(self, tau, pen, pat, start, X, S, P, R, bstart, bmin, usable, cols, bias, w,
                 n_raw, build_s):
        self.tau, self.pen, self.pat = tau, pen, pat
        self.start, self.X, self.S, self.P, self.R = start, X, S, P, R
        self.bstart, self.bmin = bstart, bmin
        self.scratch = np.empty(len(pen))     # objective buffer of the exhaustive scans
        self.usable, self.cols, self.bias, self.w = usable, cols, bias, w
        self.n_raw = n_raw                    # multiplicity vectors enumerated
        self.build_s = build_s                # build time [s]

    @property
    def nbytes(self) -> int:
        return sum(getattr(self, k).nbytes for k in ("tau", "pen", "pat", "start", "X", "S", "P",
                                                      "R", "bstart", "bmin", "scratch"))


def _build_tables(usable, cols, bias, c, w, ws: _Workspace) -> _Tables:
    """Groups of identical effective columns -> distinct torques -> octant tables. The
    heavy work is in nogil kernels over the workspace ``ws`` (one per building thread)."""
    t0 = time.perf_counter()
    usable = np.ascontiguousarray(usable, dtype=np.bool_)
    cols = np.ascontiguousarray(cols, dtype=np.float64)
    bias = np.ascontiguousarray(bias, dtype=np.float64)
    w = np.ascontiguousarray(w, dtype=np.float64)
    g_col, g_m, g_cum_pen, g_cum_pat = _group_columns(
        cols, usable, np.ascontiguousarray(c, dtype=np.float64), KEY_QUANTUM_NM)
    while True:
        n_raw, n = _enumerate_merged(g_col, g_m, g_cum_pen, g_cum_pat, bias, KEY_QUANTUM_NM,
                                     TOL_PEN, ws.ra, ws.rb, ws.rc, ws.tau, ws.pen, ws.pat)
        if n >= 0:
            break
        ws.grow(min(n_raw, 4 * ws.rows))       # never more than n_raw distinct torques
    start = _octant_members(ws.tau, n, TOL_BOX_NM, ws.octm)
    total = int(start[8])
    ws.grow_octants(total)
    bstart = np.zeros(9, dtype=np.int64)
    bstart[1:] = np.cumsum((np.diff(start) + BLOCK - 1) // BLOCK)
    tau, pen, pat = np.empty((n, N_AXES)), np.empty(n), np.empty(n, dtype=np.int64)
    X, S, P, R = np.empty((total, N_AXES)), np.empty(total), np.empty(total), np.empty(total, dtype=np.int64)
    bmin = np.empty((int(bstart[8]), N_AXES))
    _octant_fill(ws.tau, ws.pen, ws.pat, n, w, TOL_BOX_NM, ws.octm, start, ws.ka, ws.ia, ws.kb,
                 ws.ib, ws.count, tau, pen, pat, X, S, P, R, bstart, bmin)
    return _Tables(tau, pen, pat, start, X, S, P, R, bstart, bmin, usable.copy(), cols.copy(),
                   bias.copy(), w.copy(), n_raw, time.perf_counter() - t0)


# ---------------------------------------------------------------- the query
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
def _solve_kernel(tau_d, w, start, X, S, P, R, bstart, bmin, cand_tau, cand_pen, cand_pat, scratch,
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
        lim = best_obj + tol
        min_pen = np.inf
        for r in range(m):
            if scratch[r] <= lim and cand_pen[r] < min_pen:
                min_pen = cand_pen[r]
        for r in range(m):
            if scratch[r] <= lim and cand_pen[r] <= min_pen + tol_pen:
                if chosen < 0 or cand_pat[r] < cand_pat[chosen]:
                    chosen = r
    _write_answer(chosen, d0, d1, d2, w, cand_tau, cand_pen, cand_pat, ZERO3, u_out, tau_out, obj_out)
    return status


@njit(cache=True)
def _solve_shifted_kernel(tau_d, w, cand_tau, cand_pen, cand_pat, scratch, forbid, delta,
                          tol_box, tol_tie, tie_rel, tol_pen, u_out, tau_out, obj_out):
    """One allocation over the candidates with no bit of ``forbid``, whose torque is
    cand_tau + delta (a bias the tables were not built with): exhaustive scan with the
    sign box, else without it (degraded). Same tie-break and outputs as _solve_kernel."""
    d0, d1, d2 = tau_d[0], tau_d[1], tau_d[2]
    if not (np.isfinite(d0) and np.isfinite(d1) and np.isfinite(d2)):
        return _reject(u_out, obj_out)
    lo0, hi0 = (-tol_box, d0 + tol_box) if d0 >= 0.0 else (d0 - tol_box, tol_box)
    lo1, hi1 = (-tol_box, d1 + tol_box) if d1 >= 0.0 else (d1 - tol_box, tol_box)
    lo2, hi2 = (-tol_box, d2 + tol_box) if d2 >= 0.0 else (d2 - tol_box, tol_box)
    tol = tol_tie + tie_rel * (w[0] * abs(d0) + w[1] * abs(d1) + w[2] * abs(d2))
    m = cand_pen.shape[0]
    status = 0
    for attempt in range(2):              # 0: inside the sign box; 1: anywhere (degraded)
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
    lim = best_obj + tol
    min_pen = np.inf
    for r in range(m):
        if scratch[r] <= lim and cand_pen[r] < min_pen:
            min_pen = cand_pen[r]
    chosen = -1
    for r in range(m):
        if scratch[r] <= lim and cand_pen[r] <= min_pen + tol_pen:
            if chosen < 0 or cand_pat[r] < cand_pat[chosen]:
                chosen = r
    _write_answer(chosen, d0, d1, d2, w, cand_tau, cand_pen, cand_pat, delta, u_out, tau_out, obj_out)
    return status


class _Rebuilder:
    """Builds tables on a background daemon thread (the numba kernels release the GIL, so
    the control thread keeps running). Jobs: the newest reconfiguration request first, then
    the pre-build queue. Results wait in ``done`` (dict, key -> _Tables) until the
    allocator takes them; the control thread never waits on this object's lock."""

    def __init__(self) -> None:
        self._cv = threading.Condition()
        self._request = None                  # (key, usable, cols, bias, c, w): newest wins
        self._queue: deque = deque()          # pre-builds, same tuples
        self._busy = False
        self._stop = False
        self._ws = _Workspace()
        self._gate = threading.Event()        # cleared: jobs wait (deterministic tests)
        self._gate.set()
        self.done: dict = {}
        self.builds = 0
        self._thread = threading.Thread(target=self._run, name="allocator-rebuild", daemon=True)
        self._thread.start()

    def submit(self, job) -> None:
        with self._cv:
            self._request = job
            self._cv.notify()

    def queue(self, jobs) -> None:
        with self._cv:
            self._queue.extend(jobs)
            self._cv.notify()

    def cancel_queue(self) -> None:
        with self._cv:
            self._queue.clear()
            self._request = None

    def hold(self) -> None:
        """Jobs not yet started wait until release() (tests: a deterministic interim)."""
        self._gate.clear()

    def release(self) -> None:
        self._gate.set()

    def idle(self) -> bool:
        return not self._busy and self._request is None and not self._queue

    def wait_idle(self, timeout_s: float) -> bool:
        with self._cv:
            return self._cv.wait_for(self.idle, timeout_s)

    def close(self, timeout_s: float = 5.0) -> None:
        with self._cv:
            self._stop = True
            self._request = None
            self._queue.clear()
            self._cv.notify_all()
        self._gate.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        # same OS priority as the caller on purpose: a deprioritised thread can be preempted
        # while it briefly holds the GIL between kernels, stalling the control thread
        while True:
            with self._cv:
                while not self._stop and self._request is None and not self._queue:
                    self._cv.wait()
                if self._stop:
                    return
                if self._request is not None:
                    job, self._request = self._request, None
                else:
                    job = self._queue.popleft()
                self._busy = True
            self._gate.wait()
            if self._stop:
                return
            key, usable, cols, bias, c, w = job
            try:
                tables = _build_tables(usable, cols, bias, c, w, self._ws)
            except Exception as e:  # noqa: BLE001 - handed to the allocator, never lost
                tables = e
            with self._cv:
                self.done[key] = tables
                self.builds += 1
                self._busy = False
                self._cv.notify_all()


# ---------------------------------------------------------------- the allocator
class Allocator:
    """Exact fault-tolerant discrete allocator. ``solve`` is allocation-free and bounded
    (a scan of at most the distinct achievable torques, ~13,000 for the nominal jets).

    Reconfiguration (``set_health``, ``set_params``, ``set_fault_tolerance``) fetches the
    new configuration's tables from a cache or builds them:

    - ``async_rebuild=False`` (default; batch, lockstep SIL): the build runs in the call
      (a few ms), so every answer is the exact optimum of the current model and a lockstep
      run equals the batch run bit for bit.
    - ``async_rebuild=True`` (real time): the build runs on a background thread and the call
      returns at once. Until the first ``solve`` after the build completes
      (``reconfig_pending`` is True, ``interim`` True for the answers meanwhile), ``solve``
      answers with the previous tables under a SAFE interim model: every jet whose treatment
      changed (newly failed, inhibited, stuck, degraded with another eta, or back from
      stuck) is kept off, and the stuck-on bias is the new one (``_solve_shifted_kernel``
      when it differs). The interim answer never fires a jet the new health forbids, its
      tau_B and objective are those of the new model for the returned u, and it is the
      exact optimum (spec tie-break, sign box, degraded fallback) over the previous
      configuration's candidates that avoid the changed jets. It is NOT necessarily the
      optimum of the new model: combinations that need a changed jet, or a twin of a changed
      jet (the previous tables keep one representative pattern per torque), are missing, and
      after ``set_params`` the previous weights and penalties apply until the switch.
      ``prebuild_single_faults`` (default: on when async) builds, in the background at
      start-up and after every parameter change, the tables of every single jet failed off
      from the nominal health, so the most likely first fault switches at once.
    """

    PARAMS = PARAMS

    def __init__(self, torque_matrix_Nm: np.ndarray, thrust_N: np.ndarray,
                 params: dict[str, float], *, async_rebuild: bool = False,
                 prebuild_single_faults: bool | None = None) -> None:
        T, thrust, _, _ = _validate_problem(torque_matrix_Nm, thrust_N, np.ones(3), 0.0)
        self._T = T
        self._thrust = thrust
        self.n_jets = T.shape[1]
        self.async_rebuild = bool(async_rebuild)
        self.prebuild_single_faults = (self.async_rebuild if prebuild_single_faults is None
                                       else bool(prebuild_single_faults))
        self._ws = _Workspace()
        self._rebuilder: _Rebuilder | None = None
        self._finalizer = None
        self._cache: OrderedDict = OrderedDict()
        self._prebuilt: dict = {}                  # single faults, never evicted
        self._prebuild_keys: set = set()
        self._gen = 0                              # parameter generation (part of table keys)
        self._health = JetHealth(self.n_jets)
        self.u = np.zeros(self.n_jets, dtype=np.uint8)     # reused output
        self.tau_B = np.zeros(N_AXES)                         # modelled achieved torque [N m]
        self._obj = np.zeros(1)
        self.objective = float("nan")
        self.degraded = False
        self.rejected = False
        self.rebuild_time_s = 0.0          # build time of the tables adopted last [s]
        self.tables_from_cache = False     # the last reconfiguration found its tables ready
        self.reconfig_pending = False      # async: solving with the interim model
        self.interim = False               # the last answer came from the interim model
        self.tables_version = 0            # +1 at every switch of tables
        self.reconfig_latency_s = 0.0      # request -> switch of the last reconfiguration [s]
        self._active_key = None
        self._target_key = None
        self._target_job = None
        self._t_request = 0.0
        self._forbid = 0
        self._delta = np.zeros(N_AXES)
        self._shifted = False
        self._tables: _Tables | None = None
        async_now, self.async_rebuild = self.async_rebuild, False   # first tables: built here
        self.set_params(params)
        # warm-up: compile/load the kernels and run every branch once
        self.solve(np.array([100.0, -50.0, 0.0]))
        self.solve(np.array([np.nan, 0.0, 0.0]))
        t = self._tables
        _solve_shifted_kernel(np.array([1.0, -2.0, 3.0]), t.w, t.tau, t.pen, t.pat, t.scratch,
                              np.int64(1), np.ones(N_AXES), TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                              self.u, self.tau_B, self._obj)
        self.solve(np.array([100.0, -50.0, 0.0]))
        self.rejected = False
        self.async_rebuild = async_now
        if self.async_rebuild:
            self._rebuilder = _Rebuilder()
            self._finalizer = weakref.finalize(self, self._rebuilder.close, 1.0)
            self._queue_prebuilds()

    # -- configuration (not in the cycle's hot path)
    def set_params(self, params: dict[str, float]) -> None:
        """Validate the allocator.* parameters; the tables of every configuration are
        rebuilt with them (async: the previous tables and objective serve meanwhile)."""
        vals = {}
        for p in self.PARAMS:
            if p.name not in params:
                raise ValueError(f"{p.name}: missing")
            vals[p.name] = p.check(params[p.name])
        self.w = np.array([vals["allocator.w_roll"], vals["allocator.w_pitch"],
                           vals["allocator.w_yaw"]])
        self.penalty_per_N = vals["allocator.penalty_per_N"]
        self.fault_tolerance = bool(vals["allocator.fault_tolerance"])
        self._gen += 1
        self._cache.clear()
        self._prebuilt.clear()
        if self._rebuilder is not None:
            self._rebuilder.cancel_queue()
            self._queue_prebuilds()
        self._activate()

    def set_health(self, health: JetHealth) -> None:
        """Adopt a new health picture (see the class docstring for sync/async). Health is
        stored but not used while fault tolerance is off."""
        if not isinstance(health, JetHealth) or len(health.state) != self.n_jets:
            raise ValueError(f"health: expected a JetHealth of {self.n_jets} jets")
        self._health = health.copy()
        self._activate()

    def set_fault_tolerance(self, on: bool) -> None:
        self.fault_tolerance = bool(on)
        self._activate()

    def poll(self) -> bool:
        """Async: switch to finished tables now (``solve`` does this itself) and file
        finished pre-builds; True if the switch happened."""
        switched = self.reconfig_pending and self._try_switch()
        self._collect()
        return switched

    def wait_idle(self, timeout_s: float = 5.0) -> bool:
        """Async (tests, ground tools; never in the cycle): wait until the background
        builder has nothing left to do. True if idle in time. Sync mode: True."""
        return self._rebuilder is None or self._rebuilder.wait_idle(timeout_s)

    def close(self) -> None:
        """Stop the background builder (async); the allocator keeps solving with the
        tables it has (a pending reconfiguration is then built synchronously)."""
        if self._rebuilder is not None:
            self._finalizer()
            self._rebuilder = None
        self.async_rebuild = False
        if self.reconfig_pending:
            self._activate()

    def __enter__(self) -> "Allocator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def builder_alive(self) -> bool:
        return self._rebuilder is not None and self._rebuilder.alive

    @property
    def n_candidates(self) -> int:
        """Distinct achievable torque vectors of the active configuration."""
        return len(self._tables.pen)

    @property
    def tables_nbytes(self) -> dict[str, int]:
        """Memory held by tables [bytes]: active, LRU cache, pre-built, work buffers."""
        self._collect()
        ws = self._ws.nbytes + (self._rebuilder._ws.nbytes if self._rebuilder is not None else 0)
        return {"active": self._tables.nbytes,
                "cache": sum(t.nbytes for t in self._cache.values()),
                "prebuilt": sum(t.nbytes for t in self._prebuilt.values()),
                "workspace": ws}

    def _model_key(self):
        health = self._health if self.fault_tolerance else JetHealth(self.n_jets)
        return health, (self._gen, health.key())   # fault tolerance off: the nominal tables

    def _job(self, key, health):
        usable, cols, bias, c = effective_model(self._T, self._thrust, health, self.penalty_per_N)
        return (key, usable, cols, bias, c, self.w.copy())

    def _queue_prebuilds(self) -> None:
        if not self.prebuild_single_faults or self._rebuilder is None:
            return
        jobs = []
        for k in range(self.n_jets):
            h = JetHealth(self.n_jets)
            h.set(k + 1, FAILED_OFF)
            jobs.append(self._job((self._gen, h.key()), h))
        self._prebuild_keys = {job[0] for job in jobs}
        self._rebuilder.queue(jobs)

    def _collect(self) -> None:
        """Move finished background builds of this parameter generation into the stores."""
        if self._rebuilder is None:
            return
        done = self._rebuilder.done
        for key in list(done):
            t = done.pop(key, None)
            if t is None or isinstance(t, Exception) or key[0] != self._gen:
                continue
            if key in self._prebuild_keys:
                self._prebuilt[key] = t
            else:
                self._remember(key, t)

    def _lookup(self, key):
        t = self._cache.get(key)
        if t is not None:
            self._cache.move_to_end(key)
            return t
        return self._prebuilt.get(key)

    def _remember(self, key, tables) -> None:
        if key in self._prebuilt:
            return
        self._cache[key] = tables
        self._cache.move_to_end(key)
        while len(self._cache) > CACHE_MAX_CONFIGS:
            self._cache.popitem(last=False)

    def _adopt(self, key, tables, from_cache: bool) -> None:
        self._tables = tables
        self._active_key = key
        self._target_key = None
        self._target_job = None
        self.reconfig_pending = False
        self._forbid = 0
        self._shifted = False
        self.tables_from_cache = from_cache
        if not from_cache:
            self.rebuild_time_s = tables.build_s
        self.tables_version += 1
        self.reconfig_latency_s = time.perf_counter() - self._t_request

    def _activate(self) -> None:
        self._t_request = time.perf_counter()
        health, key = self._model_key()
        if key == self._active_key:
            self._target_key = None
            self.reconfig_pending = False
            self._forbid = 0
            self._shifted = False
            self.tables_from_cache = True
            return
        self._collect()
        tables = self._lookup(key)
        if tables is not None:
            self._adopt(key, tables, True)
            return
        job = self._job(key, health)
        if not self.async_rebuild or self._tables is None:
            tables = _build_tables(*job[1:], self._ws)
            self._remember(key, tables)
            self._adopt(key, tables, False)
            return
        # async: interim model on the active tables, the build in the background
        _, usable, cols, bias, _, _ = job
        t = self._tables
        same = t.usable & usable & np.all(t.cols == cols, axis=0)
        changed = np.flatnonzero(t.usable & ~same)     # in the old patterns, now different
        self._forbid = int(sum(1 << int(k) for k in changed))
        self._delta = bias - t.bias                     # stuck-on bias the tables lack
        self._shifted = bool(np.any(self._delta != 0.0))
        self._target_key = key
        self._target_job = job
        self.reconfig_pending = True
        self._rebuilder.submit(job)

    def _try_switch(self) -> bool:
        t = self._rebuilder.done.pop(self._target_key, None) if self._rebuilder is not None else None
        if t is None:
            return False
        if isinstance(t, Exception):       # never expected; build it here rather than lose it
            t = _build_tables(*self._target_job[1:], self._ws)
        key = self._target_key
        self._remember(key, t)
        self._adopt(key, t, False)
        return True

    # -- the cycle
    def solve(self, tau_d: np.ndarray) -> np.ndarray:
        """u (uint8, n jets; the same array every call) for demand tau_d [N m] in body
        axes. Sets tau_B, objective, degraded, rejected, interim. A non-finite demand is
        rejected (u = 0, tau_B = stuck bias, objective NaN); a demand that is not 3 numbers
        raises ValueError."""
        if (type(tau_d) is not np.ndarray or tau_d.dtype != np.float64
                or tau_d.shape != (N_AXES,) or not tau_d.flags.c_contiguous):
            tau_d = _as_demand(tau_d)
        if self.reconfig_pending:
            self._try_switch()
        t = self._tables
        self.interim = self.reconfig_pending
        if not self._shifted or not self.reconfig_pending:
            status = _solve_kernel(tau_d, t.w, t.start, t.X, t.S, t.P, t.R, t.bstart, t.bmin,
                                   t.tau, t.pen, t.pat, t.scratch,
                                   self._forbid, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                                   self.u, self.tau_B, self._obj)
        else:
            status = _solve_shifted_kernel(tau_d, t.w, t.tau, t.pen, t.pat, t.scratch,
                                           self._forbid, self._delta,
                                           TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                                           self.u, self.tau_B, self._obj)
        if status == STATUS_REJECTED:
            if self.interim:
                np.add(t.bias, self._delta, out=self.tau_B)
            else:
                self.tau_B[:] = t.bias
            self.objective = float("nan")
            self.degraded = False
            self.rejected = True
        else:
            self.objective = float(self._obj[0])
            self.degraded = status == STATUS_DEGRADED
            self.rejected = False
        return self.u


def _as_demand(tau_d) -> np.ndarray:
    try:
        d = np.ascontiguousarray(tau_d, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"tau_d: expected 3 numbers [N m], got {tau_d!r}") from None
    if d.shape != (N_AXES,):
        raise ValueError(f"tau_d: expected shape (3,), got {d.shape}")
    return d


# ---------------------------------------------------------------- reference solvers
def solve_highs(T, thrust, health, w, c, tau_d, fault_tolerance=True):
    """Reference/fallback MILP via HiGHS (mip_rel_gap = 0, mip_abs_gap = 0, feasibility
    tolerances = TOL_BOX_NM). ``c`` is the penalty per newton (c_k = c * thrust_k).
    Returns (u uint8[n], objective, degraded); objective evaluated from the returned u."""
    import highspy

    T, thrust, w, c = _validate_problem(T, thrust, w, c)
    tau_d = np.asarray(tau_d, dtype=float)
    if tau_d.shape != (N_AXES,) or not np.all(np.isfinite(tau_d)):
        raise ValueError(f"tau_d: expected 3 finite values, got {tau_d!r}")
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
            if box:                                     # sign box on tau_i = b_i + A_i u
                lo_i, hi_i = (0.0, tau_d[i]) if tau_d[i] >= 0 else (tau_d[i], 0.0)
                rows.append(np.concatenate([A[i], np.zeros(N_AXES)]))
                lower.append(lo_i - b[i])
                upper.append(hi_i - b[i])
        M = np.array(rows)
        lp.num_row_ = M.shape[0]
        lp.row_lower_ = np.array(lower)
        lp.row_upper_ = np.array(upper)
        csc_start, csc_index, csc_value = [0], [], []
        for j in range(M.shape[1]):
            nz = np.flatnonzero(M[:, j])
            csc_index.extend(nz.tolist())
            csc_value.extend(M[nz, j].tolist())
            csc_start.append(len(csc_index))
        lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
        lp.a_matrix_.start_ = np.array(csc_start, dtype=np.int32)
        lp.a_matrix_.index_ = np.array(csc_index, dtype=np.int32)
        lp.a_matrix_.value_ = np.array(csc_value)
        lp.integrality_ = [highspy.HighsVarType.kInteger] * p + [highspy.HighsVarType.kContinuous] * N_AXES
        h.passModel(lp)
        h.run()
        status = h.getModelStatus()
        if status == highspy.HighsModelStatus.kInfeasible:
            return None
        if status != highspy.HighsModelStatus.kOptimal:
            raise RuntimeError(f"HiGHS: unexpected status {h.modelStatusToString(status)}")
        return np.round(np.asarray(h.getSolution().col_value)[:p]).astype(np.uint8)

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
def _enumeration_kernel(tau, pen, pat, w, D, tol_box, tol_tie, tie_rel, tol_pen,
                        out_pat, out_obj, out_deg):
    """Brute force per demand over every pattern: feasible set, min objective, ties by
    penalty then pattern; if nothing is feasible, the same without the sign box."""
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
                    ok = ok and (-tol_box <= tau[r, i] <= d[i] + tol_box)
                else:
                    ok = ok and (d[i] - tol_box <= tau[r, i] <= tol_box)
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


def solve_enumeration_many(T, thrust, health, w, c, tau_d, fault_tolerance=True):
    """The oracle for many demands tau_d (n, 3): (U uint8[n, jets], objective[n], degraded[n])."""
    T, thrust, w, c = _validate_problem(T, thrust, w, c)
    D = np.ascontiguousarray(np.atleast_2d(np.asarray(tau_d, dtype=float)))
    if D.shape[1] != N_AXES or not np.all(np.isfinite(D)):
        raise ValueError("tau_d: expected finite demands of shape (n, 3)")
    tau, pen, pat = _enumeration_table(T, thrust, health, c, fault_tolerance)
    n = D.shape[0]
    out_pat = np.empty(n, dtype=np.int64)
    out_obj = np.empty(n)
    out_deg = np.empty(n, dtype=np.bool_)
    _enumeration_kernel(tau, pen, pat, w, D, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                        out_pat, out_obj, out_deg)
    U = ((out_pat[:, None] >> np.arange(T.shape[1])[None, :]) & 1).astype(np.uint8)
    return U, out_obj, out_deg


def solve_enumeration(T, thrust, health, w, c, tau_d, fault_tolerance=True):
    """The oracle: brute force over all 2^p patterns of the usable jets.
    ``c`` is the penalty per newton. Returns (u uint8[n], objective, degraded)."""
    U, obj, deg = solve_enumeration_many(T, thrust, health, w, c,
                                         np.asarray(tau_d, dtype=float).reshape(1, N_AXES),
                                         fault_tolerance)
    return U[0], float(obj[0]), bool(deg[0])
