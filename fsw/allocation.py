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

import time
from collections import OrderedDict

import numpy as np
from numba import njit

from fsw.health import DEGRADED, NOMINAL, STUCK_ON, JetHealth
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
@njit(cache=True)
def _enumerate_groups(g_col, g_m, g_cum_pen, g_cum_pat, bias):
    """All multiplicity vectors over the groups: group g contributes j * g_col[g], penalty
    g_cum_pen[g, j] and bits g_cum_pat[g, j] for j = 0..g_m[g] members on. Built group by
    group (each pass replicates the rows so far once per multiplicity)."""
    G = g_col.shape[0]
    M = 1
    for g in range(G):
        M *= g_m[g] + 1
    tau = np.empty((M, 3))
    pen = np.empty(M)
    pat = np.empty(M, dtype=np.int64)
    tau[0, 0] = bias[0]
    tau[0, 1] = bias[1]
    tau[0, 2] = bias[2]
    pen[0] = 0.0
    pat[0] = 0
    n = 1
    for g in range(G):
        for j in range(1, g_m[g] + 1):
            c0 = j * g_col[g, 0]
            c1 = j * g_col[g, 1]
            c2 = j * g_col[g, 2]
            off = j * n
            for r in range(n):
                tau[off + r, 0] = tau[r, 0] + c0
                tau[off + r, 1] = tau[r, 1] + c1
                tau[off + r, 2] = tau[r, 2] + c2
                pen[off + r] = pen[r] + g_cum_pen[g, j]
                pat[off + r] = pat[r] | g_cum_pat[g, j]
        n *= g_m[g] + 1
    return tau, pen, pat


@njit(cache=True)
def _merge_identical(tau, pen, pat, quantum, tol_pen):
    """Merge torque vectors equal on the quantum grid, keeping the smallest (penalty,
    pattern); open-addressing hash table, output in order of first appearance."""
    M = tau.shape[0]
    size = 1
    while size < 2 * M:
        size *= 2
    mask = size - 1
    inv_q = 1.0 / quantum
    slot_of = -np.ones(size, dtype=np.int32)     # hash slot -> output index
    keys = np.empty((M, 3), dtype=np.int64)
    out_tau = np.empty((M, 3))
    out_pen = np.empty(M)
    out_pat = np.empty(M, dtype=np.int64)
    n = 0
    for r in range(M):
        k0 = np.int64(np.floor(tau[r, 0] * inv_q + 0.5))
        k1 = np.int64(np.floor(tau[r, 1] * inv_q + 0.5))
        k2 = np.int64(np.floor(tau[r, 2] * inv_q + 0.5))
        h = np.uint64(k0) * np.uint64(0x9E3779B97F4A7C15)      # splitmix64-style mixing
        h = (h ^ np.uint64(k1)) * np.uint64(0xBF58476D1CE4E5B9)
        h = (h ^ np.uint64(k2)) * np.uint64(0x94D049BB133111EB)
        h = h ^ (h >> np.uint64(31))
        s = np.int64(h & np.uint64(mask))
        while True:
            o = slot_of[s]
            if o < 0:
                slot_of[s] = n
                keys[n, 0] = k0
                keys[n, 1] = k1
                keys[n, 2] = k2
                out_tau[n, 0] = tau[r, 0]
                out_tau[n, 1] = tau[r, 1]
                out_tau[n, 2] = tau[r, 2]
                out_pen[n] = pen[r]
                out_pat[n] = pat[r]
                n += 1
                break
            if keys[o, 0] == k0 and keys[o, 1] == k1 and keys[o, 2] == k2:
                d = pen[r] - out_pen[o]
                if d < -tol_pen or (d <= tol_pen and pat[r] < out_pat[o]):
                    out_tau[o, 0] = tau[r, 0]
                    out_tau[o, 1] = tau[r, 1]
                    out_tau[o, 2] = tau[r, 2]
                    out_pen[o] = pen[r]
                    out_pat[o] = pat[r]
                break
            s = (s + 1) & mask  # linear probing
    return out_tau[:n].copy(), out_pen[:n].copy(), out_pat[:n].copy()


