"""fsw/topology.py: the real-time rehearsal (a spare flight software runs the control cycle
on the last frame before each release) leaves the flight unchanged, runs only in real time,
and never rebuilds tables or solves the controllability LP (its FDIR identifies nothing). The
flying instance's own rehearsal (its allocator's query on its tables, its jet monitor on copies
of its counters, its frame check, navigation and SAMI on copies)
changes nothing either, also through a fault's detection, and also repeated while the input
task waits for its frame."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from common.events import EventLog
from common.model import load_scenario
from fsw.executive import LockstepClock, RealTimeClock
from fsw.flightsoftware import FlightSoftware
from fsw.topology import Topology
from sim.plant import Plant

MS = 1_000_000


class FakeTime:
    def __init__(self):
        self.t = 1_000 * MS

    def now(self) -> int:
        self.t += 1_000
        return self.t

    def sleep_until(self, t: int) -> None:
        self.t = max(self.t, t)


def _fly(rehearse_us: float, n: int = 60, scenario: str = "nominal", warm: bool = False, wait_polls: int = 0):
    """``n`` real-time ticks on a fake clock with the plant stepped in the loop (as the
    bench's in-process loop does); the jet commands and output records of every tick.
    ``warm``: Topology.warm_up on the first frame before the clock starts (as the SIL does).
    ``wait_polls``: the input task rehearses while it waits this many polls before its frame
    comes (Topology.rehearse_waiting, as the SIL's FSW does between its polls)."""
    scn = load_scenario(scenario)
    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog(), param_overrides={"executive.rehearse_us": rehearse_us})
    ft = FakeTime()
    clock = RealTimeClock(int(round(fsw.dt_s * 1e9)), now_ns=ft.now, sleep_until=ft.sleep_until)

    def newest_frame():
        for _ in range(wait_polls):
            topo.rehearse_waiting()
        return plant.sensors
    topo = Topology(fsw, clock, frame_source=newest_frame)
    topo.add(1, "plant", lambda c: plant.step(topo.u))
    if warm:
        topo.warm_up(plant.sensors)
    jets, outs = [], []
    clock.start()
    for _ in range(n):
        topo.tick()
        jets.append(topo.u.copy())
        outs.append(fsw.output.copy())
    return topo, clock, np.array(jets), outs


def test_the_rehearsal_runs_before_each_release_and_changes_nothing_in_the_flight():
    topo, clock, jets, outs = _fly(800.0)
    ref_topo, ref_clock, ref_jets, ref_outs = _fly(0.0)
    assert ref_topo.rehearsal is None and ref_clock.rehearse is None
    assert topo.rehearsal is not None and topo.rehearsal is not topo.fsw
    assert clock.rehearse_ns == 800_000 and clock.rehearsals == len(jets)
    # the first release has no frame taken yet: nothing to rehearse; then one cycle per release
    assert topo.rehearsal.cycles == len(jets) - 1 and topo.rehearsal_errors == 0
    assert jets.any()                         # the flight commanded jets: a real comparison
    np.testing.assert_array_equal(jets, ref_jets)
    for a, b in zip(outs, ref_outs):
        for name in a.dtype.names:
            if name not in ("t_release_ns", "jitter_us", "compute_us", "alloc_us"):    # host timing
                np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    # the spare's FDIR identifies nothing: no table rebuild, no LP inside a rehearsal
    assert topo.rehearsal.fdir.oracle and not topo.fsw.fdir.oracle


def test_warm_up_runs_the_rehearsal_once_and_changes_nothing_in_the_flight():
    """The rehearsal's first call is cold: warm_up runs it on the first frame, before the
    flying instance has flown a cycle; the flight is the same as without any rehearsal."""
    topo, clock, jets, outs = _fly(800.0, warm=True)
    ref_topo, _, ref_jets, ref_outs = _fly(0.0, warm=True)
    assert topo.rehearsal.cycles == len(jets) and topo.rehearsal_errors == 0   # warm_up's + one a release
    assert jets.any()
    np.testing.assert_array_equal(jets, ref_jets)
    for a, b in zip(outs, ref_outs):
        for name in a.dtype.names:
            if name not in ("t_release_ns", "jitter_us", "compute_us", "alloc_us"):
                np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def _compiled_overloads() -> dict:
    """Every numba dispatcher of the flight code's modules loaded so far -> how many compiled
    versions it holds (a first call loads one from the cache or compiles it: tens of ms)."""
    from numba.core.dispatcher import Dispatcher
    out = {}
    for name, mod in list(sys.modules.items()):
        if mod is None or not name.startswith(("fsw", "common", "interfaces", "sim")):
            continue
        for attr, obj in vars(mod).items():
            if isinstance(obj, Dispatcher):
                out[f"{name}.{attr}"] = len(obj.overloads)
    return out


def test_after_warm_up_the_first_rehearsal_in_flight_loads_no_compiled_code():
    """The flying instance's own rehearsal runs kernels no cycle runs (its stages on scratch
    copies): warm_up must have loaded them, or the first release in real time waits the
    ~15 ms a first call costs (seen: the bench's jitter max 15.6 ms, one release a run)."""
    scn = load_scenario("nominal")
    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog(), param_overrides={"executive.rehearse_us": 800.0})
    ft = FakeTime()
    clock = RealTimeClock(int(round(fsw.dt_s * 1e9)), now_ns=ft.now, sleep_until=ft.sleep_until)
    topo = Topology(fsw, clock, frame_source=lambda: plant.sensors)
    topo.add(1, "plant", lambda c: plant.step(topo.u))
    topo.warm_up(plant.sensors)
    clock.start()
    topo.tick()                              # the first cycle: a frame taken, nothing rehearsed yet
    before = _compiled_overloads()
    assert len(before) > 10                  # the flight's kernels are seen
    topo.tick()                              # the first release with a rehearsal before it
    assert clock.rehearsals == 2 and topo.rehearsal_errors == 0
    assert _compiled_overloads() == before
    topo.close()


