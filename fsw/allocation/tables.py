"""Candidate tables of one health configuration, the allocator's precomputation: the
``Tables`` a query scans (fsw/allocation/query.py), the ``Workspace`` of work buffers a
build reuses, and ``build_tables``, which runs the build's kernels (fsw/allocation/build.py,
where the method is described) over them.
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit

from .build import (BLOCK, ROW, SORT_BUCKETS_MAX, enumerate_merged, group_columns, map_pages, octant_fill,
                    octant_members, tree_fill)
from .model import N_AXES, TOL_BOX_NM, TOL_PEN

KEY_QUANTUM_NM = 1e-7      # grid on which identical torque vectors are merged [N m]
TREE_LEAF = 8              # rows per leaf of the spill box's tree
WORKSPACE_ROWS = 49152     # initial work buffers: >= the nominal 46,656 combinations, so the
                           # paper's configurations (<= 39,936 distinct torques) never grow them


def tree_nodes(n: int) -> int:
    """Nodes of the spill box's tree over n candidates: the shallowest complete binary tree whose
    leaves hold at most TREE_LEAF rows."""
    depth = 0
    while -(-n // (1 << depth)) > TREE_LEAF:
        depth += 1
    return (2 << depth) - 1


class Workspace:
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
        self.code = np.zeros(rows, dtype=np.int64)     # the tree's Morton sort
        self.order = np.zeros(rows, dtype=np.int64)
        self.code2 = np.zeros(rows, dtype=np.int64)
        self.order2 = np.zeros(rows, dtype=np.int64)
        for a in (self.ra, self.rb, self.rc, self.tau, self.pen, self.pat, self.octm, self.code,
                  self.order, self.code2, self.order2, self.count):
            map_pages(a.view(np.uint8).reshape(-1))
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
            map_pages(a.view(np.uint8).reshape(-1))
        self.octrows = rows

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self.ra, self.rb, self.rc, self.tau, self.pen, self.pat,
                                      self.octm, self.code, self.order, self.code2, self.order2, self.ka, self.kb, self.ia, self.ib, self.count))


# A table set is two buffers, the floats ``tf`` and the int64s ``ti``, so that the compiled
# allocation stage (fsw/allocation/dutycycle.py) takes it in two arguments rather than twenty
# (each array argument costs ~40 ns of dispatch); ``Tables``' arrays are views into them.
# ti's head: the sizes, then each array's offset (floats in tf, ints in ti) in this order.
H_N, H_NODES, H_NINT, H_TOTAL, H_NBLK = range(5)
(O_W, O_SPILL, O_BIAS, O_TAU, O_PEN, O_SCRATCH, O_NLO, O_NHI, O_NMINPEN, O_X, O_S, O_P, O_BMIN, O_BMAX,
 O_PAT, O_TIES, O_NSTART, O_NEND, O_START, O_R, O_BSTART) = range(5, 26)
TABLES_HEAD = 26


def _pack_tables(n: int, nodes: int, total: int, nblk: int) -> tuple[np.ndarray, np.ndarray]:
    """Empty buffers for ``n`` candidates, a tree of ``nodes`` nodes, ``total`` octant rows in
    ``nblk`` blocks, ti's head filled (the order ``table_views`` reads)."""
    fsizes = (N_AXES, N_AXES, N_AXES, n * N_AXES, n, n, nodes * N_AXES, nodes * N_AXES, nodes,
              total * N_AXES, total, total, nblk * N_AXES, nblk * N_AXES)
    isizes = (n, n, nodes, nodes, 9, total, 9)
    ti = np.zeros(TABLES_HEAD + sum(isizes), dtype=np.int64)
    ti[H_N], ti[H_NODES], ti[H_NINT], ti[H_TOTAL], ti[H_NBLK] = n, nodes, (nodes - 1) // 2, total, nblk
    ti[O_W:O_W + len(fsizes)] = np.concatenate([[0], np.cumsum(fsizes)[:-1]])
    ti[O_PAT:O_PAT + len(isizes)] = TABLES_HEAD + np.concatenate([[0], np.cumsum(isizes)[:-1]])
    return np.zeros(sum(fsizes)), ti


@njit(cache=True)
def table_views(tf, ti):
    """The arrays of a table set packed by ``_pack_tables``: (w, spill, bias, tau, pen, scratch,
    nlo, nhi, nminpen, X, S, P, bmin, bmax, pat, ties, nstart, nend, start, R, bstart), views
    (the compiled stage unpacks its arguments with it; ``Tables`` names them)."""
    n, nodes, total, nblk = ti[H_N], ti[H_NODES], ti[H_TOTAL], ti[H_NBLK]
    return (tf[ti[O_W]:ti[O_W] + N_AXES], tf[ti[O_SPILL]:ti[O_SPILL] + N_AXES], tf[ti[O_BIAS]:ti[O_BIAS] + N_AXES],
            tf[ti[O_TAU]:ti[O_TAU] + n * N_AXES].reshape((n, N_AXES)), tf[ti[O_PEN]:ti[O_PEN] + n],
            tf[ti[O_SCRATCH]:ti[O_SCRATCH] + n],
            tf[ti[O_NLO]:ti[O_NLO] + nodes * N_AXES].reshape((nodes, N_AXES)),
            tf[ti[O_NHI]:ti[O_NHI] + nodes * N_AXES].reshape((nodes, N_AXES)),
            tf[ti[O_NMINPEN]:ti[O_NMINPEN] + nodes],
            tf[ti[O_X]:ti[O_X] + total * N_AXES].reshape((total, N_AXES)), tf[ti[O_S]:ti[O_S] + total],
            tf[ti[O_P]:ti[O_P] + total],
            tf[ti[O_BMIN]:ti[O_BMIN] + nblk * N_AXES].reshape((nblk, N_AXES)),
            tf[ti[O_BMAX]:ti[O_BMAX] + nblk * N_AXES].reshape((nblk, N_AXES)),
            ti[ti[O_PAT]:ti[O_PAT] + n], ti[ti[O_TIES]:ti[O_TIES] + n], ti[ti[O_NSTART]:ti[O_NSTART] + nodes],
            ti[ti[O_NEND]:ti[O_NEND] + nodes], ti[ti[O_START]:ti[O_START] + 9], ti[ti[O_R]:ti[O_R] + total],
            ti[ti[O_BSTART]:ti[O_BSTART] + 9])


