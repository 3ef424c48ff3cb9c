"""Candidate tables of one health configuration, the allocator's precomputation: the
``Tables`` a query scans (fsw/allocation/query.py), the ``Workspace`` of work buffers a
build reuses, and ``build_tables``, which runs the build's kernels (fsw/allocation/build.py,
where the method is described) over them.
"""
from __future__ import annotations

import time

import numpy as np

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


class Tables:
    """Candidate tables of one configuration: the health model they were built for
    (usable, cols, bias), the objective (w, per-jet penalty c) and the query structure:
    octant tables for the sign box, a bounding-box tree for the spill box (the other's arrays empty)."""
    __slots__ = ("tau", "pen", "pat", "start", "X", "S", "P", "R", "bstart", "bmin", "bmax",
                 "nlo", "nhi", "nminpen", "nstart", "nend", "n_internal",
                 "scratch", "ties", "bias", "usable", "cols", "w", "spill", "spill_box", "n_raw", "build_s")
    _ARRAYS = ("tau", "pen", "pat", "start", "X", "S", "P", "R", "bstart", "bmin", "bmax",
               "nlo", "nhi", "nminpen", "nstart", "nend", "scratch", "ties")

    def __init__(self, tau, pen, pat, octants, tree, usable, cols, bias, w, spill, n_raw, build_s):
        self.tau, self.pen, self.pat = tau, pen, pat
        (self.start, self.X, self.S, self.P, self.R, self.bstart, self.bmin, self.bmax) = octants
        self.nlo, self.nhi, self.nminpen, self.nstart, self.nend = tree
        self.n_internal = (len(self.nminpen) - 1) // 2
        self.scratch = np.empty(len(pen))     # objective buffer of the exhaustive scans and ties
        self.ties = np.empty(len(pen), dtype=np.int64)   # tied rows of a tree query
        self.usable, self.cols, self.bias, self.w = usable, cols, bias, w
        self.spill = spill                    # box allowance [N m]
        self.spill_box = bool(np.any(spill != 0.0))   # queried through the tree
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
    tau, pen, pat = np.empty((n, N_AXES)), np.empty(n), np.empty(n, dtype=np.int64)
    if np.any(spill != 0.0):
        N = tree_nodes(n)
        tree = (np.empty((N, N_AXES)), np.empty((N, N_AXES)), np.empty(N),
                np.empty(N, dtype=np.int64), np.empty(N, dtype=np.int64))
        tree_fill(ws.tau, ws.pen, ws.pat, n, ws.code, ws.order, ws.code2, ws.order2, ws.count,
                   tau, pen, pat, *tree)
        octants = (np.zeros(9, dtype=np.int64), np.empty((0, N_AXES)), np.empty(0), np.empty(0),
                   np.empty(0, dtype=np.int64), np.zeros(9, dtype=np.int64), np.empty((0, N_AXES)),
                   np.empty((0, N_AXES)))
    else:
        lo = np.full(N_AXES, TOL_BOX_NM)
        start = octant_members(ws.tau, n, lo, ws.octm)
        total = int(start[8])
        ws.grow_octants(total)
        bstart = np.zeros(9, dtype=np.int64)
        bstart[1:] = np.cumsum((np.diff(start) + BLOCK - 1) // BLOCK)
        X, S, P, R = np.empty((total, N_AXES)), np.empty(total), np.empty(total), np.empty(total, dtype=np.int64)
        bmin = np.empty((int(bstart[8]), N_AXES))
        bmax = np.empty((int(bstart[8]), N_AXES))
        octant_fill(ws.tau, ws.pen, ws.pat, n, w, lo, ws.octm, start, ws.ka, ws.ia, ws.kb,
                     ws.ib, ws.count, tau, pen, pat, X, S, P, R, bstart, bmin, bmax)
        octants = (start, X, S, P, R, bstart, bmin, bmax)
        tree = (np.empty((0, N_AXES)), np.empty((0, N_AXES)), np.empty(0),
                np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64))
    return Tables(tau, pen, pat, octants, tree, usable.copy(), cols.copy(), bias.copy(), w.copy(),
                  spill, n_raw, time.perf_counter() - t0)
