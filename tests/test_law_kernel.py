"""The control law's stretch of the cycle in one compiled call (fsw/law.py ``law_cycle``:
the held trim, the scheduled bank reference, the reference attitude, the bank error, the
tracking failsafe, SAMI) decides bit for bit as main's Python (tests.law_oracle.py): each
kernel against the rule it replaced, and whole flights side by side through faults,
reconfiguration, a held trim, frozen adaptation, rejected frames, SAFE mode and the npc shaper,
the compiled instance rehearsing before every cycle."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from common.events import EventLog
from common.model import load_scenario
from fsw.authority import held_trim
from fsw.law import wrap_pi
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware
from fsw.guidance.reference import BankProfile, profile_eval
from fsw.modes import Failsafes, Mode, ModeManager, tracking_rule
from fsw.topology import Topology
from interfaces.records import FSW_STATE, FSW_STATE_SHELL
from sim.plant import Plant

from tests.law_oracle import (PythonFailsafes, PythonLawFlightSoftware, law_state, python_hold_trim,
                                python_profile_evaluate, python_wrap_pi)

TIMING = ("alloc_us",) + FSW_STATE_SHELL      # host timing and the loop's stamps: measured, not computed


def _same(a, b) -> bool:
    """Bit for bit (NaN equal to NaN of the same bits)."""
    return np.array_equal(np.asarray(a, dtype=float).view(np.int64), np.asarray(b, dtype=float).view(np.int64))


def _edges(prof: BankProfile) -> list[float]:
    """Each segment's start and end: where the bisection and the at-rest test turn."""
    s = prof.seg_array
    return [float(x) for x in s[:, 0]] + [float(x) for x in s[:, 0] + s[:, 1]]


def test_the_profile_kernel_evaluates_as_the_python_profile():
    rng = np.random.default_rng(7)
    for case in range(60):
        n = int(rng.integers(1, 6))
        t = np.cumsum(rng.uniform(0.5, 30.0, n))
        t[0] = 0.0
        sched = [(float(ti), float(rng.uniform(-math.pi, math.pi))) for ti in t]
        if case % 5 == 0 and n > 2:
            sched[2] = (sched[2][0], sched[1][1])          # a step to the same bank: no transition
        prof = BankProfile(sched, float(rng.uniform(0.02, 0.5)), float(rng.uniform(0.01, 0.3)))
        times = list(rng.uniform(-5.0, t[-1] + 80.0, 300)) + _edges(prof) + [0.0, -0.0]
        if case % 3 == 0:       # a re-plan mid-flight: continuations of constant acceleration
            prof.replan(float(rng.uniform(0.0, t[-1] + 10.0)), float(rng.uniform(0.02, 0.5)),
                        float(rng.uniform(0.005, 0.3)))
            times += _edges(prof)
        for ts in times:
            got = profile_eval(prof.seg_array, prof.phi0_rad, float(ts))
            want = python_profile_evaluate(prof, float(ts))
            assert _same(got, want), (case, ts, got, want)
            assert _same(got, prof.evaluate(float(ts)))


def test_the_bank_error_wraps_as_the_python_wrap():
    rng = np.random.default_rng(5)
    edges = [k * math.pi for k in range(-7, 8)]
    xs = list(rng.uniform(-20.0, 20.0, 5000)) + edges
    xs += [math.nextafter(e, math.inf) for e in edges] + [math.nextafter(e, -math.inf) for e in edges]
    xs += [0.0, -0.0, 1e-300, -1e-300, 1e6 + 0.5]
    for x in xs:
        assert _same(wrap_pi(x), python_wrap_pi(x)), x


class _Auth:
    def __init__(self, trim_ref, trim_max_deg):
        self._trim_ref = trim_ref
        self.params = {"guidance.trim_max_deg": trim_max_deg}


def test_the_trim_kernel_holds_the_trim_as_the_python_rule():
    rng = np.random.default_rng(11)
    qbars = [0.0, -1.0, math.inf, math.nan, 1e-300, 5.0, 1e3, 2e4]
    for case in range(3000):
        held = case % 7 != 0
        tr = (float(rng.normal(0, 0.1)), float(rng.normal(0, 0.1)) * (case % 4 != 1), float(rng.uniform(1, 3e4)))
        if held and max(abs(tr[0]), abs(tr[1])) == 0.0:
            continue
        mx = float(rng.choice([0.0, 5.0, 15.0, 30.0]))
        q = qbars[case % len(qbars)] if case % 2 else float(rng.uniform(0.0, 3e4))
        trim = np.array([*tr, 1.0, math.radians(mx)]) if held else np.array([0.0, 0.0, 0.0, 0.0, math.radians(mx)])
        off = np.full(2, 9.0)
        held_trim(trim, q, off)
        assert _same(off, python_hold_trim(_Auth(tr if held else None, mx), q)), (case, tr, q, mx)


