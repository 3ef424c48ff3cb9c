"""The table build's kernels: from one health configuration's effective jet columns to
its distinct achievable torques, laid out for the query (fsw/allocation/query.py). The
driver and the table types are in fsw/allocation/tables.py.

Jets with identical effective columns are grouped; every multiplicity vector over the
groups is enumerated (choosing the cheapest, then lowest-numbered members of a group), and
identical torque vectors are merged keeping the smallest (penalty, pattern). Nominal
matrix: 46,656 combinations -> ~13,000 distinct achievable torques. Torque vectors are
merged when they agree to a quantum (tables.KEY_QUANTUM_NM) on every axis (distinct
achievable torques are far further apart). The candidates are then laid out for the query:
sorted per octant for the sign box, a tree of bounding boxes for the spill box.

All kernels are nogil numba over preallocated work buffers (tables.Workspace), so a
background thread can run them while the control thread keeps solving:
 - group identical columns;
 - enumerate the multiplicity vectors group by group, keeping the list of distinct
   partial torques sorted by phi = a . tau (a generic direction): adding j times a group
   column shifts phi by a constant, so each group is a sequential merge of sorted lists,
   and torques equal on the quantum grid, whose phi differ by less than a small window,
   are found (and merged) by comparing the keys of the few phi-neighbours;
 - sign box: per octant a stable sort by score: one counting pass into about 2 buckets per
   row (a monotone fixed-point image of the score), each bucket then finished exactly by an
   insertion sort on the float score (buckets hold ~1 row; a crowded one is merge sorted);
 - spill box: the candidates in Morton (Z-order) order of their torque (a two-pass radix
   sort) and a complete binary tree over that order, leaves of tables.TREE_LEAF rows, each
   node with its bounding box and smallest penalty: O(n), and n rows instead of the 8 n a
   per-octant layout of every candidate would take. A median-split k-d tree answers
   queries faster but builds several times slower, and the build is on the
   reconfiguration's path while the query is well inside its budget either way.
"""
from __future__ import annotations

import numpy as np
from numba import njit

BLOCK = 16                 # rows per block of the block-skipping scan
MORTON_DIGIT = 15          # bits per radix pass of the Morton sort (2 passes: 30-bit codes)
PHI_DIR = (1.0, 0.7548776662466927, 0.5698402909980532)   # generic direction for phi = a . tau
SORT_BUCKETS_MAX = 1 << 17  # buckets of the octant tables' one-pass bucket sort
ROW = np.dtype([("t0", np.float64), ("t1", np.float64), ("t2", np.float64),
                ("pen", np.float64), ("pat", np.int64), ("phi", np.float64)])   # one candidate