@njit(cache=True)
def _radix_argsort(key):
    """Stable ascending argsort of finite float64 keys: LSD radix sort, 11-bit digits on
    the order-preserving unsigned image of the IEEE bits (numba's generic quicksort is
    several times slower on these sizes)."""
    n = key.shape[0]
    bits = key.view(np.uint64)
    sign = np.uint64(1) << np.uint64(63)
    ukey = np.empty(n, dtype=np.uint64)
    for i in range(n):
        b = bits[i]
        ukey[i] = ~b if (b & sign) else (b | sign)
    idx = np.arange(n)
    tmp = np.empty(n, dtype=np.int64)
    count = np.empty(2049, dtype=np.int64)
    mask = np.uint64(2047)
    for shift in range(0, 64, 11):
        sh = np.uint64(shift)
        count[:] = 0
        for i in range(n):
            count[np.int64((ukey[idx[i]] >> sh) & mask) + 1] += 1
        if count.max() == n:
            continue                      # every key has this digit: the pass is a no-op
        for d in range(2048):
            count[d + 1] += count[d]
        for i in range(n):
            dgt = np.int64((ukey[idx[i]] >> sh) & mask)
            tmp[count[dgt]] = idx[i]
            count[dgt] += 1
        idx, tmp = tmp, idx
    return idx


@njit(cache=True)
def _octant_tables(tau, pen, w, tol_box):
    """Per octant o (bit i set: tau_d,i < 0, s_i = -1): the candidates that can lie in that
    octant's sign box (s_i tau_i >= -tol_box on every axis), sorted by descending score
    sum_i w_i s_i tau_i - pen. Octant o occupies rows start[o]:start[o+1] of
    X (x = s * tau), S (score), P (penalty) and R (index into the unsorted candidates).
    A candidate with no (numerically) zero component belongs to exactly one octant."""
    n = tau.shape[0]
    member = np.zeros((8, n), dtype=np.bool_)
    start = np.zeros(9, dtype=np.int64)
    for o in range(8):
        s0 = -1.0 if (o & 1) else 1.0
        s1 = -1.0 if (o & 2) else 1.0
        s2 = -1.0 if (o & 4) else 1.0
        cnt = 0
        for r in range(n):
            if s0 * tau[r, 0] >= -tol_box and s1 * tau[r, 1] >= -tol_box and s2 * tau[r, 2] >= -tol_box:
                member[o, r] = True
                cnt += 1
        start[o + 1] = start[o] + cnt
    total = start[8]
    X = np.empty((total, 3))
    S = np.empty(total)
    P = np.empty(total)
    R = np.empty(total, dtype=np.int64)
    for o in range(8):
        s0 = -1.0 if (o & 1) else 1.0
        s1 = -1.0 if (o & 2) else 1.0
        s2 = -1.0 if (o & 4) else 1.0
        m = start[o + 1] - start[o]
        rows = np.empty(m, dtype=np.int64)
        neg_score = np.empty(m)
        q = 0
        for r in range(n):
            if member[o, r]:
                rows[q] = r
                neg_score[q] = pen[r] - (w[0] * s0 * tau[r, 0] + w[1] * s1 * tau[r, 1]
                                         + w[2] * s2 * tau[r, 2])
                q += 1
        order = _radix_argsort(neg_score)
        for q in range(m):
            r = rows[order[q]]
            j = start[o] + q
            X[j, 0] = s0 * tau[r, 0]
            X[j, 1] = s1 * tau[r, 1]
            X[j, 2] = s2 * tau[r, 2]
            S[j] = -neg_score[order[q]]
            P[j] = pen[r]
            R[j] = r
    # blocks of BLOCK consecutive rows per octant with their component-wise minimum of x
    bstart = np.zeros(9, dtype=np.int64)
    for o in range(8):
        bstart[o + 1] = bstart[o] + (start[o + 1] - start[o] + BLOCK - 1) // BLOCK
    bmin = np.empty((bstart[8], 3))
    for o in range(8):
        for blk in range(bstart[o], bstart[o + 1]):
            j0 = start[o] + (blk - bstart[o]) * BLOCK
            j1 = min(j0 + BLOCK, start[o + 1])
            for i in range(3):
                m = np.inf
                for j in range(j0, j1):
                    if X[j, i] < m:
                        m = X[j, i]
                bmin[blk, i] = m
    return start, X, S, P, R, bstart, bmin


# ---------------------------------------------------------------- the query
@njit(cache=True)
def _in_box(X, j, hi0, hi1, hi2):
    # the lower bounds x_i >= -tol_box hold for every member of an octant by construction
    # bitwise & (not `and`): one well-predicted branch instead of three unpredictable ones
    return (X[j, 0] <= hi0) & (X[j, 1] <= hi1) & (X[j, 2] <= hi2)


