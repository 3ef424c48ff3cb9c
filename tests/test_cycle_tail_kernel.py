"""fsw/flightsoftware.py ``finish_cycle`` (the control cycle's tail after the allocation in one
compiled call) and its parts (``note_sent``, ``bank_short``, fsw/output.py ``fill_record``)
give, bit for bit, what the Python tail main flew gives (tests/tail_oracle.py): over random
inputs for each part, and over whole flights with a fault, its reconfiguration, rejected
frames (jets held off under an index already answered) and guidance answers, flown side by
side by the two FSWs."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.events import EventLog
from common.model import load_scenario
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware, bank_short, note_sent
from fsw.output import OutputFiller
from fsw.topology import Topology
from interfaces.records import FSW_STATE, FSW_STATE_SHELL
from sim.plant import Plant

from tests.tail_oracle import PythonOutputFiller, PythonSentRing, PythonTailFlightSoftware, python_bank_short

TIMING = ("alloc_us",) + FSW_STATE_SHELL      # host timing and the loop's stamps: measured, not computed


def test_the_ring_kernel_notes_answers_and_ambiguity_as_the_python_ring():
    rng = np.random.default_rng(7)
    ring, n = 8, 18
    py = PythonSentRing(ring, n)
    sent, sent_k = np.zeros((ring, n), np.uint8), np.full(ring, -2, np.int64)
    k = -1
    for _ in range(3000):
        step = rng.choice([0, 1, 1, 1, 3, ring])     # the same index again, the next, a gap, a wrap
        k += int(step)
        u = (rng.random(n) < 0.3).astype(np.uint8)
        if step == 0 and rng.random() < 0.5:
            u = py.sent[k % ring].copy()             # the same answer again: not ambiguous
        py.note(k, u)
        note_sent(sent, sent_k, k, u)
        assert np.array_equal(sent, py.sent)
        assert sent_k.tolist() == py.sent_k
    assert min(py.sent_k) < -2, "no ambiguous slot was exercised"


def test_the_shortfall_kernel_decides_as_the_python_rule():
    rng = np.random.default_rng(11)
    axis = np.array([0.9, 0.0, 0.43588989435406733])
    for i in range(20000):
        u = rng.normal(0.0, 200.0, 3)
        tau = u * rng.choice([0.0, 0.5, 0.9, 1.0, 1.1]) + rng.normal(0.0, 5.0, 3) * (i % 2)
        if i % 97 == 0:
            u[:] = 0.0
        short_min, frac = float(rng.choice([0.0, 50.0, 120.0])), float(rng.choice([0.0, 0.1, 0.5]))
        assert bank_short(axis, u, tau, short_min, frac) == python_bank_short(axis, u, tau, short_min, frac)


class _Entry:
    def __init__(self, cycles, bank_cmd, pred):
        self.cycles, self.bank_cmd, self.pred_impact = cycles, bank_cmd, np.array(pred, dtype=float)


@pytest.mark.parametrize("entry", [None, _Entry(0, 0.5, [math.nan, math.nan]), _Entry(3, math.nan, [0.1, -0.2]),
                                   _Entry(4, 0.7, [0.1, math.inf]), _Entry(5, -1.2, [-0.3, 2.9])])
def test_the_record_kernel_fills_every_field_as_the_python_filler(entry):
    scn = load_scenario("guided-case2")
    fsw = FlightSoftware(scn, EventLog())
    plant = Plant(scn, scn.seed)
    for _ in range(5):
        plant.step(fsw.control_step(plant.sensors))
    fsw.entry = entry
    rng = np.random.default_rng(3)
    compiled, python = OutputFiller(scn), PythonOutputFiller(scn)
    for t_s in (0.0, 12.34, 1e-9 * 2.5, 0.5e-9, 1.5e-9, 123.456789012, 300.02):
        fsw.t_s, fsw.k = t_s, int(t_s * 50)
        fsw.bank_err_rad = float(rng.normal())
        fsw.u_cal_B[:] = rng.normal(0, 100, 3)
        fsw.alloc_short = bool(rng.random() < 0.5)
        fsw.alloc_ns = int(rng.integers(0, 10**6))
        u = (rng.random(18) < 0.5).astype(np.uint8)
        compiled.fill(fsw, u)
        python.fill(fsw, u)
        assert compiled.rec.tobytes() == python.rec.tobytes()


def _flight_events(fsw) -> list:
    """The events of the flight, without the executive's cycle slips (host timing)."""
    return [(e.t_s, e.code) for e in fsw.events.history if e.code != "cycle_slip"]


def _ring_indices(fsw) -> list:
    ring = getattr(fsw, "_py_ring", None)
    return list(ring.sent_k) if ring is not None else fsw._sent_k.tolist()


