"""The exact fault-tolerant discrete allocator (the problem: fsw/allocation/model.py).

Method (exact by construction, see tests/test_allocation_*.py):
  1. Per health configuration, the distinct achievable torques and their octant tables
     (fsw/allocation/tables.py); the queries below are fsw/allocation/query.py's kernels.
  2. Inside the sign box the objective is linear: with s_i = sign(tau_d,i) (+1 for 0),
     objective = sum_i w_i |tau_d,i| - score,  score = sum_i w_i s_i tau_i - c.
     score does not depend on the demand, only on its octant, so for each of the 8
     octants the candidates that can lie in it (s_i tau_i >= 0 on every axis) are sorted
     by score once. A query is the first candidate in that order inside the box
     |tau_i| <= |tau_d,i| (blocks of BLOCK rows whose component-wise minimum is outside
     are skipped), followed by a short scan of the score ties.
  3. If none is inside the box: an exhaustive scan of all candidates for the
     unconstrained objective (degraded).
  Spill box (e != 0): the objective is no longer linear in the box, so the candidates
  are held in a bounding-box tree (fsw/allocation/tables.py) and a query is a depth-first
  branch and bound on the objective itself: a node's bound is the weighted distance from
  the demand to its bounding box clipped to the box, plus its smallest penalty; nearer
  child first; a node is pruned once its bound exceeds the best objective + the tie
  tolerance, so every tie is visited and the tie-break (model.py) is applied to them. With no
  candidate in the box, the same search without the box (degraded). The tree does not
  depend on the demand's octant (one tree, not 8 sorted tables), and the interim model of
  an asynchronous reconfiguration (forbidden jets, shifted bias) is the same search.

Non-finite demand: ``solve`` returns u = 0 (all usable jets off), sets ``rejected`` and
leaves ``objective`` = NaN; it never raises in the cycle.

Here: the ``Allocator`` (its parameters, the cache of configurations' tables, the switch
between them, and the interim model while a new configuration's tables are being built);
the query kernels it calls are in fsw/allocation/query.py.
"""
from __future__ import annotations

import time
import weakref
from collections import OrderedDict

import numpy as np
from numba import njit

from fsw.health import FAILED_OFF, JetHealth
from fsw.params import Param

from .model import N_AXES, TIE_REL, TOL_BOX_NM, TOL_PEN, TOL_TIE, effective_model, spill_of, validate_problem
from .rebuild import Rebuilder
from .tables import Tables, Workspace, build_tables
from .query import (STATUS_DEGRADED, STATUS_REJECTED, TREE_STACK, ZERO3, solve_kernel, solve_scan_kernel,
                    solve_tree_kernel)

CACHE_MAX_CONFIGS = 16     # health configurations whose tables are kept

# The allocator's per-cycle arrays are views into two buffers, the floats ``af`` and the int64s
# ``ai``, so the compiled allocation stage (fsw/allocation/dutycycle.py) takes them in two
# arguments: af = [tau_B (3), objective, the rehearsal's tau_B (3) and objective, the tree
# query's bound stack]; ai = [its node stack, then as bytes u and the rehearsal's u].
AF_WARM = 4                # the rehearsal's outputs: after tau_B and the objective
AF_STACK = 8


