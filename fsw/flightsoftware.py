"""The flight software assembled: what the rate groups call.

RG1 (control, every tick): sensor frame -> monitors -> FDIR -> navigation -> guidance ->
SAMI -> allocator -> jet driver. RG2 (slow): analytic-redundancy check. Ground commands
(``cmd_*``, ``set_param``) arrive between cycles.
This object is the same in the one-process batch runner and in the SIL FSW process; the
process shell only moves records in and out. No transport, threads or clocks here.
"""
from __future__ import annotations

import math
import time

import numpy as np

from common.events import EventLog, Severity
from common import rt
from common.frames import wrap_pi
from common.model import Scenario
from interfaces.vocabulary import MARK_KINDS, N_JETS, CommandResult

from .allocation import Allocator
from .allocation.dutycycle import DutyCycleRealiser
from .control import SamiController
from .controllability import (Controllability, aero_moment_per_rad, controllability, velocity_dir_B,
                              schedule_accel_need_radps2)
from .fdir import Fdir
from .guidance.reference import BankProfile, Guidance
from .health import JetHealth
from .jetdriver import JetDriver
from .modes import FailsafeAction, Failsafes, Mode, ModeManager
from .monitors import SensorMonitor
from .navigation import Navigation
from .guidance.npc import PARAMS as NPC_PARAMS, EntryGuidance
from .params import Param, ParamRegistry
from . import executive

Reply = tuple[CommandResult, str]
COMMAND_RING = 64      # answers kept for FDIR (1.28 s at 50 Hz): a command held longer is not judged
_MODE_CHOICES = ",".join(f"{int(m)} {m.name}" for m in Mode)

GUIDANCE_PARAMS = [
    Param("guidance.authority_use", 0.05, 1.0, "",
          "after a reconfiguration the reference's bank acceleration is capped at this fraction of the weaker "
          "way of the controllability LP's bank authority (the rest is kept for the feedback)"),
    Param("guidance.trim_max_deg", 0.0, 30.0, "deg",
          "largest alpha/beta trim offset accepted to absorb a stuck-on bias the jets cannot cancel"),
]


def declarations() -> tuple[tuple[str, list[Param]], ...]:
    """Every FSW parameter, by the owner that declares it and applies a new value."""
    return (("FlightSoftware", GUIDANCE_PARAMS), ("SamiController", SamiController.PARAMS),
            ("EntryGuidance", NPC_PARAMS), ("Allocator", Allocator.PARAMS), ("Fdir", Fdir.PARAMS),
            ("SensorMonitor", SensorMonitor.PARAMS),
            ("Failsafes", Failsafes.PARAMS), ("JetDriver", JetDriver.PARAMS), ("Executive", executive.PARAMS))


def all_params() -> list[Param]:
    return [p for _, plist in declarations() for p in plist]