def _fly(cls, scenario: str, n: int, reject_every: int):
    """``n`` lockstep cycles of ``cls`` with its rate groups, the plant stepped; every
    ``reject_every``-th frame arrives with a non-finite rate (rejected: jets held off under the
    index of the last good frame). Returns the commands, output records, the ring's frame
    indices after each cycle, the final FSW."""
    scn = load_scenario(scenario)
    plant = Plant(scn, scn.seed)
    fsw = cls(scn, EventLog())
    topo = Topology(fsw, LockstepClock())
    jets, outs, rings = [], [], []
    for i in range(n):
        frame = plant.sensors
        if i % reject_every == reject_every - 1:
            frame = frame.copy()
            frame["omega_BN_B"][0] = math.nan
        topo.tick(frame)
        jets.append(topo.u.copy())
        outs.append(fsw.output.copy())
        rings.append(_ring_indices(fsw))
        plant.step(topo.u)
    return np.array(jets), np.array(outs), np.array(rings), fsw


@pytest.mark.parametrize("scenario", ["guided-case2", "case1"])
def test_a_flight_with_the_compiled_tail_equals_the_python_tail_bit_for_bit(scenario):
    n = 400     # 8 s: the fault at 2.5 s, its detection and reconfiguration
    jets_c, outs_c, rings_c, fc = _fly(FlightSoftware, scenario, n, reject_every=37)
    jets_p, outs_p, rings_p, fp = _fly(PythonTailFlightSoftware, scenario, n, reject_every=37)
    assert np.array_equal(jets_c, jets_p)
    for name in FSW_STATE.names:
        if name not in TIMING:
            assert np.array_equal(outs_c[name], outs_p[name], equal_nan=True), name
    assert np.array_equal(fc._sent, fp._py_ring.sent)
    assert np.array_equal(rings_c, rings_p)
    dc, dp = fc.driver, fp.driver
    assert np.array_equal(dc.pulses, dp.pulses) and np.array_equal(dc.on_time_s, dp.on_time_s)
    assert (dc.propellant_kg, dc.seq) == (dp.propellant_kg, dp.seq)
    assert (fc.alloc_short_cycles, fc._tau_sum, fc._tau_n) == (fp.alloc_short_cycles, fp._tau_sum, fp._tau_n)
    assert _flight_events(fc) == _flight_events(fp)
    # what the flight went through (or the comparison proves less than it says)
    assert rings_p.min() < -2, "no answer was made ambiguous by a rejected frame"
    assert fc.reconfig_times or scenario == "case1"
    assert dc.propellant_kg > 0.0


def test_the_tails_rehearsal_writes_only_its_scratch_and_computes_what_the_cycle_did():
    """FlightSoftware.rehearse runs ``finish_cycle`` with the last cycle's answer on scratch copies
    of what it writes. The real state is set so that a rehearsal writing any of it would change
    it (the command in force inverted, the ring's slot for this frame and the record's k spoilt,
    tau_alloc_B zeroed); after the rehearsal all of it is as it was, and the scratch holds what
    the last cycle's tail wrote (the ring, the record, tau_alloc_B) and one more period of
    on-time for the jets on."""
    scn = load_scenario("nominal")
    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog())
    frame = plant.sensors
    for _ in range(30):
        frame = plant.step(fsw.control_step(frame))
    d = fsw.driver
    u = d.last_command.copy()
    assert u.any() and fsw._have_prev
    slot = fsw.k % fsw._ring
    done = {"sent": fsw._sent[slot].copy(), "out": fsw.output.copy(), "tau": fsw.tau_alloc_B.copy(),
            "on": d.on_time_s.copy()}
    d.last_command[:] = 1 - u
    fsw._sent_k[slot] = -1
    fsw._sent[slot] = 0
    fsw.output["k"] = -7
    fsw.tau_alloc_B[:] = 0.0
    real = [a.copy() for a in d.packed()] + [fsw.output.copy(), fsw.torques.copy()]   # tau_alloc_B's buffer
    counts = (d.propellant_kg, d.seq, fsw.alloc_short_cycles, len(fsw.events.history))
    fsw.rehearse(frame, fsw.u_cal_B.copy())
    for a, b in zip([*d.packed(), fsw.output, fsw.torques], real):
        assert a.tobytes() == b.tobytes()
    assert (d.propellant_kg, d.seq, fsw.alloc_short_cycles, len(fsw.events.history)) == counts
    jb, jc, jr, rec, torques = fsw._tail_scratch
    n = d.n
    np.testing.assert_array_equal(jb[1], u)                               # the command, re-driven
    np.testing.assert_array_equal(jb[2 + slot], done["sent"])
    assert jc[n + slot] == fsw.k
    np.testing.assert_array_equal(jr[:n], done["on"] + np.where(u != 0, fsw.dt_s, 0.0))
    np.testing.assert_array_equal(torques[3:6], done["tau"])
    assert rec.reshape(()).tobytes() == done["out"].tobytes()