@njit(cache=True, nogil=True)
def group_columns(cols, usable, c, quantum):
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
def enumerate_merged(g_col, g_m, g_cum_pen, g_cum_pat, bias, quantum, tol_pen,
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
def _in_octant(o, t0, t1, t2, lo):
    """Whether torque (t0, t1, t2) can lie in octant o's box: s_i t_i >= -lo_i."""
    a0 = -t0 >= -lo[0] if (o & 1) else t0 >= -lo[0]
    a1 = -t1 >= -lo[1] if (o & 2) else t1 >= -lo[1]
    a2 = -t2 >= -lo[2] if (o & 4) else t2 >= -lo[2]
    return a0 and a1 and a2


@njit(cache=True, nogil=True)
def octant_members(tau, n, lo, octm):
    """Octant membership of candidates 0:n: a candidate belongs to octant o (bit i set:
    tau_d,i < 0, s_i = -1) if it can lie in that octant's box, s_i tau_i >= -lo_i on every
    axis (lo = tol_box, the sign box);
    one with every |tau_i| > lo_i belongs to exactly one.
    Writes octm[r] (its octant, or -1 if several) and returns start (9,): octant o gets
    rows start[o]:start[o+1] of the tables."""
    start = np.zeros(9, dtype=np.int64)
    for r in range(n):
        t0, t1, t2 = tau[r, 0], tau[r, 1], tau[r, 2]
        if abs(t0) > lo[0] and abs(t1) > lo[1] and abs(t2) > lo[2]:
            o = np.int64(t0 < 0.0) | (np.int64(t1 < 0.0) << 1) | (np.int64(t2 < 0.0) << 2)
            octm[r] = o
            start[o + 1] += 1
        else:                               # on or near a coordinate plane: several octants
            octm[r] = -1
            for o in range(8):
                if _in_octant(o, t0, t1, t2, lo):
                    start[o + 1] += 1
    for o in range(8):
        start[o + 1] += start[o]
    return start


@njit(cache=True, nogil=True)
def _push_key(o, r, t0, t1, t2, pen_r, w, pos, ka, ia, kmin, kmax):
    """Append candidate r to octant o's sort input with key -score = pen - sum_i w_i s_i t_i."""
    s0 = 1.0 - 2.0 * (o & 1)                # signs by arithmetic: no unpredictable branches
    s1 = 1.0 - (o & 2)
    s2 = 1.0 - 0.5 * (o & 4)
    k = pen_r - (w[0] * s0 * t0 + w[1] * s1 * t1 + w[2] * s2 * t2)
    j = pos[o]
    pos[o] = j + 1
    ka[j] = k
    ia[j] = r
    kmin[o] = min(kmin[o], k)
    kmax[o] = max(kmax[o], k)


@njit(cache=True, nogil=True)
def octant_fill(tau, pen, pat, n, w, lo, octm, start, ka, ia, kb, ib, count,
                 tau_out, pen_out, pat_out, X, S, P, R, bstart, bmin, bmax):
    """The tables of one configuration from its n distinct candidates (tau, pen, pat) and
    their octant membership (octant_members): candidates copied to tau/pen/pat_out, and
    per octant o, rows start[o]:start[o+1] of X (x = s * tau), S (score), P (penalty) and
    R (index into the candidates) sorted by descending score sum_i w_i s_i tau_i - pen
    (stable: ties keep candidate order); bmin/bmax[bstart[o] + b] are the component-wise
    minimum/maximum of x over block b (BLOCK rows) of octant o. Work buffers: ka, kb (float64) and ia, ib
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
            _push_key(np.int64(o1), r, t0, t1, t2, pen[r], w, pos, ka, ia, kmin, kmax)
            continue
        for o in range(8):
            if _in_octant(o, t0, t1, t2, lo):
                _push_key(np.int64(o), r, t0, t1, t2, pen[r], w, pos, ka, ia, kmin, kmax)
    for o in range(8):
        _bucket_sort(ka, ia, start[o], start[o + 1], kmin[o], kmax[o], kb, ib, count)
    for o in range(8):
        s0 = -1.0 if (o & 1) else 1.0
        s1 = -1.0 if (o & 2) else 1.0
        s2 = -1.0 if (o & 4) else 1.0
        m0 = m1 = m2 = np.inf
        M0 = M1 = M2 = -np.inf
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
            M0 = max(M0, x0)
            M1 = max(M1, x1)
            M2 = max(M2, x2)
            if (j - start[o]) % BLOCK == BLOCK - 1 or j == start[o + 1] - 1:
                bmin[blk, 0] = m0
                bmin[blk, 1] = m1
                bmin[blk, 2] = m2
                bmax[blk, 0] = M0
                bmax[blk, 1] = M1
                bmax[blk, 2] = M2
                blk += 1
                m0 = m1 = m2 = np.inf
                M0 = M1 = M2 = -np.inf


@njit(cache=True, nogil=True)
def _spread3(x):
    """The 10 low bits of x spread to every third bit (a Morton code's axis)."""
    x &= 0x3FF
    x = (x | (x << 16)) & 0x030000FF
    x = (x | (x << 8)) & 0x0300F00F
    x = (x | (x << 4)) & 0x030C30C3
    return (x | (x << 2)) & 0x09249249


@njit(cache=True, nogil=True)
def _radix_pass(key, idx, n, shift, key_out, idx_out, count):
    """One stable counting pass of an LSD radix sort on bits shift:shift+MORTON_DIGIT."""
    nb = 1 << MORTON_DIGIT
    for d in range(nb + 1):
        count[d] = 0
    for j in range(n):
        count[((key[j] >> shift) & (nb - 1)) + 1] += 1
    for d in range(nb):
        count[d + 1] += count[d]
    for j in range(n):
        d = (key[j] >> shift) & (nb - 1)
        q = count[d]
        count[d] = q + 1
        key_out[q] = key[j]
        idx_out[q] = idx[j]


@njit(cache=True, nogil=True)
def tree_fill(tau, pen, pat, n, code, order, code2, order2, count,
               tau_out, pen_out, pat_out, nlo, nhi, nminpen, nstart, nend):
    """The spill box's query structure over the n candidates (tau, pen, pat): the candidates
    copied to tau/pen/pat_out in Morton (Z-order) order of their torque (10 bits per axis
    over the candidates' range; an LSD radix sort), so that rows close in the order are
    close in torque, and a complete binary tree over those rows: node k (children 2k+1,
    2k+2) holds rows nstart[k]:nend[k], halved at the middle row; nlo/nhi (N, 3) bound the
    torques under each node and nminpen is its smallest penalty (an empty leaf: lo = +inf,
    hi = -inf). The leaves are the last (N + 1) / 2 nodes. Work buffers code, order, code2,
    order2 (int64, >= n rows) and count (int64, >= 2^MORTON_DIGIT + 1)."""
    N = nlo.shape[0]
    n_internal = (N - 1) // 2
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for j in range(n):
        for i in range(3):
            lo[i] = min(lo[i], tau[j, i])
            hi[i] = max(hi[i], tau[j, i])
    scale = np.zeros(3)
    for i in range(3):
        if hi[i] > lo[i]:
            scale[i] = 1023.0 / (hi[i] - lo[i])
    for j in range(n):
        c = np.int64(0)
        for i in range(3):
            q = min(max(np.int64((tau[j, i] - lo[i]) * scale[i]), 0), 1023)
            c |= _spread3(q) << i
        code[j] = c
        order[j] = j
    _radix_pass(code, order, n, 0, code2, order2, count)
    _radix_pass(code2, order2, n, MORTON_DIGIT, code, order, count)
    for j in range(n):
        r = order[j]
        tau_out[j, 0] = tau[r, 0]
        tau_out[j, 1] = tau[r, 1]
        tau_out[j, 2] = tau[r, 2]
        pen_out[j] = pen[r]
        pat_out[j] = pat[r]
    nstart[0] = 0
    nend[0] = n
    for k in range(n_internal):
        a, b = nstart[k], nend[k]
        mid = (a + b) // 2
        nstart[2 * k + 1], nend[2 * k + 1] = a, mid
        nstart[2 * k + 2], nend[2 * k + 2] = mid, b
    for k in range(N - 1, -1, -1):
        if k >= n_internal:
            lo0 = lo1 = lo2 = mp = np.inf
            hi0 = hi1 = hi2 = -np.inf
            for j in range(nstart[k], nend[k]):
                lo0 = min(lo0, tau_out[j, 0])
                hi0 = max(hi0, tau_out[j, 0])
                lo1 = min(lo1, tau_out[j, 1])
                hi1 = max(hi1, tau_out[j, 1])
                lo2 = min(lo2, tau_out[j, 2])
                hi2 = max(hi2, tau_out[j, 2])
                mp = min(mp, pen_out[j])
            nlo[k, 0], nlo[k, 1], nlo[k, 2] = lo0, lo1, lo2
            nhi[k, 0], nhi[k, 1], nhi[k, 2] = hi0, hi1, hi2
            nminpen[k] = mp
        else:
            c1, c2 = 2 * k + 1, 2 * k + 2
            for i in range(3):
                nlo[k, i] = min(nlo[c1, i], nlo[c2, i])
                nhi[k, i] = max(nhi[c1, i], nhi[c2, i])
            nminpen[k] = min(nminpen[c1], nminpen[c2])



@njit(cache=True, nogil=True)
def map_pages(b):
    """Write one byte of every page of the byte view b (zero pages stay zero), so the
    kernel maps them here, outside the GIL (a numpy fill holds the GIL while the pages are
    mapped, and the control thread waits on it)."""
    for i in range(0, b.shape[0], 4096):
        b[i] = 0