def test_the_flying_instances_rehearsal_changes_nothing_through_a_detection():
    # case1: four jets fail off at 2.5 s (tick 125); the jet monitor counts and declares them
    # while the flying FDIR and allocator are rehearsed before every release
    topo, _, jets, outs = _fly(800.0, n=200, scenario="case1")
    ref_topo, _, ref_jets, ref_outs = _fly(0.0, n=200, scenario="case1")
    det = [(d["jet"], d["t_s"]) for d in topo.fsw.fdir.detections]
    assert det and det == [(d["jet"], d["t_s"]) for d in ref_topo.fsw.fdir.detections]
    assert topo.fsw.allocator.tables_version == ref_topo.fsw.allocator.tables_version > 1
    np.testing.assert_array_equal(jets, ref_jets)
    for a, b in zip(outs, ref_outs):
        for name in ("u_cal_B", "tau_alloc_B", "health", "eta_hat", "theta_hat", "jets_cmd"):
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_the_flying_instances_own_rehearsals_change_nothing_and_compute_what_the_cycle_does():
    """FlightSoftware.rehearse on a fresh frame with an out-of-range chamber entry: the frame,
    the monitor's counts, the navigation and SAMI states and the output record are unchanged;
    the copies hold what the real calls then compute (navigation on the frame, the frame
    check's NaN) or what ``update`` computes on the same inputs (SAMI)."""
    import copy
    scn = load_scenario("nominal")
    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog())
    frame = plant.sensors
    for _ in range(30):
        frame = plant.step(fsw.control_step(frame))
    assert frame is plant.sensors and fsw._frame_views[0] is frame    # one record, refilled
    frame["chamber"][2] = 50.0                      # above fdir.chamber_hi: NaN for the check
    before = {"frame": frame.copy(), "nav": fsw.nav.state.buf.copy(), "sami": fsw.control._sb.copy(),
              "counts": dict(fsw.monitor.counts), "out": fsw.output.copy()}
    sami = copy.deepcopy(fsw.control)
    sami.update(fsw.nav.state, fsw.guidance, fsw.tau_alloc_B)
    fsw.rehearse(frame, fsw.u_cal_B.copy())
    assert frame.tobytes() == before["frame"].tobytes()
    np.testing.assert_array_equal(fsw.nav.state.buf, before["nav"])
    np.testing.assert_array_equal(fsw.control._sb, before["sami"])
    assert fsw.monitor.counts == before["counts"]
    assert fsw.output.tobytes() == before["out"].tobytes()
    np.testing.assert_array_equal(fsw.control._rb, sami._sb)          # SAMI's update, on the copy
    assert np.isnan(fsw.monitor._r_x[15 + 2]) and np.isnan(fsw.monitor._r_x[15:]).sum() == 1
    fsw.control_step(frame)
    np.testing.assert_array_equal(fsw.nav._r_buf, fsw.nav.state.buf)  # navigation on this frame
    assert np.isnan(frame["chamber"][2]) and fsw.monitor.counts["chamber_range"] == 1