def allocator_buffers(n_jets: int) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(AF_STACK + TREE_STACK), np.zeros(TREE_STACK + -(-2 * n_jets // 8), dtype=np.int64)


@njit(cache=True)
def allocator_views(af, ai, n_jets, warm):
    """(stack_k, stack_lb, u, tau_B, objective) of the buffers ``allocator_buffers`` made; the
    rehearsal's u, tau_B and objective if ``warm``."""
    o = AF_WARM if warm else 0
    ub = TREE_STACK * 8 + (n_jets if warm else 0)
    return (ai[:TREE_STACK], af[AF_STACK:AF_STACK + TREE_STACK], ai.view(np.uint8)[ub:ub + n_jets],
            af[o:o + N_AXES], af[o + N_AXES:o + N_AXES + 1])

PARAMS: list[Param] = [
    Param("allocator.w_roll", 0.0, 1e3, "-", "weight of the roll-torque error in the objective"),
    Param("allocator.w_pitch", 0.0, 1e3, "-", "weight of the pitch-torque error in the objective"),
    Param("allocator.w_yaw", 0.0, 1e3, "-", "weight of the yaw-torque error in the objective"),
    Param("allocator.penalty_per_N", 0.0, 10.0, "N m/N",
          "firing penalty per newton of jet thrust: c_k = penalty_per_N * thrust_k"),
    Param("allocator.spill_jets", 0.0, 18.0, "jets",
          "box: wrong-sign or overshooting torque admitted per cycle on each axis, in largest "
          "single-jet torques of that axis (0: the paper's sign box)"),
    Param("allocator.fault_tolerance", 0.0, 1.0, "-",
          "1: allocate with the FDIR jet health; 0: assume every jet nominal (paper fig. 5)",
          integer=True),
]


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
      changed (newly failed_off, inhibited, stuck_on, degraded with another eta, or back from
      stuck_on) is kept off, and the stuck-on bias is the new one (``solve_scan_kernel``
      when it differs; the spill box's tree search takes both). The interim answer never fires a jet the new health forbids, its
      tau_B and objective are those of the new model for the returned u, and it is the
      exact optimum (tie-break of model.py, sign box, degraded answer) over the previous
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
        T, thrust, _, _ = validate_problem(torque_matrix_Nm, thrust_N, np.ones(3), 0.0)
        self._T = T
        self._thrust = thrust
        self.n_jets = T.shape[1]
        self.async_rebuild = bool(async_rebuild)
        self.prebuild_single_faults = (self.async_rebuild if prebuild_single_faults is None
                                       else bool(prebuild_single_faults))
        self._ws = Workspace()
        self._rebuilder: Rebuilder | None = None
        self._finalizer = None
        self._cache: OrderedDict = OrderedDict()
        self._prebuilt: dict = {}                  # single faults, never evicted
        self._prebuild_keys: set = set()
        self._gen = 0                              # parameter generation (part of table keys)
        self._health = JetHealth(self.n_jets)
        self._af, self._ai = allocator_buffers(self.n_jets)
        # u: reused output; tau_B: modelled achieved torque [N m]; the stacks: spill-box query work arrays
        self._stack_k, self._stack_lb, self.u, self.tau_B, self._obj = allocator_views(
            self._af, self._ai, self.n_jets, False)
        _, _, self._warm_u, self._warm_tau, self._warm_obj = allocator_views(   # rehearse's answer, discarded
            self._af, self._ai, self.n_jets, True)
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
        self._tables: Tables | None = None
        async_now, self.async_rebuild = self.async_rebuild, False   # first tables: built here
        self.set_params(params)
        self._warm_kernels()
        self.solve(np.array([100.0, -50.0, 0.0]))
        self.rejected = False
        self.async_rebuild = async_now
        if self.async_rebuild:
            self._rebuilder = Rebuilder()
            self._finalizer = weakref.finalize(self, self._rebuilder.close, 1.0)
            self._queue_prebuilds()

    def _warm_kernels(self) -> None:
        """Compile (or load) every build and query kernel of both boxes and run each branch
        once, on two-jet tables, so neither a later parameter change nor the background
        builder meets a cold kernel."""
        usable = np.zeros(self.n_jets, dtype=bool)
        usable[:2] = True
        cols = np.where(usable[None, :], self._T, 0.0)
        c = self.penalty_per_N * self._thrust
        u, tau, obj = self.u.copy(), np.zeros(N_AXES), np.zeros(1)
        for spill in (np.zeros(N_AXES), self.spill + 1.0):
            t = build_tables(usable, cols, ZERO3, c, self.w, spill, self._ws)
            for d in (np.array([100.0, -50.0, 0.0]), np.array([np.nan, 0.0, 0.0]), np.full(N_AXES, 1e9)):
                if t.spill_box:
                    solve_tree_kernel(d, t.w, t.spill, t.nlo, t.nhi, t.nminpen, t.nstart, t.nend,
                                      t.n_internal, t.tau, t.pen, t.pat, t.ties, t.scratch, 1, ZERO3,
                                      TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN, self._stack_k, self._stack_lb,
                                      u, tau, obj)
                else:
                    solve_kernel(d, t.w, t.start, t.X, t.S, t.P, t.R, t.bstart, t.bmin, t.tau, t.pen,
                                 t.pat, t.scratch, 1, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN, u, tau, obj)
                    solve_scan_kernel(d, t.w, t.spill, t.tau, t.pen, t.pat, t.scratch, 1, ZERO3,
                                      TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN, u, tau, obj)

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
        self.spill_jets = vals["allocator.spill_jets"]
        self.spill = spill_of(self._T, self.spill_jets)
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
        return (key, usable, cols, bias, c, self.w.copy(), self.spill.copy())

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
        for key, t in self._rebuilder.finished():
            if isinstance(t, Exception) or key[0] != self._gen:
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
            tables = build_tables(*job[1:], self._ws)
            self._remember(key, tables)
            self._adopt(key, tables, False)
            return
        # async: interim model on the active tables, the build in the background
        _, usable, cols, bias, _, _, _ = job
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
        t = self._rebuilder.take(self._target_key) if self._rebuilder is not None else None
        if t is None:
            return False
        if isinstance(t, Exception):       # never expected; build it here rather than lose it
            t = build_tables(*self._target_job[1:], self._ws)
        key = self._target_key
        self._remember(key, t)
        self._adopt(key, t, False)
        return True

    # -- the cycle
    def rehearse(self, tau_d: np.ndarray) -> None:
        """Real time, just before a release: the query of ``solve`` on the active tables for a
        demand near the next one, its answer discarded, so the tables the next ``solve``
        searches are in the caches (a period asleep leaves them out). Changes nothing an
        answer depends on: the outputs go to scratch arrays, the work buffers (ties, stacks)
        are rewritten by every query before they are read, and no switch of tables is made."""
        t = self._tables
        if (t is None or type(tau_d) is not np.ndarray or tau_d.dtype != np.float64 or tau_d.shape != (N_AXES,)):
            return
        if t.spill_box:
            solve_tree_kernel(tau_d, t.w, t.spill, t.nlo, t.nhi, t.nminpen, t.nstart, t.nend,
                              t.n_internal, t.tau, t.pen, t.pat, t.ties, t.scratch,
                              self._forbid, self._delta if self._shifted else ZERO3,
                              TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                              self._stack_k, self._stack_lb, self._warm_u, self._warm_tau, self._warm_obj)
        elif not (self.reconfig_pending and self._shifted):
            solve_kernel(tau_d, t.w, t.start, t.X, t.S, t.P, t.R, t.bstart, t.bmin,
                         t.tau, t.pen, t.pat, t.scratch, self._forbid, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                         self._warm_u, self._warm_tau, self._warm_obj)

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
        if t.spill_box:
            status = solve_tree_kernel(tau_d, t.w, t.spill, t.nlo, t.nhi, t.nminpen, t.nstart, t.nend,
                                       t.n_internal, t.tau, t.pen, t.pat, t.ties, t.scratch,
                                       self._forbid, self._delta if self._shifted else ZERO3,
                                       TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                                       self._stack_k, self._stack_lb, self.u, self.tau_B, self._obj)
        elif self.reconfig_pending and self._shifted:
            status = solve_scan_kernel(tau_d, t.w, t.spill, t.tau, t.pen, t.pat, t.scratch,
                                       self._forbid, self._delta,
                                       TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                                       self.u, self.tau_B, self._obj)
        else:
            status = solve_kernel(tau_d, t.w, t.start, t.X, t.S, t.P, t.R, t.bstart, t.bmin,
                                  t.tau, t.pen, t.pat, t.scratch,
                                  self._forbid, TOL_BOX_NM, TOL_TIE, TIE_REL, TOL_PEN,
                                  self.u, self.tau_B, self._obj)
        if status == STATUS_REJECTED:
            if self.interim:
                np.add(t.bias, self._delta, out=self.tau_B)
            else:
                self.tau_B[:] = t.bias
        self.note_status(status)
        return self.u

    @property
    def objective(self) -> float:
        """The objective of the last answer (NaN for a rejected demand: the query writes NaN)."""
        return float(self._obj[0])

    def note_status(self, status: int) -> None:
        """``degraded`` and ``rejected`` of a query's status (also for the realiser's compiled
        call, fsw/allocation/dutycycle.py, which queries these tables without ``solve``)."""
        self.degraded = status == STATUS_DEGRADED
        self.rejected = status == STATUS_REJECTED


def _as_demand(tau_d) -> np.ndarray:
    try:
        d = np.ascontiguousarray(tau_d, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"tau_d: expected 3 numbers [N m], got {tau_d!r}") from None
    if d.shape != (N_AXES,):
        raise ValueError(f"tau_d: expected shape (3,), got {d.shape}")
    return d
