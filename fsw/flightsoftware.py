"""The flight software assembled: what the rate groups call.

RG1 (control, every tick): sensor frame -> monitors -> FDIR -> navigation -> guidance ->
SAMI -> allocator -> jet driver. RG2 (slow): analytic-redundancy check. RG3: housekeeping.
This object is the same in the one-process batch runner and in the SIL FSW process; the
process shell only moves records in and out. No transport, threads or clocks here.
"""
from __future__ import annotations

import time

import numpy as np

from common.frames import wrap_pi

from common.model import Scenario
from .allocation import Allocator
from .control import SamiController
from .events import EventLog, Severity
from .fdir import Fdir
from .guidance import BankProfile, Guidance
from .health import JetHealth
from .jetdriver import JetDriver
from .modes import FailsafeAction, Failsafes, Mode, ModeManager
from .monitors import SensorMonitor
from .navigation import Navigation
from .params import Param, load_params
from . import executive

GUIDANCE_PARAMS = [
    Param("guidance.authority_factor", 0.0, 10.0, "",
          "after a reconfiguration, the reference's bank acceleration is capped at this multiple of the "
          "weaker one-way body-roll acceleration of a pure-roll allocator probe (0 = never re-shape)"),
]


def all_params() -> list[Param]:
    return (GUIDANCE_PARAMS + SamiController.PARAMS + Allocator.PARAMS + Fdir.PARAMS + JetDriver.PARAMS + executive.PARAMS)


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
        self.param_table = {p.name: p for p in all_params()}
        self.params = load_params(all_params(), overrides)

        self.nav = Navigation(planet, veh)
        self.guidance = Guidance(BankProfile(scenario.bank_schedule, scenario.bank_rate_limit_radps,
                                             scenario.bank_accel_limit_radps2),
                                 veh.aero.alpha_trim_rad, planet.omega_radps)
        self.control = SamiController(self.params, veh, self.dt_s)
        self.allocator = Allocator(veh.torque_matrix_Nm, veh.thrust_N, self.params, async_rebuild=realtime)
        self.fdir = Fdir(self.params, self.dt_s, self.events)
        self.driver = JetDriver(veh.thrust_N, veh.isp_s, planet.g0_mps2, self.dt_s, self.events)
        self.modes = ModeManager(self.events)
        self.monitor = SensorMonitor(self.events, self.dt_s, self.params, planet.radius_m)
        self.failsafes = Failsafes(self.params, self.modes)

        if start_mode != Mode.STANDBY:
            self.modes.request(0.0, start_mode, "start")
        self.driver.arm(0.0, armed)
        self.allocator.set_health(self.fdir.health_active)
        self._tables_version = self.allocator.tables_version

        self.k = -1
        self.t_s = 0.0
        self.u_cal_B = np.zeros(3)
        self.tau_alloc_B = np.zeros(3)
        self._omega_prev = np.zeros(3)
        self._tau_cmd_prev = np.zeros(3)
        self._have_prev = False
        self.alloc_ns = 0
        self.reconfig_times: list[float] = []
        self.cycles = 0
        self.bank_err_rad = 0.0
        self._frame_views: tuple = (None,)
        self._zero_u = np.zeros(18, dtype=np.uint8)   # jets off
        self._zero3 = np.zeros(3)
        self._residual_ready = False                   # RG2 has one earlier sample to difference
        self._residual_dt = 0.0

    # ---------------------------------------------------------------- RG1
    def control_step(self, frame) -> np.ndarray:
        """One control cycle on a SENSORS record; returns the jet command (uint8, 18)."""
        self.cycles += 1
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
        if self.fdir.update(t_s, self.driver.last_command, fv[6]):
            self.allocator.set_health(self.fdir.health_active)
            self.reconfig_times.append(t_s)
            self.fit_reference_to_authority(t_s)
        nav = self.nav.update(t_s, fv[1], fv[2], fv[3], fv[4], fv[5])
        self.guidance.update(nav)
        self.bank_err_rad = wrap_pi(nav.bank_rad - self.guidance.phi_r)
        if self.failsafes.evaluate(t_s, self.dt_s, sensors_stale=False,
                                   tracking_error_rad=self.bank_err_rad) == FailsafeAction.HOLD_JETS_OFF:
            return self._hold_off(t_s)
        mode = self.modes.mode
        if mode == Mode.ENTRY:
            self.control.freeze = not self.modes.adaptation_enabled
            u_cal = self.control.update(nav, self.guidance, self.tau_alloc_B if self._have_prev else None)
        elif mode == Mode.SAFE:
            self.control.freeze = True
            u_cal = self.control.safe_torque(nav)
        else:
            u_cal = self._zero3
        self.u_cal_B[:] = u_cal
        t0 = time.perf_counter_ns()
        u_alloc = self.allocator.solve(self.u_cal_B)
        self.alloc_ns = time.perf_counter_ns() - t0
        self.tau_alloc_B[:] = self.allocator.tau_B
        if self.allocator.tables_version != self._tables_version:      # new tables in use
            self._tables_version = self.allocator.tables_version
            self.events.emit(t_s, Severity.NOTICE, "allocator", "reconfigured",
                             f"ALLOCATOR RECONFIGURED ({self.allocator.rebuild_time_s * 1e3:.1f} ms)")
        if self.allocator.degraded:
            self.events.emit(t_s, Severity.WARNING, "allocator", "alloc_degraded",
                             "ALLOCATION DEGRADED (infeasible)", rate_limited=True)
        self._have_prev = True
        return self.driver.command(u_alloc, self.modes.jets_enabled)

    def roll_authority_Nm(self) -> tuple[float, float]:
        """(positive, negative) roll torque [N m] the allocator can give now with pitch and
        yaw held as well as it can: its answers to a pure-roll demand each way."""
        probe = np.zeros(3)
        out = []
        for sign in (1.0, -1.0):
            probe[0] = sign * 1e5
            self.allocator.solve(probe)
            out.append(max(0.0, sign * float(self.allocator.tau_B[0])))
        return out[0], out[1]

    def fit_reference_to_authority(self, t_s: float) -> None:
        """Guidance that knows its actuators: after a reconfiguration, transitions not yet
        started keep their bank acceleration within ``guidance.authority_factor`` times the
        weaker one-way roll acceleration (stuck or failed jets can leave one way much
        weaker); the scenario's limit stays the ceiling, so healthy jets change nothing.

        The estimate is a pure body-roll probe of the allocator, a lower bound of what
        turns the vehicle about its velocity (the yaw jets, the 5-degree margin of the
        bank-error budget and the aerodynamic moments help too), hence a factor above 1.
        Case 2 (seven jets stuck on: 8.9 N m one way, 0.19 deg/s^2) sets the window,
        measured 2026-11-22 over seeds 1-3: factor <= 2.5 -> reversals so slow the entry
        skips out (timeout at 700 s); 3 -> Mach 2 at 629 s, 1.07 deg; 3.5 -> 603 s,
        1.13 deg; 4 -> 602 s, 1.38-1.41 deg; 5 -> 5.45 deg; >= 6 -> no re-shape, 6.62 deg.
        """
        m = self.params["guidance.authority_factor"]
        if m <= 0.0:
            return
        pos, neg = self.roll_authority_Nm()
        a = self.scenario.vehicle.aero.alpha_trim_rad
        v = np.array([np.cos(a), 0.0, np.sin(a)])          # velocity direction in body axes at trim
        I_v = float(v @ self.control.inertia_hat() @ v)
        accel = m * min(pos, neg) * np.cos(a) / I_v
        limit = max(min(self.scenario.bank_accel_limit_radps2, accel), 1e-4)
        prof = self.guidance.profile
        if prof.replan(t_s, prof.rate_limit_radps, limit):
            self.events.emit(t_s, Severity.NOTICE, "guidance", "reference_reshaped",
                             f"REFERENCE ACCEL LIMIT {np.degrees(limit):.2f} DEG/S2")

    def no_frame(self, t_s: float) -> np.ndarray:
        """A control cycle in which no fresh sensor frame arrived (SIL): counts towards
        STALE and holds the jets off once stale."""
        self.cycles += 1
        self.t_s = t_s
        self.monitor.tick(t_s, got_frame=False)
        if self.monitor.stale:
            return self._hold_off(t_s)
        return self.driver.command(self._zero_u, False)

    def _hold_off(self, t_s: float) -> np.ndarray:
        """Jets off, nothing learnt: a rejected frame or stale sensors."""
        self._have_prev = False
        self.u_cal_B[:] = 0.0
        self.tau_alloc_B[:] = 0.0
        return self.driver.command(self._zero_u, False)

    # ---------------------------------------------------------------- RG2 / RG3
    def slow_step(self) -> None:
        """RG2: analytic-redundancy residual (needs two consecutive good cycles)."""
        nav = self.nav.state
        if self._have_prev and self._residual_ready:
            self.fdir.residual_check(self.t_s, nav.omega_BN_B, self._omega_prev, self._residual_dt,
                                     self._tau_cmd_prev, self.control.aero_torque_est(nav),
                                     self.control.inertia_hat())
        self._omega_prev[:] = nav.omega_BN_B
        self._tau_cmd_prev[:] = self.tau_alloc_B
        self._residual_dt = self.dt_s * self.params["executive.rg2_divisor"]
        self._residual_ready = True

    def housekeeping(self) -> None:
        """RG3: nothing periodic beyond telemetry yet (the ground link adds its heartbeat here)."""

    # ---------------------------------------------------------------- commands
    def close(self) -> None:
        """Stop background work (the allocator's table builder)."""
        self.allocator.close()

    def health_changed(self) -> None:
        """Hand the allocator the health FDIR now holds (after an override, clear or inhibit)."""
        self.allocator.set_health(self.fdir.health_active)

    def set_fault_tolerance(self, on: bool) -> None:
        self.allocator.set_fault_tolerance(on)
        self.health_changed()

    def set_param(self, name: str, value: float) -> float:
        """Validated ground parameter set; raises ValueError (value unchanged) when refused."""
        p = self.param_table.get(name)
        if p is None:
            raise ValueError(f"{name}: unknown parameter")
        if not p.ground_settable:
            raise ValueError(f"{name}: not settable in flight")
        v = p.check(value)
        section = name.split(".", 1)[0]
        if section == "control":
            self.control.set_param(name, v)
        elif section == "allocator":
            if name == "allocator.fault_tolerance":
                self.set_fault_tolerance(bool(v))
            else:
                self.allocator.set_params({**self.params, name: v})
                self.health_changed()
        elif section == "fdir":
            self.fdir.set_param(name, v)
        self.params[name] = v
        return v

    def allocator_health(self) -> JetHealth:
        """The health the allocator is solving with (nominal when fault tolerance is off)."""
        return self.fdir.health_active if self.allocator.fault_tolerance else JetHealth()

    @property
    def health(self) -> JetHealth:
        return self.fdir.health_active
