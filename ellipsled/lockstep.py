"""Plant and flight software in one process, stepped in lockstep: the flight both the batch
runner and the fault-free twin (ellipsled/reference.py) fly.

No transport: the plant's SENSORS record goes straight to the FSW topology (the same rate
groups the SIL FSW process runs) and the jet command straight back.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

from common.events import EventLog
from common.model import Scenario
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware
from fsw.topology import Topology
from interfaces import records
from sim.plant import Plant

from .sil.fsw_report import alloc_sample
from .sil.history import History, record_fsw, record_truth

PROGRESS_EVERY = 50       # steps between progress reports (1 s of simulated time at 50 Hz)


@dataclass
class Flight:
    """What one lockstep flight leaves: its history, the flight software (closed), the
    plant's fault log and end reason, and what the judgement needs besides the history."""
    history: History
    fsw: FlightSoftware
    fault_log: list
    end_reason: str           # the plant's (sil.variant.end_reason_of gives the run's)
    deploy: dict              # the plant's deploy record (Plant.deploy_report)
    slips: int
    alloc_samples: list
    wall_s: float


def tell_faults(fsw: FlightSoftware, fault_log: list, start: int, eta_of) -> int:
    """Oracle identification (a test mode): hand FDIR the plant's fault-log entries from
    ``start`` on, each at the time the plant applied it; returns the new count told.
    ``eta_of[jet - 1]``: the thrust factor the plant gave a degraded jet."""
    for t, jet, kind in fault_log[start:]:
        fsw.fdir.identified(float(t), int(jet), kind, float(eta_of[jet - 1]))     # a fault kind is a health word
    return len(fault_log)


def fly(scn: Scenario, seed: int, verify_every: int = 1000, on_progress=None) -> Flight:
    """Fly the prepared scenario ``scn`` (sil.variant.prepare) with ``seed`` to the plant's
    end. ``verify_every``: steps between allocation samples (0: none); ``on_progress(t_s)``
    is called every PROGRESS_EVERY steps with the simulated time reached."""
    plant = Plant(scn, seed)
    fsw = FlightSoftware(scn, EventLog())
    topo = Topology(fsw, LockstepClock())
    topo.warm_up(plant.sensors)
    h = History(int(math.ceil(scn.max_duration_s / scn.dt_control_s)) + 2)
    samples = []
    frame = plant.sensors
    trec = records.new(records.TRUTH)     # refilled in place every step
    told = 0                              # oracle mode: fault-log entries handed to FDIR so far
    wall0 = time.perf_counter()
    while True:
        if fsw.fdir.oracle and len(plant.fault_log) > told:
            told = tell_faults(fsw, plant.fault_log, told, plant.fault_eta)
        topo.tick(frame)
        u = topo.u
        if verify_every and plant.k % verify_every == 0:
            samples.append(alloc_sample(fsw))
        if on_progress is not None and plant.k % PROGRESS_EVERY == 0:
            on_progress(plant.t_s)
        i = h.row()
        record_truth(h, i, plant.fill_truth(trec))
        record_fsw(h, i, fsw.output)
        if fsw.deploy is not None:
            plant.command_deploy(fsw.deploy.command)
        done, reason = plant.done()
        if done:
            break
        frame = plant.step(u)
    wall = time.perf_counter() - wall0
    fsw.close()
    return Flight(h, fsw, plant.fault_log, reason, plant.deploy_report(), topo.executive.slips, samples, wall)

