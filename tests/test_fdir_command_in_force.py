"""FDIR judges each jet by the command the plant actually held (SENSORS.u_k), not the last
one sent. In real time an answer that arrives late leaves the plant holding the one before;
the chamber pressures then follow that older command. Flown here in one process with the
real plant and FSW, with late deliveries scripted by a seeded generator and no fault at all:
every FDIR declaration is a false alarm (the independent truth is "no jet failed")."""
from __future__ import annotations

import numpy as np
import pytest

from common.model import load_scenario
from fsw.flightsoftware import COMMAND_RING_S, FlightSoftware
from sim.plant import Plant

STEPS = 1500           # 30 s at 50 Hz, the first minute's firing from the initial transient


def fly(p_stall: float, honest: bool, seed: int = 7) -> tuple[int, int, int]:
    """(FDIR declarations, late periods, periods FDIR could not judge). ``p_stall``: chance
    per period that the FSW's process stalls (a loaded host): its answers then reach the
    plant after the deadline for 2-15 periods in a row, and the plant holds the last one it
    had. ``honest``: the plant reports the index of the command held (as sim/plant.py and
    the SIL do); else it claims the newest, as if the FSW's last command were the one in
    force (the behaviour before u_k existed)."""
    scn = load_scenario("nominal")
    plant, fsw = Plant(scn, seed=1), FlightSoftware(scn)
    rng = np.random.default_rng(seed)
    frame, held, held_k, late, stall = plant.sensors, np.zeros(18, np.uint8), -1, 0, 0
    try:
        for k in range(STEPS):
            u = fsw.control_step(frame).copy()
            if stall == 0 and k > 0 and rng.random() < p_stall:
                stall = int(rng.integers(2, 16))
            if stall > 0:
                stall -= 1
                late += 1                      # the plant keeps what it held
            else:
                held, held_k = u, k
            frame = plant.step(held, u_k=held_k if honest else k)
        return len(fsw.fdir.detections), late, fsw.fdir.unknown_command_periods
    finally:
        fsw.close()


def test_on_time_answers_change_nothing():
    """Lockstep and batch: the plant always holds the answer to the frame before."""
    det, late, unknown = fly(0.0, honest=True)
    assert (det, late, unknown) == (0, 0, 0)


def test_late_answers_raise_no_false_alarm_when_the_plant_reports_the_command_held():
    det, late, unknown = fly(0.03, honest=True)
    assert late > 200 and det == 0 and unknown == 0


def test_the_same_flight_judged_by_the_last_command_sent_does_raise_false_alarms():
    """The check above can fail: judged by the newest command, the same late deliveries
    make FDIR declare nominal jets failed."""
    det, late, _ = fly(0.03, honest=False)
    assert late > 200 and det > 0


@pytest.mark.parametrize("dt_s, ring", [(0.02, 64), (0.005, 256)])
def test_a_command_older_than_the_ring_is_no_evidence(dt_s, ring):
    """The ring keeps the same time of answers at any control rate."""
    scn = load_scenario("nominal").with_(dt_control_s=dt_s)
    plant, fsw = Plant(scn, seed=1), FlightSoftware(scn)
    try:
        assert round(COMMAND_RING_S / dt_s) == ring == len(fsw._sent_k)
        frame = plant.sensors
        for k in range(ring + 5):
            u = fsw.control_step(frame).copy()
            frame = plant.step(u, u_k=k)
        frame["u_k"] = 0                     # the answer to frame 0: overwritten in the ring
        fsw.control_step(frame)
        assert fsw.fdir.unknown_command_periods == 1 and not fsw.fdir.detections
    finally:
        fsw.close()


def fly_missing_frames(p_miss: float, seed: int = 7) -> tuple[int, int]:
    """(FDIR declarations, periods without a frame). ``p_miss``: chance per period that the
    frame reaches the FSW after its tick (a starved FSW in real time): that tick runs
    without a frame and sends nothing, the plant holds the last answer it had, and the next
    tick takes the newest frame, which reports that older answer as the command held."""
    scn = load_scenario("nominal")
    plant, fsw = Plant(scn, seed=1), FlightSoftware(scn)
    rng = np.random.default_rng(seed)
    frame, held, held_k, missed = plant.sensors, np.zeros(18, np.uint8), -1, 0
    try:
        for k in range(STEPS):
            if k > 0 and rng.random() < p_miss:
                fsw.no_frame(fsw.t_s + fsw.dt_s)
                missed += 1
            else:
                held, held_k = fsw.control_step(frame).copy(), k
            frame = plant.step(held, u_k=held_k)
        return len(fsw.fdir.detections), missed
    finally:
        fsw.close()


def test_ticks_without_a_frame_raise_no_false_alarm():
    """A tick without a frame sends no command, so it must not stand in the record of
    answers for the frame before: the plant still holds that frame's answer (jets firing),
    and judged against the tick's jets-off the chamber pressures read as stuck-on jets."""
    det, missed = fly_missing_frames(0.2)
    assert missed > 200 and det == 0


def test_a_second_different_answer_to_a_frame_makes_its_period_no_evidence():
    """A rejected frame (here frame k again: a duplicate) is answered with jets off under
    the last good index k, after k was answered with jets firing: the plant may hold
    either, so the period it reports as k's is not judged (neither answer is assumed)."""
    scn = load_scenario("nominal")
    plant, fsw = Plant(scn, seed=1), FlightSoftware(scn)
    try:
        frame = plant.sensors
        for k in range(STEPS):
            u = fsw.control_step(frame).copy()
            if k > 50 and u.any():
                break
            frame = plant.step(u, u_k=k)
        else:
            pytest.fail("no jet fired in the first 30 s")
        again = fsw.control_step(frame)                   # the same frame: refused as a duplicate
        assert fsw.monitor.counts["duplicate"] == 1 and not again.any()
        frame = plant.step(u, u_k=k)                      # the plant held the first answer
        before = fsw.fdir.unknown_command_periods
        fsw.control_step(frame)
        assert fsw.fdir.unknown_command_periods == before + 1
    finally:
        fsw.close()