class FlightSoftware:
    """All FSW functions wired together. ``scenario`` supplies only what the FSW may know:
    the nominal vehicle and planet models, the guidance schedule, and parameter overrides."""

    def __init__(self, scenario: Scenario, events: EventLog | None = None, start_mode: Mode = Mode.ENTRY,
                 armed: bool = True, param_overrides: dict | None = None, realtime: bool = False):
        """``realtime``: the allocator rebuilds its tables in the background after a health
        change (the loop never waits for it); lockstep and batch stay synchronous, so they
        are deterministic."""
        self.scenario = scenario
        veh, planet = scenario.vehicle, scenario.planet
        self.dt_s = scenario.dt_control_s
        self.events = events if events is not None else EventLog()
        overrides = dict(scenario.fsw)
        if param_overrides:
            overrides.update(param_overrides)
        self.registry = ParamRegistry(declarations(), overrides)
        self.params = self.registry.values          # current values, read by the owners below

        self.nav = Navigation(planet, veh)
        # guidance mode (spec 60-guidance.md): the scenario's bank schedule, or the
        # predictor-corrector's command through its shaper; the attitude chain is the same
        self.entry = None
        if scenario.guidance_mode == "npc":
            self.entry = EntryGuidance(scenario, self.params, self.events, self.dt_s, realtime=realtime)
            profile = self.entry.shaper
        else:
            profile = BankProfile(scenario.bank_schedule, scenario.bank_rate_limit_radps,
                                  scenario.bank_accel_limit_radps2)
        self.guidance = Guidance(profile, veh.aero.alpha_trim_rad, planet.omega_radps)
        self.control = SamiController(self.params, veh, self.dt_s)
        self.allocator = Allocator(veh.torque_matrix_Nm, veh.thrust_N, self.params, async_rebuild=realtime)
        self.fdir = Fdir(self.params, self.dt_s, self.events)
        self.driver = JetDriver(veh.thrust_N, veh.isp_s, planet.g0_mps2, self.dt_s, self.events)
        self.modes = ModeManager(self.events)
        self.monitor = SensorMonitor(self.events, self.dt_s, self.params, planet.radius_m)
        self.failsafes = Failsafes(self.params, self.modes)

        self.driver.set_param("driver.arm_on_entry", self.params["driver.arm_on_entry"])
        reg = self.registry            # each owner applies its own parameters
        reg.bind("FlightSoftware", self._set_guidance_param)
        reg.bind("SamiController", self.control.set_param)
        reg.bind("Allocator", self._set_allocator_param)
        reg.bind("Fdir", self.fdir.set_param)
        reg.bind("SensorMonitor", self.monitor.set_param)
        reg.bind("Failsafes", self.failsafes.set_param)
        reg.bind("JetDriver", self.driver.set_param)
        reg.bind("EntryGuidance", self.entry.set_param if self.entry is not None else self._npc_not_flown)
        reg.check_bound()

        if start_mode != Mode.STANDBY:
            self.modes.request(0.0, start_mode, "start")
        self.driver.arm(0.0, armed)
        self.allocator.set_health(self.fdir.health_active)
        self._tables_version = self.allocator.tables_version

        self.k = -1
        self.t_s = 0.0
        self.u_cal_B = np.zeros(3)
        self.tau_alloc_B = np.zeros(3)
        # the bank axis (velocity direction at trim, body axes) and its jet quantum: a cycle is
        # short when the torque delivered about it falls short of the demand by more than
        # control.shortfall_frac of a demand worth two or more of the largest jet increments
        # (the rule SAMI's saturation awareness applies per body axis)
        self.bank_axis_B = velocity_dir_B(veh.aero.alpha_trim_rad)
        self._bank_short_min_Nm = 2.0 * float(np.max(np.abs(self.bank_axis_B @ np.asarray(veh.torque_matrix_Nm))))
        # while the bank axis falls short, the duty-cycle LP's average realised over cycles
        # (fsw/allocation/dutycycle.py) instead of one pattern per cycle
        self.dutycycle = DutyCycleRealiser(self.bank_axis_B, veh.torque_matrix_Nm, veh.thrust_N)
        self.dutycycle.short_min_Nm = self._bank_short_min_Nm
        self.alloc_short = False
        self.alloc_short_cycles = 0
        self._trim_ref = None          # (dalpha, beta [rad], qbar [Pa]) of the LP's trim, None: none
        self._omega_prev = np.zeros(3)
        # the RG2 residual compares the rate change over its interval with the torque the jets
        # gave over it: the mean of the interval's RG1 commands (the allocator's torque changes
        # from cycle to cycle; one cycle's sample misstates it). Each cycle adds the torque of
        # the cycle before it (the one that acted up to this frame); jets held off add zero.
        self._tau_last = np.zeros(3)
        self._tau_sum = np.zeros(3)
        self._tau_n = 0
        self._tau_mean = np.zeros(3)
        self._have_prev = False
        self.alloc_ns = 0
        self.reconfig_times: list[float] = []
        self.cycles = 0
        self.bank_err_rad = 0.0
        self._frame_views: tuple = (None,)
        self._zero_u = np.zeros(self.driver.n, dtype=np.uint8)   # jets off
        # the commands this FSW answered frames with, by frame index: FDIR judges each jet by
        # the command the plant reports it held (SENSORS.u_k), which in real time can be an
        # older one than the last sent (a late answer: the plant held the one before)
        self._sent = np.zeros((COMMAND_RING, self.driver.n), dtype=np.uint8)
        self._sent_k = np.full(COMMAND_RING, -2, dtype=np.int64)
        self._zero3 = np.zeros(3)
        self._residual_ready = False                   # RG2 has one earlier sample to difference
        self.realtime = realtime
        self.controllability: Controllability | None = None   # the LP's answer at the last reconfiguration
        self._lp_worker: _LpWorker | None = None
        self._lp_periodic = (False, False)   # the answer awaited is (a periodic re-assessment, with the held trim)
        self._assess_pending = False

    # ---------------------------------------------------------------- RG1
    def control_step(self, frame) -> np.ndarray:
        """One control cycle on a SENSORS record; returns the jet command (uint8, one per jet)."""
        self.cycles += 1
        self._count_torque()
        t_s = float(frame["t_ns"]) * 1e-9     # a Python float (a 0-d field times 1e-9 is a NumPy scalar)
        ok = self.monitor.check(t_s, frame)
        if not ok or self.monitor.stale:
            return self._hold_off(t_s)
        fv = self._frame_views
        if fv[0] is not frame:     # field views of the record, made once per record object
            fv = self._frame_views = (frame, frame["sigma_BN"], frame["omega_BN_B"], frame["r_N"], frame["v_N"],
                                      frame["accel_B"], frame["chamber"])
        self.k = self.monitor.last_k
        self.t_s = t_s
        if self.fdir.update(t_s, self._command_in_force(int(frame["u_k"])), fv[6]):
            self.allocator.set_health(self.fdir.health_active)
            self.reconfig_times.append(t_s)
            self._assess_pending = True
        nav = self.nav.update(t_s, fv[1], fv[2], fv[3], fv[4], fv[5])
        if self._assess_pending:
            self._assess_pending = False
            self.assess_controllability(t_s)
        if self._lp_worker is not None and self._lp_worker.ready():
            need, r = self._lp_worker.take()
            self._apply_controllability(t_s, need, r, *self._lp_periodic)     # re-planned from now
        if self.entry is not None:
            self.entry.steer(nav)
        self._hold_trim(nav.qbar_pa)
        self.guidance.update(nav)
        self.bank_err_rad = wrap_pi(nav.bank_rad - self.guidance.phi_r)
        if self.failsafes.evaluate(t_s, self.dt_s, sensors_stale=False,
                                   tracking_error_rad=self.bank_err_rad) == FailsafeAction.HOLD_JETS_OFF:
            return self._hold_off(t_s)
        mode = self.modes.mode
        if mode == Mode.ENTRY:
            # no learning while FDIR holds a detection not yet reconfigured: the torque
            # commanded through the faulty jets is not what the tracking error saw
            self.control.freeze = not self.modes.adaptation_enabled or self.fdir.reconfig_pending
            u_cal = self.control.update(nav, self.guidance, self.tau_alloc_B if self._have_prev else None)
        elif mode == Mode.SAFE:
            self.control.freeze = True
            u_cal = self.control.safe_torque(nav)
        else:
            u_cal = self._zero3
        self.u_cal_B[:] = u_cal
        self.dutycycle.short_frac = self.params["control.shortfall_frac"]
        t0 = time.perf_counter_ns()
        u_alloc = self.dutycycle.solve(self.allocator, self.u_cal_B)
        self.alloc_ns = time.perf_counter_ns() - t0
        self.tau_alloc_B[:] = self.dutycycle.tau_B
        if self.allocator.tables_version != self._tables_version:      # new tables in use
            self._tables_version = self.allocator.tables_version
            self.dutycycle.reset()
            self.events.emit(t_s, Severity.NOTICE, "allocator", "reconfigured",
                             f"ALLOCATOR RECONFIGURED ({self.allocator.rebuild_time_s * 1e3:.1f} ms)")
        if self.allocator.degraded:
            self.events.emit(t_s, Severity.WARNING, "allocator", "alloc_degraded",
                             "ALLOCATION DEGRADED (infeasible)", rate_limited=True)
        self._check_bank_shortfall(t_s)
        self._have_prev = True
        self._tau_last[:] = self.tau_alloc_B
        return self._sent_for(self.driver.command(u_alloc, self.modes.jets_enabled))

    def _sent_for(self, u: np.ndarray) -> np.ndarray:
        """Note ``u`` as this frame's answer (frame index self.k); returns u."""
        i = self.k % COMMAND_RING
        self._sent[i] = u
        self._sent_k[i] = self.k
        return u

    def _command_in_force(self, u_k: int) -> np.ndarray | None:
        """The command the plant held over the period just ended: the answer to frame
        ``u_k``, jets off for -1, None when this FSW has no record of it (then FDIR takes the
        period as no evidence)."""
        if u_k == -1:
            return self._zero_u
        i = u_k % COMMAND_RING
        return self._sent[i] if self._sent_k[i] == u_k else None

    def _check_bank_shortfall(self, t_s: float) -> None:
        ax = self.bank_axis_B
        d = float(ax[0] * self.u_cal_B[0] + ax[1] * self.u_cal_B[1] + ax[2] * self.u_cal_B[2])
        got = float(ax[0] * self.tau_alloc_B[0] + ax[1] * self.tau_alloc_B[1] + ax[2] * self.tau_alloc_B[2])
        self.alloc_short = (abs(d) > self._bank_short_min_Nm
                            and (d - got) * np.sign(d) > self.params["control.shortfall_frac"] * abs(d))
        if self.alloc_short:
            self.alloc_short_cycles += 1
            self.events.emit(t_s, Severity.WARNING, "allocator", "alloc_short",
                             "ALLOCATION SHORT ON BANK AXIS", rate_limited=True)

    def _lp_problem(self, t_s: float, held_trim_rad=None) -> tuple:
        """(schedule's need, arguments of controllability()) for the health the allocator uses;
        the authority promised for every inertia within the vehicle's stated uncertainty about
        its nominal inertia (the box known to hold the truth). SAMI's inertia estimate is not
        used as that knowledge: with the dead zone it stays at nominal or drifts along what the
        tracking excites (campaign 777 run 13: I33 6,954 against a truth of 5,002 kg m^2)."""
        nav = self.nav.state
        veh = self.scenario.vehicle
        a = veh.aero
        d = self.control.d_hat
        V = nav.V_rel_mps
        v_B = nav.C_BN @ nav.vrel_N / V if V > 1.0 else None
        if v_B is None or not np.all(np.isfinite(v_B)):     # no flight condition yet: the trim direction
            v_B = velocity_dir_B(a.alpha_trim_rad)
        A = aero_moment_per_rad(nav.qbar_pa, veh.S_ref_m2, veh.l_ref_m, a.C_lbeta * d[0], a.C_malpha * d[1],
                                a.C_nbeta * d[2])
        need = schedule_accel_need_radps2(self.scenario.bank_schedule, t_s)
        args = (veh.torque_matrix_Nm, self.allocator_health().copy(), veh.inertia_kgm2, v_B, A,
                self.params["guidance.trim_max_deg"], need, float(nav.qbar_pa), veh.inertia_uncertainty_frac,
                held_trim_rad)
        return need, args

    def assess_controllability(self, t_s: float, periodic: bool = False, held_trim_rad=None) -> None:
        """The duty-cycle LP (fsw/controllability.py) on the health the allocator now uses, with
        the FSW's own models: inertia estimate, velocity direction from navigation, the aero
        moment of its density model, nominal derivatives and current factors d_hat. In real time
        it runs on a background thread (tens of ms: longer than a control period); its answer is
        applied by the first cycle after it is ready. Batch and lockstep apply it here.
        ``periodic``: a re-assessment of the same health (``reassess_step``); ``held_trim_rad``:
        the authority with the trim offset the reference flies now (no new trim sought)."""
        need, args = self._lp_problem(t_s, held_trim_rad)
        if not self.realtime:
            self._apply_controllability(t_s, need, controllability(*args), periodic, held_trim_rad is not None)
            return
        if self._lp_worker is None:
            self._lp_worker = _LpWorker()
        self._lp_periodic = (periodic, held_trim_rad is not None)
        self._lp_worker.submit(need, args)

    def reassess_step(self) -> None:
        """RG3 (1 Hz): the LP asked again while a stuck-on bias the jets cannot cancel has no
        trim yet (the aerodynamic moment grows with the dynamic pressure: a stuck-on jet found
        early, at qbar near 0, gets its trim once the air can give it). Once a trim exists it is
        carried by its qbar scaling (``_hold_trim``) and the LP is not asked again: a fresh
        solve may return another of its equally good trims, and the reference's alpha/beta
        would jump between them (campaign run 54: 1.3 deg -> 9.2 deg with re-solves at 1 Hz).

        While a trim is held, the authority is asked again with that trim as flown now: the
        jets' share of the bias grows as the dynamic pressure falls (the offset is held within
        guidance.trim_max_deg) and the aerodynamic factors are learned, so the authority found
        at the reconfiguration's dynamic pressure does not hold for a reversal flown at the
        entry's lowest (campaign 777 run 0: assessed at 6,400 Pa, reversal at 280 Pa)."""
        r = self.controllability
        if (r is None or self._assess_pending or self.cycles == 0 or r.bias_Nm == 0.0
                or (self._lp_worker is not None and self._lp_worker.busy())):
            return
        if self._trim_ref is not None:
            g = self.guidance
            self.assess_controllability(self.t_s, periodic=True,
                                        held_trim_rad=(g.trim_offset_alpha_rad, g.trim_offset_beta_rad))
        elif not math.isfinite(r.trim_needed_deg):
            self.assess_controllability(self.t_s, periodic=True)

    def _hold_trim(self, qbar_pa: float) -> None:
        """The reference's alpha/beta offset that lets the aerodynamic moment absorb the part of
        the stuck-on bias the jets cannot cancel (the LP's trim, fsw/controllability.py), instead
        of SAMI fighting it with torque that does not exist. That residual torque is fixed and
        the aerodynamic moment grows with dynamic pressure, so the offset is the LP's times
        qbar_LP / qbar, held within guidance.trim_max_deg."""
        g = self.guidance
        tr = self._trim_ref
        if tr is None:
            g.trim_offset_alpha_rad = g.trim_offset_beta_rad = 0.0
            return
        k = tr[2] / qbar_pa if qbar_pa > 0.0 and math.isfinite(qbar_pa) else math.inf
        k = min(k, math.radians(self.params["guidance.trim_max_deg"]) / max(abs(tr[0]), abs(tr[1])))
        g.trim_offset_alpha_rad = tr[0] * k
        g.trim_offset_beta_rad = tr[1] * k

    def _apply_controllability(self, t_s: float, need: float, r: Controllability, periodic: bool = False,
                               held: bool = False) -> None:
        """Event and telemetry of the LP's answer; the guidance re-planned to the weaker way's
        authority times ``guidance.authority_use`` (the scenario's limit stays the ceiling), never
        below what the schedule still needs (the reference then keeps the schedule's pace: the
        tracking, not the reference, shows what the jets cannot do). A periodic re-assessment
        whose answer reads the same as the last (the event's precision: 0.01 deg/s^2, 1 N m,
        0.1 deg) and keeps its verdict changes nothing but the trim's dynamic pressure.
        ``held``: the answer with the held trim (``reassess_step``): the trim stays, and the
        reference is only ever slowed by it (the authority it needs is no longer there), never
        sped up again before the next reconfiguration (no re-shaping back and forth as the
        dynamic pressure falls and rises)."""
        last, self.controllability = self.controllability, r
        if held:
            if last is not None and r.controllable != last.controllable and not r.controllable:
                self.events.emit(t_s, Severity.WARNING, "guidance", "not_controllable",
                                 f"NOT CONTROLLABLE: {r.reason}"[:50])
            if self._reference_limit(need, r)[0] < self.guidance.profile.accel_limit_radps2:
                self._replan_to(t_s, need, r)      # says so when the limit's text changes
            return
        if periodic and last is not None and r.text() == last.text() and r.controllable == last.controllable:
            self._set_trim_ref(r)
            return
        self.events.emit(t_s, Severity.NOTICE, "guidance", "controllability", r.text())
        self._set_trim_ref(r)
        if periodic and last is not None and r.controllable == last.controllable:
            self._replan_to(t_s, need, r)
            return
        if not r.controllable:
            self.events.emit(t_s, Severity.WARNING, "guidance", "not_controllable",
                             f"NOT CONTROLLABLE: {r.reason}"[:50])
        self._replan_to(t_s, need, r)

    def _set_trim_ref(self, r: Controllability) -> None:
        trim = (math.radians(r.trim_alpha_deg), math.radians(r.trim_beta_deg))
        self._trim_ref = ((trim[0], trim[1], r.qbar_pa) if all(map(math.isfinite, (*trim, r.qbar_pa)))
                          and max(map(abs, trim)) > 0.0 and r.qbar_pa > 0.0 else None)

    def _reference_limit(self, need: float, r: Controllability) -> tuple[float, bool]:
        """(the reference's acceleration limit for the LP's answer, True when that is the
        schedule's need because the authority is below it): ``guidance.authority_use`` of the
        weaker way, within the scenario's limit. 0 when neither gives anything."""
        accel = self.params["guidance.authority_use"] * min(r.authority_pos_radps2, r.authority_neg_radps2)
        low = accel < need
        accel = need if low else accel
        return (min(self.scenario.bank_accel_limit_radps2, accel) if accel > 0.0 else 0.0), low

    def _replan_to(self, t_s: float, need: float, r: Controllability) -> None:
        limit, low = self._reference_limit(need, r)
        if low:
            weak = min(r.authority_pos_radps2, r.authority_neg_radps2)
            self.events.emit(t_s, Severity.WARNING, "guidance", "authority_low",
                             f"BANK AUTH {np.degrees(weak):.2f} DEG/S2: REF KEPT AT NEED")
        if limit <= 0.0:
            return
        prof = self.guidance.profile
        # the same limit at the precision the event states (0.01 deg/s^2) is no new reference:
        # answers of equal LPs differ in their last bits, and each re-plan would say so again
        if _limit_text(limit) == _limit_text(prof.accel_limit_radps2):
            return
        if prof.replan(t_s, prof.rate_limit_radps, limit):
            self.events.emit(t_s, Severity.NOTICE, "guidance", "reference_reshaped",
                             f"REFERENCE ACCEL LIMIT {_limit_text(limit)} DEG/S2")

    def no_frame(self, t_s: float) -> np.ndarray:
        """A control cycle in which no fresh sensor frame arrived (SIL): counts towards
        STALE and holds the jets off once stale."""
        self.cycles += 1
        self._count_torque()
        self._tau_last[:] = 0.0
        self.t_s = t_s
        self.monitor.tick(t_s, got_frame=False)
        if self.monitor.stale:
            return self._hold_off(t_s)
        return self._sent_for(self.driver.command(self._zero_u, False))

    def _count_torque(self) -> None:
        self._tau_sum += self._tau_last
        self._tau_n += 1

    def _hold_off(self, t_s: float) -> np.ndarray:
        """Jets off, nothing learnt: a rejected frame or stale sensors."""
        self._have_prev = False
        self.u_cal_B[:] = 0.0
        self.dutycycle.reset()
        self.tau_alloc_B[:] = 0.0
        self._tau_last[:] = 0.0
        self.alloc_short = False
        return self._sent_for(self.driver.command(self._zero_u, False))

    # ---------------------------------------------------------------- RG2
    def slow_step(self) -> None:
        """RG2: analytic-redundancy residual (needs two consecutive good cycles)."""
        nav = self.nav.state
        if self._have_prev and self._residual_ready and self._tau_n > 0:
            np.multiply(self._tau_sum, 1.0 / self._tau_n, out=self._tau_mean)
            self.fdir.residual_check(self.t_s, nav.omega_BN_B, self._omega_prev, self._tau_n * self.dt_s,
                                     self._tau_mean, self.control.aero_torque_est(nav),
                                     self.control.inertia_hat())
        self._omega_prev[:] = nav.omega_BN_B
        self._tau_sum[:] = 0.0
        self._tau_n = 0
        self._residual_ready = True

    def entry_guidance_step(self) -> None:
        """Slow rate group (mode "npc"): one predictor-corrector cycle on the latest navigation."""
        if self.entry is not None and self.cycles > 0:
            self.entry.cycle(self.nav.state, self.t_s)

    # ---------------------------------------------------------------- commands
    # The ground's requests (the ground link translates MAVLink to these). Each returns
    # (CommandResult, reason): the reason says why a request was refused, for the operator;
    # nothing here raises on a bad request. A command acts between control cycles (the
    # executive runs the ground link in the same thread), so it holds from the next cycle.

    def cmd_mode(self, mode) -> Reply:
        """Request a mode (Mode, its number or name); entering ENTRY arms the jets when
        driver.arm_on_entry is set."""
        try:
            target = Mode[mode.upper()] if isinstance(mode, str) else Mode(int(mode))
        except (KeyError, ValueError, TypeError, AttributeError):
            return CommandResult.DENIED, f"MODE {mode!s:.12} DENIED ({_MODE_CHOICES})"
        before = self.modes.mode
        if not self.modes.request(self.t_s, target, "ground"):
            return CommandResult.DENIED, ""              # ModeManager already said why
        if target == Mode.ENTRY and before != Mode.ENTRY:
            self.driver.entering_entry(self.t_s)
        return CommandResult.ACCEPTED, ""

    def cmd_arm(self, on: bool) -> Reply:
        self.driver.arm(self.t_s, bool(on))
        return CommandResult.ACCEPTED, ""

    def cmd_fault_tolerance(self, on: bool) -> Reply:
        self.set_param("allocator.fault_tolerance", float(bool(on)))
        self.events.emit(self.t_s, Severity.NOTICE, "ground", "fault_tolerance",
                         f"GND FAULT TOLERANCE {'ON' if on else 'OFF'}")
        return CommandResult.ACCEPTED, ""

    def cmd_mark(self, jet: int, kind: str, eta: float = 1.0) -> Reply:
        """Operator override of one jet's health (a MARK_KINDS word); "inhibited" sets the
        inhibit mask instead. The allocator adopts it now."""
        if not _jet_in(jet, 1):
            return CommandResult.DENIED, f"MARK JET {jet} DENIED (1..{N_JETS})"
        if kind not in MARK_KINDS:
            return CommandResult.DENIED, f"MARK KIND {kind!s:.12} DENIED"
        jet = int(jet)
        if kind == "inhibited":
            return self.cmd_inhibit(jet, True)
        if kind == "degraded" and not (isinstance(eta, (int, float)) and math.isfinite(eta) and 0.0 < eta < 1.0):
            return CommandResult.DENIED, f"MARK ETA {eta:g} DENIED (0<ETA<1)"
        try:
            self.fdir.override(self.t_s, jet, kind, float(eta) if kind == "degraded" else 1.0)
        except ValueError as e:
            return CommandResult.DENIED, f"MARK DENIED: {e}"
        self.health_changed()
        return CommandResult.ACCEPTED, ""

    def cmd_inhibit(self, jet: int, on: bool) -> Reply:
        """The ground inhibit mask (jet 0 = all): the driver never fires the jet and the
        allocator no longer plans with it."""
        if not _jet_in(jet, 0):
            return CommandResult.DENIED, f"INHIBIT JET {jet} DENIED (0..{N_JETS})"
        self.driver.set_inhibit(self.t_s, int(jet), bool(on))
        self.fdir.set_inhibit(self.t_s, int(jet), bool(on))
        self.health_changed()
        return CommandResult.ACCEPTED, ""

    def cmd_clear(self, jet: int) -> Reply:
        """FDIR latch, pending reconfiguration, override and inhibit of ``jet`` (0 = all) cleared."""
        if not _jet_in(jet, 0):
            return CommandResult.DENIED, f"CLEAR JET {jet} DENIED (0..{N_JETS})"
        self.fdir.clear(self.t_s, int(jet))
        return self.cmd_inhibit(jet, False)

    def cmd_delay(self, delay_s: float) -> Reply:
        """FDIR isolation-to-reconfiguration delay for detections from now on."""
        try:
            v = self.set_param("fdir.delay_s", delay_s)
        except ValueError as e:
            return CommandResult.DENIED, f"DELAY DENIED: {str(e).split(': ', 1)[-1]}"
        self.events.emit(self.t_s, Severity.NOTICE, "fdir", "fdir_delay", f"FDIR DELAY {v:.2f} S")
        return CommandResult.ACCEPTED, ""

    def set_param(self, name: str, value: float) -> float:
        """Validated parameter set, applied by its owner; ValueError (nothing changed) when
        refused (fsw/params.py ParamRegistry)."""
        return self.registry.set(name, value)

    def close(self) -> None:
        """Stop background work (the allocator's table builder, the controllability LP)."""
        self.allocator.close()
        if self._lp_worker is not None:
            self._lp_worker.close()
        if self.entry is not None:
            self.entry.close()

    def warm_background(self, timeout_s: float = 10.0) -> bool:
        """Before the first cycle (real time): the allocator's single-fault pre-builds finished
        and the controllability LP solved once here (answer discarded), so the first fault's
        reconfiguration finds nothing cold. Cold, the LP thread's first solve loads HiGHS
        (~150 ms holding the GIL) while the allocator's builder and the control thread wait,
        and the new tables queue behind the pre-builds. True if the builder is idle in time.

        The LP is solved once on this thread (the loop's: the duty-cycle realiser's HiGHS) and
        once on the LP's own worker thread, started here: HiGHS sets itself up per thread, and
        the worker's first solve, cold at the first fault, held the GIL so long that the
        control task of case1's detection cycle took 18-24 ms in the real-time SIL (a slip in
        about half the 20-s runs; 4.5 ms warm)."""
        need, args = self._lp_problem(self.t_s)
        controllability(*args)
        t_end = time.monotonic() + timeout_s
        if self._lp_worker is None:
            self._lp_worker = _LpWorker()
        self._lp_worker.submit(need, args)
        while self._lp_worker.busy() and not self._lp_worker.ready() and time.monotonic() < t_end:
            time.sleep(0.002)
        self._lp_worker.take()                  # the answer is discarded
        return self.allocator.wait_idle(max(0.0, t_end - time.monotonic()))

    def health_changed(self) -> None:
        """Hand the allocator the health FDIR now holds (after an override, clear or inhibit)
        and ask the LP what the jets can do with it."""
        self.allocator.set_health(self.fdir.health_active)
        self.assess_controllability(self.t_s)

    # ---------------------------------------------------------------- owners' hooks
    def _set_guidance_param(self, name: str, value: float) -> None:
        """guidance.*: the LP and the re-plan read them from ``params`` (already holding the
        new value); after a reconfiguration, assess again so the reference uses it now."""
        if self.controllability is not None:
            self.assess_controllability(self.t_s)

    def _npc_not_flown(self, name: str, value: float) -> None:
        """npc.* in a profile-mode flight: refused, so no value is acknowledged and ignored."""
        raise ValueError(f"{name}: not flown in mode {self.scenario.guidance_mode}")

    def _set_allocator_param(self, name: str, value: float) -> None:
        if name == "allocator.fault_tolerance":
            self.allocator.set_fault_tolerance(bool(value))
        else:
            self.allocator.set_params({**self.params, name: value})
        self.health_changed()

    def allocator_health(self) -> JetHealth:
        """The health the allocator is solving with (nominal when fault tolerance is off)."""
        return self.fdir.health_active if self.allocator.fault_tolerance else JetHealth()

    @property
    def health(self) -> JetHealth:
        return self.fdir.health_active