@pytest.mark.parametrize("scenario, n", [("nominal", 60), ("case1", 200)])
def test_rehearsing_while_the_input_task_waits_changes_nothing_in_the_flight(scenario, n):
    """The flying instance's own rehearsal repeated between the input task's polls (three a
    tick, on the record the plant has refilled with the frame due) leaves every jet command and
    output the same as a flight never rehearsed; case1 through its four detections and the
    tables rebuilt for them."""
    topo, _, jets, outs = _fly(800.0, n=n, scenario=scenario, wait_polls=3)
    ref_topo, _, ref_jets, ref_outs = _fly(0.0, n=n, scenario=scenario, wait_polls=3)
    assert topo.wait_rehearsals == 3 * (n - 1) and topo.rehearsal_errors == 0   # none before a frame was taken
    assert ref_topo.wait_rehearsals == 0                      # no rehearsal: nothing while waiting either
    assert jets.any()
    np.testing.assert_array_equal(jets, ref_jets)
    for a, b in zip(outs, ref_outs):
        for name in a.dtype.names:
            if name not in ("t_release_ns", "jitter_us", "compute_us", "alloc_us"):    # host timing
                np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    if scenario == "case1":
        det = [(d["jet"], d["t_s"]) for d in topo.fsw.fdir.detections]
        assert det and det == [(d["jet"], d["t_s"]) for d in ref_topo.fsw.fdir.detections]
        assert topo.fsw.allocator.tables_version == ref_topo.fsw.allocator.tables_version > 1


def test_a_failing_rehearsal_while_waiting_is_counted_and_the_flight_goes_on():
    topo, _, _, _ = _fly(800.0, n=3)
    topo.fsw.rehearse = None                     # calling it raises TypeError
    topo.rehearse_waiting()
    assert topo.rehearsal_errors == 1 and topo.wait_rehearsals == 0
    topo.tick()
    assert topo.fsw.cycles == 4


def test_the_rehearsal_runs_the_jet_monitor_on_copies_of_its_counters():
    """FlightSoftware.rehearse: intake_cycle's jet monitor on scratch counters -- FDIR's own
    untouched, the scratch holding what the next cycle then computes on the same frame."""
    scn = load_scenario("nominal")
    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog())
    frame = plant.sensors
    for _ in range(30):
        frame = plant.step(fsw.control_step(frame))
    fd = fsw.fdir
    held = fsw._sent[int(frame["u_k"]) % fsw._ring]
    assert held.any()
    frame["chamber"][held != 0] = 0.0          # the jets in force gave nothing: failed-off evidence
    cnt, sums = fd._cnt.copy(), fd._sum_dg.copy()
    fsw.rehearse(frame, fsw.u_cal_B.copy())
    np.testing.assert_array_equal(fd._cnt, cnt)               # the counters untouched
    np.testing.assert_array_equal(fd._sum_dg, sums)
    fsw.control_step(frame)
    assert fd._cnt.sum() > cnt.sum()                          # evidence accumulated ...
    np.testing.assert_array_equal(fd._r_cnt, fd._cnt)         # ... as the rehearsal computed it


def test_allocator_rehearse_leaves_the_answer_and_its_outputs():
    fsw = FlightSoftware(load_scenario("nominal"), EventLog())
    a = fsw.allocator
    d1, d2 = np.array([400.0, -150.0, 80.0]), np.array([-300.0, 60.0, -20.0])
    u2 = a.solve(d2).copy()
    tau2, obj2 = a.tau_B.copy(), a.objective
    u1 = a.solve(d1).copy()
    a.solve(d2)
    a.rehearse(d1)
    np.testing.assert_array_equal(a.u, u2)                    # the last answer stands
    np.testing.assert_array_equal(a.tau_B, tau2)
    assert a.objective == obj2
    np.testing.assert_array_equal(a._warm_u, u1)              # the rehearsal searched for d1
    assert not np.array_equal(u1, u2)


