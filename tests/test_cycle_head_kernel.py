"""fsw/flightsoftware.py ``intake_cycle`` (the control cycle's head -- frame check, FDIR's jet
monitor on the command in force, navigation -- in one compiled call, the Python shell reporting
what it flags) gives, bit for bit, what main's Python head gives (tests/front_oracle.py): two
FSWs flown side by side on the same frames, with every kind of rejected frame, bad chamber
entries, periods without a frame (stale, then recovered), unknown commands in force, a jet
fault declared and reconfigured, SAFE mode and frozen adaptation."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.events import EventLog
from common.model import load_scenario
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware
from fsw.topology import Topology
from interfaces.records import FSW_STATE, FSW_STATE_SHELL
from sim.plant import Plant

from tests.front_oracle import PythonFrontFlightSoftware

TIMING = ("alloc_us",) + FSW_STATE_SHELL      # host timing and the loop's stamps: measured, not computed
NAV = ("V_rel_mps", "h_m", "alpha_rad", "beta_rad", "bank_rad", "rho_kgpm3", "qbar_pa", "mach", "t_s")


def _frame_for(i: int, frame: np.ndarray, last_k: int) -> np.ndarray | None:
    """Cycle ``i``'s record: the plant's, or a damaged copy of it (None: no frame this period)."""
    f = frame.copy()
    if i % 37 == 36:
        f["omega_BN_B"][0] = math.nan            # non-finite vector
    elif i % 43 == 42:
        f["v_N"][:] = 1e7                        # |v| out of range
    elif i % 41 == 40:
        f["k"] = last_k                          # duplicate
    elif i % 53 == 52:
        f["k"] = last_k - 1                      # out of order
    elif i % 59 == 58:
        f["k"] = -4                              # k < 0
    elif i % 29 == 28:
        f["chamber"][6] = 50.0                   # one transducer out of range (frame kept)
    elif i % 31 == 30:
        f["chamber"][2] = math.nan               # one transducer non-finite (frame kept)
    elif i % 47 == 46:
        f["u_k"] = f["u_k"] - 200                # a command in force this FSW no longer holds
    elif 150 <= i < 150 + 6:
        return None                              # no frame: stale after fdir.stale_s
    return f


def _events(fsw) -> list:
    """The flight's events with their arguments, less host timing (slips, table build times)."""
    return [(e.t_s, e.code, tuple(a for a in e.args if a[0] != "rebuild_ms"))
            for e in fsw.events.history if e.code != "cycle_slip"]


def _fly(cls, scenario: str, n: int):
    scn = load_scenario(scenario)
    plant = Plant(scn, scn.seed)
    fsw = cls(scn, EventLog())
    topo = Topology(fsw, LockstepClock())
    jets, outs, navs, mons = [], [], [], []
    u = np.zeros(fsw.driver.n, dtype=np.uint8)
    last_k = 0
    for i in range(n):
        if i == 250:
            fsw.cmd_mode("safe")
        f = _frame_for(i, plant.sensors, last_k)
        if f is None:
            u = fsw.no_frame(float(plant.sensors["t_ns"]) * 1e-9)
        else:
            topo.tick(f)
            u = topo.u
            last_k = int(plant.sensors["k"])
        jets.append(u.copy())
        outs.append(fsw.output.copy())
        navs.append([getattr(fsw.nav.state, a) for a in NAV] + fsw.nav.state.buf.tolist())
        m = fsw.monitor
        mons.append((dict(m.counts), m.last_k, m.accepted, m.missed, m.stale, fsw.k, fsw.t_s))
        plant.step(u)
    return np.array(jets), np.array(outs), np.array(navs), mons, fsw


@pytest.mark.parametrize("scenario", ["case1", "guided-case2"])
def test_a_flight_with_the_compiled_head_equals_the_python_head_bit_for_bit(scenario):
    n = 330
    jets_c, outs_c, navs_c, mons_c, fc = _fly(FlightSoftware, scenario, n)
    jets_p, outs_p, navs_p, mons_p, fp = _fly(PythonFrontFlightSoftware, scenario, n)
    assert np.array_equal(navs_c, navs_p, equal_nan=True)
    assert mons_c == mons_p
    assert np.array_equal(jets_c, jets_p)
    for name in FSW_STATE.names:
        if name not in TIMING:
            assert np.array_equal(outs_c[name], outs_p[name], equal_nan=True), name
    assert _events(fc) == _events(fp)
    dc, dp = fc.fdir, fp.fdir
    assert dc.detections == dp.detections and fc.reconfig_times == fp.reconfig_times
    assert (dc.unknown_command_periods, dc.nonfinite_count) == (dp.unknown_command_periods, dp.nonfinite_count)
    assert np.array_equal(dc._cnt, dp._cnt) and np.array_equal(dc._sum_dg, dp._sum_dg)
    # what the flight went through (or the comparison proves less than it says)
    counts = fc.monitor.counts
    assert all(counts[r] > 0 for r in counts if r != "format"), counts
    codes = {e.code for e in fc.events.history}
    assert {"sensors_stale", "sensors_recovered", "fdir_chamber_skip"} <= codes, codes
    assert dc.unknown_command_periods > 0
    assert scenario != "case1" or (dc.detections and fc.reconfig_times)