class Tables:
    """Candidate tables of one configuration: the health model they were built for
    (usable, cols, bias), the objective (w, per-jet penalty c) and the query structure:
    octant tables for the sign box, a bounding-box tree for the spill box (the other's arrays empty).
    Every array but usable and cols is a view into the two buffers ``tf``, ``ti``."""
    __slots__ = ("tf", "ti", "tau", "pen", "pat", "start", "X", "S", "P", "R", "bstart", "bmin", "bmax",
                 "nlo", "nhi", "nminpen", "nstart", "nend", "n_internal",
                 "scratch", "ties", "bias", "usable", "cols", "w", "spill", "spill_box", "n_raw", "build_s")
    _ARRAYS = ("tau", "pen", "pat", "start", "X", "S", "P", "R", "bstart", "bmin", "bmax",
               "nlo", "nhi", "nminpen", "nstart", "nend", "scratch", "ties")

    def __init__(self, tf, ti, usable, cols, n_raw, build_s):
        self.tf, self.ti = tf, ti
        (self.w, self.spill, self.bias, self.tau, self.pen, self.scratch, self.nlo, self.nhi, self.nminpen,
         self.X, self.S, self.P, self.bmin, self.bmax, self.pat, self.ties, self.nstart, self.nend, self.start,
         self.R, self.bstart) = table_views(tf, ti)
        # scratch: objective buffer of the exhaustive scans and ties; ties: tied rows of a tree query
        self.n_internal = int(ti[H_NINT])
        self.usable, self.cols = usable, cols
        self.spill_box = bool(np.any(self.spill != 0.0))   # queried through the tree (spill: box allowance [N m])
        self.n_raw = n_raw                    # multiplicity vectors enumerated
        self.build_s = build_s                # build time [s]

    @property
    def nbytes(self) -> int:
        return sum(getattr(self, k).nbytes for k in self._ARRAYS)


def build_tables(usable, cols, bias, c, w, spill, ws: Workspace) -> Tables:
    """Groups of identical effective columns -> distinct torques -> the sign box's octant
    tables, or the spill box's tree. The heavy work is in nogil kernels over the
    workspace ``ws`` (one per building thread)."""
    t0 = time.perf_counter()
    usable = np.ascontiguousarray(usable, dtype=np.bool_)
    cols = np.ascontiguousarray(cols, dtype=np.float64)
    bias = np.ascontiguousarray(bias, dtype=np.float64)
    w = np.ascontiguousarray(w, dtype=np.float64)
    g_col, g_m, g_cum_pen, g_cum_pat = group_columns(
        cols, usable, np.ascontiguousarray(c, dtype=np.float64), KEY_QUANTUM_NM)
    while True:
        n_raw, n = enumerate_merged(g_col, g_m, g_cum_pen, g_cum_pat, bias, KEY_QUANTUM_NM,
                                     TOL_PEN, ws.ra, ws.rb, ws.rc, ws.tau, ws.pen, ws.pat)
        if n >= 0:
            break
        ws.grow(min(n_raw, 4 * ws.rows))       # never more than n_raw distinct torques
    spill = np.array(spill, dtype=np.float64)
    if np.any(spill != 0.0):
        tf, ti = _pack_tables(n, tree_nodes(n), 0, 0)
        v = table_views(tf, ti)
        tree_fill(ws.tau, ws.pen, ws.pat, n, ws.code, ws.order, ws.code2, ws.order2, ws.count,
                   v[3], v[4], v[14], v[6], v[7], v[8], v[16], v[17])
    else:
        lo = np.full(N_AXES, TOL_BOX_NM)
        start = octant_members(ws.tau, n, lo, ws.octm)
        total = int(start[8])
        ws.grow_octants(total)
        bstart = np.zeros(9, dtype=np.int64)
        bstart[1:] = np.cumsum((np.diff(start) + BLOCK - 1) // BLOCK)
        tf, ti = _pack_tables(n, 0, total, int(bstart[8]))
        (_, _, _, tau, pen, _, _, _, _, X, S, P, bmin, bmax, pat, _, _, _, start_v, R, bstart_v) = table_views(tf, ti)
        start_v[:] = start
        bstart_v[:] = bstart
        octant_fill(ws.tau, ws.pen, ws.pat, n, w, lo, ws.octm, start_v, ws.ka, ws.ia, ws.kb,
                     ws.ib, ws.count, tau, pen, pat, X, S, P, R, bstart_v, bmin, bmax)
    v = table_views(tf, ti)
    v[0][:], v[1][:], v[2][:] = w, spill, bias
    return Tables(tf, ti, usable.copy(), cols.copy(), n_raw, time.perf_counter() - t0)