class _LpWorker:
    """One background thread for the controllability LP in real time: the newest request
    wins (a request overtaken by a newer health is dropped, and so is an answer not yet
    taken); the loop polls ``ready``. ``solve``: the job, controllability() (tests wrap it
    to inject delays)."""

    def __init__(self, solve=controllability):
        import threading
        self._solve = solve
        self._cv = threading.Condition()
        self._job = None
        self._result = None
        self._running = False
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="controllability", daemon=True)
        self._thread.start()

    def submit(self, need: float, args: tuple) -> None:
        with self._cv:
            self._job = (need, args)
            self._result = None                # an answer to an older request is stale
            self._cv.notify()

    def ready(self) -> bool:
        return self._result is not None

    def busy(self) -> bool:
        """A request queued, being solved, or its answer not yet taken."""
        return self._job is not None or self._running or self._result is not None

    def take(self) -> tuple:
        with self._cv:
            r, self._result = self._result, None
        return r

    def _run(self) -> None:
        rt.run_below_loop()
        while True:
            with self._cv:
                while self._job is None and not self._stop:
                    self._cv.wait()
                if self._stop:
                    return
                (need, args), self._job = self._job, None
                self._running = True
            r = self._solve(*args)
            with self._cv:
                self._running = False
                if self._job is None:          # else a newer health is queued: this answer is stale
                    self._result = (need, r)

    def close(self) -> None:
        with self._cv:
            self._stop = True
            self._cv.notify()
        self._thread.join(timeout=5.0)


def _limit_text(accel_radps2: float) -> str:
    """The reference's acceleration limit as events state it [deg/s^2]."""
    return f"{math.degrees(accel_radps2):.2f}"


def _jet_in(jet, lo: int) -> bool:
    """A jet number lo..N_JETS given as an integer or an integral float (a MAVLink param)."""
    try:
        return float(jet).is_integer() and lo <= jet <= N_JETS and not isinstance(jet, bool)
    except (TypeError, ValueError, OverflowError):
        return False
