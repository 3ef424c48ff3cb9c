"""The FSW topology: which function runs in which rate group (spec 20-fsw.md, Executive).

  RG1 (every tick, 50 Hz)  control: frame -> monitors -> FDIR -> nav -> guidance -> SAMI
                                     -> allocator -> jet driver
  RG2 (every 5th, 10 Hz)   fdir_slow: analytic-redundancy residual
  RG3 (every 50th, 1 Hz)   housekeeping
Process shells append their own tasks (publish the jet command, ground link) with add().
The batch runner and the SIL FSW process both fly through this object.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from .executive import Cycle, Executive, LockstepClock, RealTimeClock
from .flightsoftware import FlightSoftware


class Topology:
    def __init__(self, fsw: FlightSoftware, clock: LockstepClock | RealTimeClock,
                 frame_source: Callable[[], object] | None = None, history: int = 4096):
        """``frame_source`` (real time): returns the newest fresh sensor frame or None;
        in lockstep the frame comes with each tick."""
        self.fsw = fsw
        self.frame_source = frame_source
        period_ns = int(round(fsw.dt_s * 1e9))
        self.executive = Executive.from_params(fsw.params, period_ns, clock, events=fsw.events,
                                               history=history)
        self.u: np.ndarray = fsw.driver.last_command
        self.got_frame = False
        self.executive.add(1, "control", self._control)
        self.executive.add(2, "fdir_slow", lambda c: fsw.slow_step())
        self.executive.add(3, "housekeeping", lambda c: fsw.housekeeping())

    def _control(self, cyc: Cycle) -> None:
        frame = cyc.frame if cyc.frame is not None else (self.frame_source() if self.frame_source else None)
        self.got_frame = frame is not None
        if frame is None:
            self.u = self.fsw.no_frame(self.fsw.t_s + self.fsw.dt_s)
        else:
            self.u = self.fsw.control_step(frame)

    def warm_up(self, frame) -> None:
        """Run one control cycle of a throwaway FlightSoftware on ``frame`` so every compiled
        kernel is loaded before the first real cycle (the first call of each numba kernel
        costs tens of ms). The flying instance's state is untouched."""
        spare = FlightSoftware(self.fsw.scenario, param_overrides=None)
        spare.control_step(frame)
        spare.slow_step()

    def add(self, group: int, name: str, fn: Callable[[Cycle], object]) -> None:
        self.executive.add(group, name, fn)

    def tick(self, frame=None) -> bool:
        """One base tick (lockstep: with the frame of step k). True if on time."""
        if frame is not None:
            return self.executive.tick(frame, k=int(frame["k"]), t_s=float(frame["t_ns"]) * 1e-9)
        return self.executive.tick()

    @property
    def last_compute_ns(self) -> int:
        st = self.executive.stats
        return int(st.compute_ns[(st.n - 1) % st.capacity]) if st is not None and st.n else 0
