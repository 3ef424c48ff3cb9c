"""fsw/allocation/dutycycle.py's compiled allocation stage (``realise``, packed buffers:
the allocator's query, the bank gate, the duty-cycle LP and the sigma-delta in one call) gives,
bit for bit, what main's Python stage gives (tests/alloc_oracle.py): over sequences of demands
(modulating, delivered, rejected, degraded) through health changes and back, on the spill box and
the paper's sign box, and over whole flights side by side (rejected frames, a fault and its
reconfiguration, operator marks that make the bank axis short, fault tolerance off and on, SAFE
mode) -- answers, torques, the realiser's and allocator's state, records and events."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.events import EventLog
from common.model import load_scenario, load_vehicle
from fsw.allocation import Allocator
from fsw.allocation.dutycycle import DutyCycleRealiser
from fsw.controllability import velocity_dir_B
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware
from fsw.health import JetHealth
from fsw.modes import Mode
from fsw.params import load_params
from fsw.topology import Topology
from interfaces.records import FSW_STATE_SHELL
from sim.plant import Plant

from tests.alloc_oracle import PythonAllocFlightSoftware, python_realiser

VEH = load_vehicle("ellipsled")
T, THRUST = VEH.torque_matrix_Nm, VEH.thrust_N
AXIS = velocity_dir_B(VEH.aero.alpha_trim_rad)
PARAMS = load_params(Allocator.PARAMS)
SHORT_MIN = 2.0 * float(np.max(np.abs(AXIS @ np.asarray(T))))

RUN82 = JetHealth.of(failed_off=(1, 7, 8), stuck_on=(14, 15))
RUN190 = JetHealth.of(failed_off=(4, 10, 18), stuck_on=(2, 7), degraded=((9, 0.8381), (13, 0.3271)))
STUCK = JetHealth.of(stuck_on=(3, 5, 11))          # stuck-on bias: degraded answers possible
NOMINAL = JetHealth()

REALISER = ("tau_B", "demand_B", "avg_B", "d", "acc", "u", "_basis", "_state")
FLAGS = ("modulated", "modulated_cycles", "pivots", "fell_back", "fallbacks")


def _pair(params, short_min):
    out = []
    for oracle in (False, True):
        al = Allocator(T, THRUST, params)
        dc = DutyCycleRealiser(AXIS, T, THRUST)
        dc.short_min_Nm = short_min
        out.append((al, python_realiser(dc) if oracle else dc))
    return out


def _same(a, b):
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _demands(rng, n):
    for i in range(n):
        kind = i % 7
        if kind in (0, 1, 2):
            yield rng.normal(0.0, 1.0) * rng.choice([150.0, 400.0, 1500.0]) * AXIS + rng.normal(0.0, 20.0, 3)
        elif kind == 3:
            yield rng.normal(0.0, 300.0, 3)
        elif kind == 4:
            yield rng.normal(0.0, 30.0, 3)
        elif kind == 5:
            yield np.array([np.nan, 0.0, 0.0]) if i % 3 == 0 else np.zeros(3)
        else:
            yield rng.normal(0.0, 4000.0, 3)


@pytest.mark.parametrize("spill_jets", [1.0, 0.0], ids=["spill-box", "sign-box"])
@pytest.mark.parametrize("short_min", [SHORT_MIN, 0.0], ids=["fsw-gate", "any-shortfall"])
def test_the_compiled_stage_equals_mains_python_over_demands_and_health_changes(spill_jets, short_min):
    params = {**PARAMS, "allocator.spill_jets": spill_jets}
    (al, dc), (al_p, dc_p) = _pair(params, short_min)
    rng = np.random.default_rng(int(spill_jets * 10 + short_min))
    healths = [RUN82, NOMINAL, STUCK, RUN82]     # RUN82 again: tables back from the cache
    modulated = degraded = rejected = 0
    for h_i, health in enumerate(healths):
        for a, d in ((al, dc), (al_p, dc_p)):
            a.set_health(health)
            d.reset()
        for u_B in _demands(rng, 120):
            frac = float(rng.choice([0.0, 0.1, 0.3]))
            dc.short_frac = dc_p.short_frac = frac
            jets = dc.solve(al, u_B.copy())
            jets_p = dc_p.solve(al_p, u_B.copy())
            assert _same(jets, jets_p)
            for name in REALISER:
                assert _same(getattr(dc, name), getattr(dc_p, name)), name
            for name in FLAGS:
                assert getattr(dc, name) == getattr(dc_p, name), name
            assert _same(al.u, al_p.u) and _same(al.tau_B, al_p.tau_B)
            assert _same(al._obj, al_p._obj)
            assert (al.degraded, al.rejected, al.interim) == (al_p.degraded, al_p.rejected, al_p.interim)
            assert dc.rare or not (al.degraded or al.rejected or dc.fell_back)
            modulated += dc.modulated
            degraded += al.degraded
            rejected += al.rejected
            if h_i % 2 and u_B[0] > 0.0:      # the rehearsal between some cycles changes nothing
                dc.rehearse(al, u_B * 0.9)
    assert rejected > 0
    if spill_jets:
        assert modulated > 20, "the LP path was not exercised"
    else:
        assert modulated == 0
    assert degraded > 0 or spill_jets, "no degraded answer was exercised"


def _fly(cls, scenario: str, n: int, reject_every: int):
    scn = load_scenario(scenario)
    plant = Plant(scn, scn.seed)
    fsw = cls(scn, EventLog())
    topo = Topology(fsw, LockstepClock())
    jets, outs, state = [], [], []
    for i in range(n):
        if i == 60:
            for jet in (1, 7, 8):
                fsw.cmd_mark(jet, "failed_off")
            for jet in (14, 15):
                fsw.cmd_mark(jet, "stuck_on")
        if i == 160:
            fsw.cmd_fault_tolerance(False)
        if i == 175:
            fsw.cmd_fault_tolerance(True)          # the same tables again
        if i == 330:
            fsw.cmd_mode(Mode.SAFE)
        frame = plant.sensors
        if i % reject_every == reject_every - 1:
            frame = frame.copy()
            frame["omega_BN_B"][0] = math.nan
        topo.tick(frame)
        u = topo.u.copy()
        if i % 5 == 0:
            fsw.rehearse(frame, fsw.u_cal_B * 1.1)
        jets.append(u)
        rec = fsw.output.copy()
        for f in ("alloc_us",) + FSW_STATE_SHELL:
            if f in rec.dtype.names:
                rec[f] = 0
        outs.append(rec)
        dcs = fsw.dutycycle
        state.append((dcs.modulated, dcs.modulated_cycles, dcs.pivots, dcs.tau_B.tobytes(), dcs.acc.tobytes(),
                      fsw.allocator.degraded, fsw.allocator.rejected, fsw.allocator.tables_version))
        plant.step(u)
    fsw.close()
    events = [(e.t_s, e.code) for e in fsw.events.history if e.code != "cycle_slip"]   # rebuild_ms: host timing
    return np.array(jets), outs, state, events, fsw


@pytest.mark.parametrize("scenario", ["guided-case2", "case1"])
def test_a_flight_with_the_compiled_stage_equals_mains_python_bit_for_bit(scenario):
    n = 420
    jets_c, outs_c, state_c, ev_c, fc = _fly(FlightSoftware, scenario, n, reject_every=37)
    jets_p, outs_p, state_p, ev_p, fp = _fly(PythonAllocFlightSoftware, scenario, n, reject_every=37)
    assert np.array_equal(jets_c, jets_p)
    for i in range(n):
        assert outs_c[i].tobytes() == outs_p[i].tobytes(), f"record of cycle {i}"
        assert state_c[i] == state_p[i], f"allocation state after cycle {i}"
    assert ev_c == ev_p
    assert fc.allocator.tables_version >= 3
    if scenario == "guided-case2":
        assert fc.dutycycle.modulated_cycles > 0, "no modulated cycle flown"


def _disjoint_views(views, buffers):
    """Each view lies in one of ``buffers`` and no two share a byte: every view filled with its own
    marker byte, each then reads back only its own."""
    for v in views:
        assert any(np.shares_memory(v, b) for b in buffers)
    for b in buffers:
        b.view(np.uint8)[:] = 0
    for i, v in enumerate(views):
        v.view(np.uint8)[...] = i + 1
    for i, v in enumerate(views):
        assert np.all(v.view(np.uint8) == i + 1), i


@pytest.mark.parametrize("spill_jets", [0.0, 1.0])
def test_the_packed_buffers_hold_every_array_apart(spill_jets):
    """Tables', the allocator's and the realiser's arrays are views into their buffers, none
    overlapping another (the realiser's for every size of the LP), so the compiled call's
    unpacking by offsets reads what the Python paths wrote."""
    from fsw.allocation.allocator import allocator_views
    from fsw.allocation.dutycycle import RF_AXIS, RI_BASIS, RI_P, realiser_views
    from fsw.allocation.tables import TABLES_HEAD, table_views
    al = Allocator(T, THRUST, {**PARAMS, "allocator.spill_jets": spill_jets})
    al.set_health(RUN82)
    t = al._tables
    assert t.spill_box == (spill_jets > 0.0)
    _disjoint_views([t.ti[:TABLES_HEAD]] + [v for v in table_views(t.tf, t.ti) if v.size], [t.tf, t.ti])
    n = al.n_jets
    _disjoint_views(list(allocator_views(al._af, al._ai, n, False)) + list(allocator_views(al._af, al._ai, n, True))[2:],
                    [al._af, al._ai])
    dc = DutyCycleRealiser(AXIS, T, THRUST)
    for p in (0, 1, n):
        dc._ri[:] = 0
        dc._ri[0], dc._ri[RI_P] = n, p
        main, warm = realiser_views(dc._rf, dc._ri, False), realiser_views(dc._rf, dc._ri, True)
        shared = {4, 5, 6, 7, 8, 12, 13, 14, 15, 16, 17, 18, 20}    # rhs .. work, cols, the LP's model, jets
        views = [dc._rf[:RF_AXIS], dc._ri[:RI_BASIS]] + list(main) + [v for i, v in enumerate(warm) if i not in shared and i != 0]
        _disjoint_views([v for v in views if v.size], [dc._rf, dc._ri])
