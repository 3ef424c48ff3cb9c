"""The cycle's head and law stretch on packed buffers (fsw/flightsoftware.py ``intake_cycle``,
``head_buffers``; fsw/law.py ``law_cycle``, LR_*/LW_*) fly, bit for bit, what main's calls with
one argument per array fly (tests/headlaw_oracle.py): two FSWs side by side on the same frames,
rejected frames, bad chamber entries, periods without a frame, unknown commands in force, a jet
fault declared and reconfigured, SAFE mode, each cycle preceded by the rehearsal. And the owners'
arrays are views of the buffers the calls take (what the packing is for)."""
from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

from common.events import EventLog
from common.model import load_scenario
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware, intake_cycle
from fsw.law import law_cycle
from fsw.topology import Topology
from interfaces.records import FSW_STATE, FSW_STATE_SHELL
from sim.plant import Plant

from tests.headlaw_oracle import MainHeadLawFlightSoftware

TIMING = ("alloc_us",) + FSW_STATE_SHELL
NAV = ("V_rel_mps", "h_m", "alpha_rad", "beta_rad", "bank_rad", "rho_kgpm3", "qbar_pa", "mach", "t_s")


def _damaged(i: int, frame: np.ndarray, last_k: int) -> np.ndarray | None:
    f = frame.copy()
    if i % 37 == 36:
        f["omega_BN_B"][0] = math.nan
    elif i % 43 == 42:
        f["v_N"][:] = 1e7
    elif i % 41 == 40:
        f["k"] = last_k
    elif i % 29 == 28:
        f["chamber"][6] = 50.0
    elif i % 31 == 30:
        f["chamber"][2] = math.nan
    elif i % 47 == 46:
        f["u_k"] = f["u_k"] - 200
    elif 150 <= i < 156:
        return None
    return f


def _fly(cls, scenario: str, n: int):
    scn = load_scenario(scenario)
    plant = Plant(scn, scn.seed)
    fsw = cls(scn, EventLog())
    topo = Topology(fsw, LockstepClock())
    rows, navs = [], []
    u = np.zeros(fsw.driver.n, dtype=np.uint8)
    last_k, last_f = 0, None
    for i in range(n):
        if i == 250:
            fsw.cmd_mode("safe")
        f = _damaged(i, plant.sensors, last_k)
        if last_f is not None:
            fsw.rehearse(last_f, fsw.u_cal_B.copy())      # the real-time rehearsal before the release
        if f is None:
            u = fsw.no_frame(float(plant.sensors["t_ns"]) * 1e-9)
        else:
            topo.tick(f)
            u = topo.u
            last_k, last_f = int(plant.sensors["k"]), f
        rows.append((u.copy(), fsw.output.copy()))
        navs.append([getattr(fsw.nav.state, a) for a in NAV] + fsw.nav.state.buf[:36].tolist()
                    + fsw.failsafes.state.tolist() + fsw.control._sb.tolist() + fsw.guidance._out.tolist())
        plant.step(u)
    return rows, np.array(navs), fsw


@pytest.mark.parametrize("scenario", ["case1", "guided-case2"])
def test_the_packed_calls_fly_main_bit_for_bit(scenario):
    rows_n, navs_n, fn = _fly(FlightSoftware, scenario, 330)
    rows_o, navs_o, fo = _fly(MainHeadLawFlightSoftware, scenario, 330)
    assert np.array_equal(navs_n, navs_o, equal_nan=True)
    for (un, on), (uo, oo) in zip(rows_n, rows_o):
        assert np.array_equal(un, uo)
        for name in FSW_STATE.names:
            if name not in TIMING:
                assert np.array_equal(on[name], oo[name], equal_nan=True), name
    ev = lambda f: [(e.t_s, e.code, tuple(a for a in e.args if a[0] != "rebuild_ms"))
                    for e in f.events.history if e.code != "cycle_slip"]
    assert ev(fn) == ev(fo)
    assert fn.fdir.detections == fo.fdir.detections and fn.reconfig_times == fo.reconfig_times
    assert np.array_equal(fn.fdir._cnt, fo.fdir._cnt) and np.array_equal(fn.fdir._sum_dg, fo.fdir._sum_dg)
    assert scenario != "case1" or fn.reconfig_times          # a fault was declared and reconfigured
    assert any(e.code == "sensors_stale" for e in fn.events.history)


def test_the_calls_take_few_arguments_and_the_owners_arrays_are_views_of_them():
    assert len(inspect.signature(intake_cycle.py_func).parameters) <= 10
    assert len(inspect.signature(law_cycle.py_func).parameters) <= 16
    fsw = FlightSoftware(load_scenario("case1"), EventLog())
    ro, wf, wi, nav, jb, jc = fsw._intake_args
    mon, fd = fsw.monitor, fsw.fdir
    for a in (fsw._zero_u, fd.health_isolated.state, mon._lims, fd._thr, fd._persist):
        assert np.shares_memory(a, ro)
    # the ring of answers: the jet driver's, which the tail writes and the head reads
    assert np.shares_memory(fsw._sent, jb) and np.shares_memory(fsw._sent_k, jc)
    for a in (mon._out, fd._sum_dg, fd._eta_new):
        assert np.shares_memory(a, wf)
    for a in (mon._seq, fd._cnt, fd._new_kind):
        assert np.shares_memory(a, wi)
    assert nav is fsw.nav.state.buf
    lr, g_out, kb, sb, lw, torques = fsw._law_args
    assert np.shares_memory(fsw.authority.trim, lr)
    for a in (fsw.failsafes.state, fsw.control.chart, fsw.guidance.trim_offset):
        assert np.shares_memory(a, lw)
    assert torques is fsw.torques and np.shares_memory(fsw.u_cal_B, torques) and np.shares_memory(fsw.tau_alloc_B, torques)
    # the rehearsal's scratch is apart from the flying state it copies
    _, wf_r, wi_r, nav_r, _, _ = fsw._intake_scratch
    assert not np.shares_memory(wf_r, wf) and not np.shares_memory(wi_r, wi) and nav_r is not nav