@njit(cache=True)
def _solve_kernel(tau_d, w, start, X, S, P, R, bstart, bmin, cand_tau, cand_pen, cand_pat, scratch,
                  tol_box, tol_tie, tie_rel, tol_pen, u_out, tau_out, obj_out):
    """One allocation. Writes u_out (n jets), tau_out (3,), obj_out[0]; returns
    STATUS_OK / STATUS_DEGRADED / STATUS_REJECTED. No allocation."""
    d0, d1, d2 = tau_d[0], tau_d[1], tau_d[2]
    if not (np.isfinite(d0) and np.isfinite(d1) and np.isfinite(d2)):
        for k in range(u_out.shape[0]):
            u_out[k] = 0
        obj_out[0] = np.nan
        return 2
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
    # first candidate inside the sign box = max score; skip blocks whose component-wise
    # minimum already leaves the box
    for blk in range(bstart[o], bstart[o + 1]):
        if (bmin[blk, 0] > hi0) | (bmin[blk, 1] > hi1) | (bmin[blk, 2] > hi2):
            continue
        j0 = first + (blk - bstart[o]) * BLOCK
        for j in range(j0, min(j0 + BLOCK, stop)):
            if _in_box(X, j, hi0, hi1, hi2):
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
            if P[j] < min_pen and _in_box(X, j, hi0, hi1, hi2):
                min_pen = P[j]
        for j in range(best, end):        # ... then smallest bit pattern
            if P[j] <= min_pen + tol_pen and _in_box(X, j, hi0, hi1, hi2):
                r = R[j]
                if chosen < 0 or cand_pat[r] < cand_pat[chosen]:
                    chosen = r
    else:                                 # empty sign box: unconstrained exhaustive scan
        status = 1
        m = cand_pen.shape[0]
        best_obj = np.inf
        for r in range(m):
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
    r = chosen
    tau_out[0] = cand_tau[r, 0]
    tau_out[1] = cand_tau[r, 1]
    tau_out[2] = cand_tau[r, 2]
    obj_out[0] = (w[0] * abs(d0 - cand_tau[r, 0]) + w[1] * abs(d1 - cand_tau[r, 1])
                  + w[2] * abs(d2 - cand_tau[r, 2]) + cand_pen[r])
    pat = cand_pat[r]
    for k in range(u_out.shape[0]):
        u_out[k] = (pat >> k) & 1
    return status


class _Tables:
    """Candidate tables of one health configuration."""
    __slots__ = ("tau", "pen", "pat", "start", "X", "S", "P", "R", "bstart", "bmin", "scratch",
                 "bias", "n_raw")

    def __init__(self, tau, pen, pat, start, X, S, P, R, bstart, bmin, bias, n_raw):
        self.tau, self.pen, self.pat = tau, pen, pat
        self.start, self.X, self.S, self.P, self.R = start, X, S, P, R
        self.bstart, self.bmin = bstart, bmin
        self.scratch = np.empty(len(pen))     # objective buffer of the degraded scan
        self.bias = bias
        self.n_raw = n_raw                    # combinations enumerated before merging


def _build_tables(usable, cols, bias, c, w) -> _Tables:
    """Groups of identical effective columns -> enumeration -> merge -> octant sort."""
    idx = np.flatnonzero(usable)
    groups: dict[tuple, list[int]] = {}
    for k in idx:
        key = tuple(np.round(cols[:, k] / KEY_QUANTUM_NM).astype(np.int64))
        if all(v == 0 for v in key):
            continue                      # a zero column (eta = 0) never helps: keep it off
        groups.setdefault(key, []).append(int(k))
    G = len(groups)
    m_max = max((len(v) for v in groups.values()), default=0)
    g_col = np.zeros((G, N_AXES))
    g_m = np.zeros(G, dtype=np.int64)
    g_cum_pen = np.zeros((G, m_max + 1))
    g_cum_pat = np.zeros((G, m_max + 1), dtype=np.int64)
    for g, members in enumerate(groups.values()):
        # j members on: the j cheapest, lowest-numbered first (smallest pattern on ties)
        members = sorted(members, key=lambda k: (c[k], k))
        g_col[g] = cols[:, members[0]]
        g_m[g] = len(members)
        for j, k in enumerate(members, start=1):
            g_cum_pen[g, j] = g_cum_pen[g, j - 1] + c[k]
            g_cum_pat[g, j] = g_cum_pat[g, j - 1] | (1 << k)
    tau_all, pen_all, pat_all = _enumerate_groups(g_col, g_m, g_cum_pen, g_cum_pat,
                                                  np.ascontiguousarray(bias, dtype=float))
    tau, pen, pat = _merge_identical(tau_all, pen_all, pat_all, KEY_QUANTUM_NM, TOL_PEN)
    start, X, S, P, R, bstart, bmin = _octant_tables(tau, pen, np.ascontiguousarray(w, dtype=float), TOL_BOX_NM)
    return _Tables(tau, pen, pat, start, X, S, P, R, bstart, bmin, np.array(bias, dtype=float),
                   len(pen_all))


