"""The FSW topology: which function runs in which rate group (docs/fsw/index.md, Executive).

  RG1 (every tick: 50 Hz, or the scenario's control rate)
                           control: frame -> monitors -> FDIR -> nav -> guidance -> SAMI
                                     -> allocator -> jet driver
  RG2 (10 Hz: every 5th tick at 50 Hz)   fdir_slow: analytic-redundancy residual
  RG3 (1 Hz: every 50th tick at 50 Hz)   entry guidance (mode "npc": predictor-corrector)
Process shells append their own tasks (publish the jet command, ground link) with add().
The batch runner and the SIL FSW process both fly through this object. It stamps the loop
timing fields (records.FSW_STATE_SHELL) of the FSW's output record: release, jitter and
slips when the control task has run, the compute time when the tick has ended.

Real time (executive.rehearse_us > 0): a period asleep leaves the control task's code and
the interpreter's paths through it out of the caches, and the first cycle after it runs
several times slower than the same cycle run back to back. A spare FlightSoftware (the
rehearsal) runs the control cycle on a copy of the last frame shortly before each release
(RealTimeClock.set_rehearsal), so the flying one finds the code warm. The spare is the same
code, not a copy of it; its outputs go nowhere, and its FDIR identifies nothing (mode
oracle without a fault log), so it never rebuilds tables or solves the controllability LP
inside the rehearsal. What the spare cannot warm for the flying one -- its own data searched
by a compiled kernel (the allocator's tables) and the kernel the spare skips (the jet
monitor) -- the flying one rehearses itself, its answers discarded (FlightSoftware.rehearse).
A process shell whose input task waits for its frame after the release (the SIL's FSW) repeats
that own rehearsal between its polls (rehearse_waiting): the wait, with the transport's threads
at work, cools again what the rehearsal warmed. Lockstep and batch have no idle gap and no
rehearsal.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from common.events import EventLog

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
        self.executive.event_time = lambda: fsw.t_s     # its events in mission time, as every other
        self.u: np.ndarray = fsw.driver.last_command
        self.got_frame = False
        out = fsw.output        # views of its loop timing fields, made once
        self._t_release_ns, self._jitter_us, self._slips, self._compute_us = (
            out["t_release_ns"], out["jitter_us"], out["slips"], out["compute_us"])
        self._frame = None
        if frame_source is not None:
            # real time: fetching the newest frame (and waiting briefly for the one due) is its
            # own task, so the control task's compute time is the FSW's alone
            self.executive.add(1, "input", self._input)
        self.executive.add(1, "control", self._control)
        self.executive.add(2, "fdir_slow", lambda c: fsw.slow_step())
        if fsw.entry is not None:
            self.executive.add(3, "entry_guidance", lambda c: fsw.entry_guidance_step())
        self.executive.add(3, "controllability", lambda c: fsw.reassess_step())
        self.rehearsal: FlightSoftware | None = None
        self.rehearsal_errors = 0
        self.wait_rehearsals = 0          # the flying instance's own rehearsals while its input task waited
        self._last_frame = None
        self._rehearsal_frame = None     # the spare's own copy of the last frame (made once)
        lead_ns = int(round(fsw.params["executive.rehearse_us"] * 1e3))
        if isinstance(clock, RealTimeClock) and lead_ns > 0:
            if lead_ns >= period_ns:
                raise ValueError(f"executive.rehearse_us = {lead_ns / 1e3:g} us: not shorter than the control period "
                                 f"({period_ns / 1e3:g} us); set it lower, or 0 for no rehearsal")
            self.rehearsal = FlightSoftware(fsw.scenario, EventLog(),
                                            param_overrides={**fsw.params, "fdir.mode": "oracle"})
            clock.set_rehearsal(self._rehearse, lead_ns)

    def _rehearse(self) -> None:
        """The control cycle of the spare on a copy of the last frame the flying FSW took (never
        raises: a failing rehearsal is counted, the flight goes on)."""
        frame = self._last_frame
        if frame is None:
            return
        try:
            # the spare's frame check writes NaN into bad chamber entries, in place: it works on
            # its own copy, for the record the flying instance took may already hold the next
            # frame (a source that refills one record), which the flying check must see as sent
            mine = self._rehearsal_frame
            if not isinstance(frame, np.ndarray):
                mine = frame                     # not a record: refused by the check, not written
            elif mine is None or mine.dtype != frame.dtype or mine.shape != frame.shape:
                mine = self._rehearsal_frame = frame.copy()
            else:
                np.copyto(mine, frame)
            self.rehearsal.control_step(mine)
            self.fsw.rehearse(frame, self.rehearsal.u_cal_B)
        except Exception:
            self.rehearsal_errors += 1

    def rehearse_waiting(self) -> None:
        """Real time, while the input task waits for the frame due (between its polls): the
        flying instance's own rehearsal alone (FlightSoftware.rehearse on the last frame it took,
        the allocator's query for the spare's last demand), short enough to repeat between polls.
        Changes nothing the next cycle reads; without a rehearsal (lockstep, --no-rehearse)
        nothing; never raises (a failure is counted)."""
        frame = self._last_frame
        if frame is None or self.rehearsal is None:
            return
        try:
            self.fsw.rehearse(frame, self.rehearsal.u_cal_B)
            self.wait_rehearsals += 1
        except Exception:
            self.rehearsal_errors += 1

    def _input(self, cyc: Cycle) -> None:
        self._frame = self.frame_source()

    def _control(self, cyc: Cycle) -> None:
        frame = cyc.frame if cyc.frame is not None else self._frame
        self._frame = None
        self.got_frame = frame is not None
        if frame is None:
            self.u = self.fsw.no_frame(self.fsw.t_s + self.fsw.dt_s)
        else:
            self.u = self.fsw.control_step(frame)
            self._last_frame = frame
        self._t_release_ns[()] = cyc.t_release_ns
        self._jitter_us[()] = (cyc.t_start_ns - cyc.t_release_ns) * 1e-3
        self._slips[()] = self.executive.slips

    def warm_up(self, frame) -> FlightSoftware:
        """Run one control cycle of a throwaway FlightSoftware on ``frame`` so every compiled
        kernel is loaded before the first real cycle (the first call of each numba kernel
        costs tens of ms). The flying instance's state is untouched. Returns the spare (it
        has flown: a source for warming up telemetry encoders). Real time: the rehearsal run
        once and the flying instance's background work warmed (FlightSoftware.warm_background)."""
        spare = FlightSoftware(self.fsw.scenario, param_overrides=None)
        nxt = frame.copy()          # a second, consecutive frame: the second slow step then
        nxt["k"] = frame["k"] + 1   # runs the residual check's kernels too
        nxt["t_ns"] = frame["t_ns"] + int(round(spare.dt_s * 1e9))
        for f in (frame, nxt):
            spare.control_step(f)
            spare.slow_step()
        # the flying instance's own rehearsal (its stages' compiled calls on scratch copies)
        # is code no cycle runs: loaded here too, on the spare, which has flown
        spare.rehearse(nxt, spare.u_cal_B)
        # the cycles off the common path -- no frame, the sensors stale, a frame the check
        # refuses -- call compiled code of their own (the driver, the answers' ring, the record,
        # each on its own): its first call would cost a real cycle milliseconds
        for _ in range(spare.monitor.stale_n + 1):
            spare.no_frame(spare.t_s + spare.dt_s)
        spare.control_step(frame)   # an old step: refused
        spare.control_step(nxt)     # a frame again after them
        spare.close()
        if self.rehearsal is not None:
            # the rehearsal's own first call is cold too (its spare's first cycle, the flying
            # instance's first rehearsed query): run it once now, not just before the first release
            self._last_frame = frame
            self._rehearse()
            self._last_frame = None
        if self.fsw.realtime:
            self.fsw.warm_background()
        return spare

    def close(self) -> None:
        """Stop the rehearsal's spare's background work (the flying FSW is its owner's to
        close); the rehearsal ends with it. Safe to call twice."""
        if self.rehearsal is not None:          # (only ever set on a RealTimeClock)
            self.executive.clock.set_rehearsal(None, 0)
            self.rehearsal.close()
            self.rehearsal = None

    def add(self, group: int, name: str, fn: Callable[[Cycle], object]) -> None:
        self.executive.add(group, name, fn)

    def tick(self, frame=None) -> bool:
        """One base tick (lockstep: with the frame of step k). True if on time."""
        if frame is not None:
            on_time = self.executive.tick(frame, k=int(frame["k"]), t_s=float(frame["t_ns"]) * 1e-9)
        else:
            on_time = self.executive.tick()
        self._compute_us[()] = self.last_compute_ns * 1e-3
        return on_time

    @property
    def last_compute_ns(self) -> int:
        """Compute time of the last cycle, without the input task's wait for its frame."""
        st = self.executive.stats
        if st is None or not st.n:
            return 0
        i = (st.n - 1) % st.capacity
        total = int(st.compute_ns[i])
        if self.frame_source is not None:
            wait = int(st.task_ns[i, self.executive._names.index("input")])
            total -= max(wait, 0)
        return total

    def task_percentiles(self) -> dict[str, dict[str, float]]:
        """p50/p99 [us] of each task over the executive's recent history."""
        st = self.executive.stats
        if st is None:
            return {}
        return {name: {q: (v if q == "runs" else v / 1e3) for q, v in st.task_percentiles(name).items()}
                for _, name in self.executive.tasks()}