def test_the_failsafe_kernel_counts_and_fires_as_the_python_rule():
    rng = np.random.default_rng(3)
    # (period, persistence): sums of the period that reach the persistence a rounding short of it
    edge = ((0.02, 0.5), (0.1, 0.9), (0.005, 0.06), (0.005, 1.1), (0.02, 0.0))
    errs = [0.0, 0.3, 0.349, math.radians(20.0), 0.35, 1.0, -2.0, math.nan, math.inf]
    for case in range(60):
        dt, persist = edge[case % len(edge)]
        params = {"fdir.safe_track_deg": 20.0, "fdir.safe_track_s": persist}
        events = EventLog()
        modes = ModeManager(events)
        modes.request(0.0, Mode.ENTRY, "start")
        fs = Failsafes(params, modes)
        py_modes = ModeManager(EventLog())
        py_modes.request(0.0, Mode.ENTRY, "start")
        py = PythonFailsafes(Failsafes(params, py_modes))
        e, fired = 0.0, 0
        for i in range(400):
            if rng.random() < 0.05:         # an error held for a while (long enough to persist)
                e = float(rng.choice(errs))
            if i % 50 == 49:       # the ground takes it back to ENTRY
                modes.request(i * dt, Mode.ENTRY, "ground")
                py.fs.modes.request(i * dt, Mode.ENTRY, "ground")
            entry = modes.mode is Mode.ENTRY
            due = tracking_rule(e, entry, dt, fs.state)
            if due:
                fs.enter_safe(i * dt)
            act = py.evaluate(i * dt, dt, e)
            assert due == (act != 0), (case, i)
            fired += due
            assert fs.state[0] == py.above_s and fs.last_rule == py.last_rule
            assert modes.mode == py.fs.modes.mode
        assert fired or persist > 1.0, case


def _flight_events(fsw) -> list:
    return [(e.t_s, e.code) for e in fsw.events.history if e.code != "cycle_slip"]


def _fly(cls, scenario: str, n: int, overrides: dict, rehearse: bool, trim_at: int = -1, reject_every: int = 37):
    """``n`` lockstep cycles with the rate groups, the plant stepped; every ``reject_every``-th
    frame with a non-finite rate (rejected). ``rehearse``: FlightSoftware.rehearse on the last
    good frame's record before each cycle (as the real-time loop). Returns commands, records, the law's state
    after each cycle, modes, the rule names, the final FSW. ``trim_at``: at that cycle the
    authority holds a trim (as an LP answer would set it; no scenario here finds one in 8 s)."""
    scn = load_scenario(scenario)
    plant = Plant(scn, scn.seed)
    fsw = cls(scn, EventLog(), param_overrides=overrides)
    topo = Topology(fsw, LockstepClock())
    jets, outs, laws, modes, rules = [], [], [], [], []
    for i in range(n):
        frame = plant.sensors
        if i % reject_every == reject_every - 1:
            frame = frame.copy()
            frame["omega_BN_B"][0] = math.nan
        if i == trim_at:
            fsw.authority._set_trim_ref(SimpleNamespace(trim_alpha_deg=2.5, trim_beta_deg=-1.5,
                                                        qbar_pa=0.5 * fsw.nav.state.qbar_pa))
        if rehearse and fsw._frame_views[0] is not None:
            fsw.rehearse(fsw._frame_views[0], fsw.u_cal_B.copy())
        topo.tick(frame)
        jets.append(topo.u.copy())
        outs.append(fsw.output.copy())
        laws.append(law_state(fsw))
        modes.append(int(fsw.modes.mode))
        rules.append(fsw._py_fs.last_rule if hasattr(fsw, "_py_fs") else fsw.failsafes.last_rule)
        plant.step(topo.u)
    return np.array(jets), np.array(outs), np.array(laws), modes, rules, fsw


SAFE_SOON = {"fdir.safe_track_deg": 2.0, "fdir.safe_track_s": 0.3}
FLIGHTS = [
    ("case2", {"fdir.delay_s": 0.5}, 200),      # stuck-on jets: learning frozen until reconfigured; a held trim
    ("guided-case2", {"fdir.delay_s": 0.5}, 300),   # the npc shaper's reference, a fault, a held trim
    ("case1", SAFE_SOON, -1),                   # SAFE entered on the tracking error
]


@pytest.mark.parametrize("scenario,overrides,trim_at", FLIGHTS)
def test_a_flight_with_the_compiled_law_equals_the_python_law_bit_for_bit(scenario, overrides, trim_at):
    n = 400     # 8 s: the fault at 2.5 s, its detection and reconfiguration
    jc, oc, lc, mc, rc, fc = _fly(FlightSoftware, scenario, n, overrides, rehearse=True, trim_at=trim_at)
    jp, op, lp, mp, rp, fp = _fly(PythonLawFlightSoftware, scenario, n, overrides, rehearse=False, trim_at=trim_at)
    assert np.array_equal(jc, jp)
    for name in FSW_STATE.names:
        if name not in TIMING:
            assert np.array_equal(oc[name], op[name], equal_nan=True), name
    for i in range(n):
        assert _same(lc[i], lp[i]), (i, np.nonzero(lc[i] != lp[i]))
    assert mc == mp and rc == rp
    assert _flight_events(fc) == _flight_events(fp)
    assert fc.control._have_chart == fp._py_chart
    # what the flight went through (or the comparison proves less than it says)
    assert lp[:, -1].any(), "adaptation never frozen"
    if overrides is SAFE_SOON:
        assert int(Mode.SAFE) in mp and "tracking_error" in rp
    else:
        assert fc.reconfig_times and mp[-1] == int(Mode.ENTRY)
        assert lp[np.array(mp) == int(Mode.ENTRY), -1].any(), "learning never frozen in ENTRY"
        assert sum(a != 0.0 for a, _ in fp.trim_offsets) > 50, "no trim held"