def test_close_ends_the_rehearsal_and_its_spare():
    topo, clock, _, _ = _fly(800.0, n=3)
    spare = topo.rehearsal
    closed = []
    spare.close = lambda: closed.append(True)
    topo.close()
    topo.close()                                 # a second call does nothing
    assert closed == [True] and topo.rehearsal is None and clock.rehearse is None
    topo.tick()                                  # flies on, unrehearsed
    assert clock.rehearsals == 3 and topo.fsw.cycles == 4


def test_a_failing_rehearsal_is_counted_and_the_flight_goes_on():
    topo, clock, jets, _ = _fly(800.0, n=3)
    topo.rehearsal.control_step = None           # calling it raises TypeError
    topo.tick()
    assert topo.rehearsal_errors == 1 and topo.fsw.cycles == 4


def test_no_rehearsal_in_lockstep_and_a_lead_of_a_period_refused():
    scn = load_scenario("nominal")
    fsw = FlightSoftware(scn, EventLog(), param_overrides={"executive.rehearse_us": 800.0})
    assert Topology(fsw, LockstepClock()).rehearsal is None
    fast = scn.with_(dt_control_s=0.002)
    fsw = FlightSoftware(fast, EventLog(), param_overrides={"executive.rehearse_us": 2000.0,
                                                            "executive.rg2_period_s": 0.1})
    with pytest.raises(ValueError, match="executive.rehearse_us = 2000 us: not shorter than the control period"):
        Topology(fsw, RealTimeClock(2 * MS))


def test_the_spare_rehearses_on_a_copy_so_the_next_frame_in_a_refilled_record_reaches_the_flying_check_as_sent():
    """The bench's loop (and any source that refills one record) holds the NEXT frame in the
    record the flying instance took by the time the rehearsal runs. A chamber entry out of range
    in that frame must reach the flying frame check as sent (counted out of range, then NaN),
    not already NaN from the spare's check (which would count it non-finite)."""
    topo, _, _, _ = _fly(800.0, n=30)
    ref_topo, _, _, _ = _fly(0.0, n=30)
    for t in (topo, ref_topo):
        t.frame_source()["chamber"][2] = 50.0         # the next frame: above fdir.chamber_hi
        t.tick()
    assert topo.rehearsal.cycles == 30 and topo.rehearsal_errors == 0      # it ran on that frame
    counts = topo.fsw.monitor.counts
    assert counts["chamber_range"] == 1 and counts["chamber_nonfinite"] == 0
    assert counts == ref_topo.fsw.monitor.counts
    assert topo.rehearsal.monitor.counts["chamber_range"] == 1              # the spare saw the value too


def test_after_warm_up_a_missing_a_stale_and_a_rejected_frame_load_no_compiled_code():
    """The cycles off the common path -- no frame came, the sensors went stale, the frame check
    refused a frame -- are rare in flight, so their first one must not wait for a kernel's
    first call either (seen: every real-time SIL run's largest control task, ~5 ms, was the
    one tick after the plant's last step, which has no frame)."""
    scn = load_scenario("nominal")
    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog())
    src = [plant.sensors]
    topo = Topology(fsw, LockstepClock(), frame_source=lambda: src[0])
    topo.warm_up(plant.sensors)
    old = None
    for i in range(3):
        if i == 1:
            old = plant.sensors.copy()
        topo.tick()
        plant.step(topo.u)
    before = _compiled_overloads()
    assert len(before) > 10
    src[0] = None
    for _ in range(fsw.monitor.stale_n + 1):     # no frame, until the sensors are stale
        topo.tick()
    assert fsw.monitor.stale
    src[0] = old                                 # an old step: the frame check refuses it
    topo.tick()
    src[0] = plant.sensors
    topo.tick()
    assert _compiled_overloads() == before
    topo.close()