# ---------------------------------------------------------------- the allocator
class Allocator:
    """Exact fault-tolerant discrete allocator. ``solve`` is allocation-free and bounded
    (a scan of at most the ~13,000 distinct achievable torques)."""

    PARAMS = PARAMS

    def __init__(self, torque_matrix_Nm: np.ndarray, thrust_N: np.ndarray,
                 params: dict[str, float]) -> None:
        T, thrust, _, _ = _validate_problem(torque_matrix_Nm, thrust_N, np.ones(3), 0.0)
        self._T = T
        self._thrust = thrust
        self.n_jets = T.shape[1]
        self._cache: OrderedDict = OrderedDict()
        self._health = JetHealth(self.n_jets)
        self.u = np.zeros(self.n_jets, dtype=np.uint8)     # reused output
        self.tau_B = np.zeros(N_AXES)                         # modelled achieved torque [N m]
        self._obj = np.zeros(1)
        self.objective = float("nan")
        self.degraded = False
        self.rejected = False
        self.rebuild_time_s = 0.0
        self.tables_from_cache = False
        self.set_params(params)
        # warm-up: compile/load the kernels and run every branch once
        self.solve(np.array([100.0, -50.0, 0.0]))
        self.solve(np.array([np.nan, 0.0, 0.0]))
        self.rejected = False

    # -- configuration (not in the cycle's hot path)
    def set_params(self, params: dict[str, float]) -> None:
        """Validate the allocator.* parameters and rebuild the tables."""
        vals = {}
        for p in self.PARAMS:
            if p.name not in params:
                raise ValueError(f"{p.name}: missing")
            vals[p.name] = p.check(params[p.name])
        self.w = np.array([vals["allocator.w_roll"], vals["allocator.w_pitch"],
                           vals["allocator.w_yaw"]])
        self.penalty_per_N = vals["allocator.penalty_per_N"]
        self.fault_tolerance = bool(vals["allocator.fault_tolerance"])
        self._cache.clear()
        self._activate()

    def set_health(self, health: JetHealth) -> None:
        """Adopt a new health picture: fetch its tables from the cache or rebuild them
        (see rebuild_time_s). Health is stored but not used while fault tolerance is off."""
        if not isinstance(health, JetHealth) or len(health.state) != self.n_jets:
            raise ValueError(f"health: expected a JetHealth of {self.n_jets} jets")
        self._health = health.copy()
        self._activate()

    def set_fault_tolerance(self, on: bool) -> None:
        self.fault_tolerance = bool(on)
        self._activate()

    def _activate(self) -> None:
        health = self._health if self.fault_tolerance else JetHealth(self.n_jets)
        key = health.key()          # fault tolerance off shares the all-nominal tables
        tables = self._cache.get(key)
        self.tables_from_cache = tables is not None
        if tables is None:
            t0 = time.perf_counter()
            usable, cols, bias, c = effective_model(self._T, self._thrust, health,
                                                    self.penalty_per_N)
            tables = _build_tables(usable, cols, bias, c, self.w)
            self.rebuild_time_s = time.perf_counter() - t0
            self._cache[key] = tables
            while len(self._cache) > CACHE_MAX_CONFIGS:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        self._tables = tables

    @property
    def n_candidates(self) -> int:
        """Distinct achievable torque vectors of the active configuration."""
        return len(self._tables.pen)

    # -- the cycle
    def solve(self, tau_d: np.ndarray) -> np.ndarray:
        """u (uint8, n jets; the same array every call) for demand tau_d [N m] in body
        axes. Sets tau_B, objective, degraded, rejected. A non-finite demand is rejected
        (u = 0, tau_B = stuck bias, objective NaN); a demand that is not 3 numbers raises
        ValueError."""
        if (type(tau_d) is not np.ndarray or tau_d.dtype != np.float64
                or tau_d.shape != (N_AXES,) or not tau_d.flags.c_contiguous):
            tau_d = _as_demand(tau_d)
        t = self._tables
        status = _solve_kernel(tau_d, self.w, t.start, t.X, t.S, t.P, t.R, t.bstart, t.bmin,
                               t.tau, t.pen, t.pat, t.scratch,
                               TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                               self.u, self.tau_B, self._obj)
        if status == STATUS_REJECTED:
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
