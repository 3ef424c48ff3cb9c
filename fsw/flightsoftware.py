"""The flight software assembled: the cycle pipeline the rate groups call.

RG1 (control, every tick): sensor frame -> monitors -> FDIR -> navigation -> authority
supervisor -> guidance -> SAMI -> allocator -> jet driver. RG2 (slow): analytic-redundancy
check. RG3: the guidance cycle and the authority's re-assessment. Beside it: the authority
supervisor (fsw/authority.py) and the command API (fsw/commands.py); ground commands
(``cmd_*``, ``set_param``) arrive between cycles.
This object is the same in the one-process batch runner and in the SIL FSW process; the
process shell only moves records in and out. No transport, threads or clocks here: work that
outlasts a control period runs as background jobs (fsw/jobs.py) owned by the functions that
need it.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from common.events import EventLog
from common.model import Scenario
from interfaces.event_catalogue import EV

from .allocation import Allocator
from .allocation.dutycycle import DutyCycleRealiser
from .authority import AuthoritySupervisor
from .commands import GroundCommands
from .control import SamiController
from .controllability import Controllability, velocity_dir_B
from .fdir import Fdir, jet_step
from .guidance.reference import BankProfile, Guidance
from .health import JetHealth
from .jetdriver import JetDriver, drive_jets, packed_views, ring_views
from .law import LAW_DONE, LAW_SAFE_DUE, LR_ALPHA_TRIM, LR_DT, LR_MU, LR_N, LR_OMEGA, LR_TRIM, LW_CHART, LW_FS, \
    LW_N, LW_TRIM_OFF, law_cycle
from .modes import Failsafes, Mode, ModeManager
from .monitors import SensorMonitor, frame_check
from .navigation import _S_T, Navigation, _nav_kernel
from .output import OutputFiller, fill_record
from .guidance.npc import PARAMS as NPC_PARAMS, EntryGuidance
from .guidance.trigger import PARAMS as DEPLOY_PARAMS, DeployTrigger
from .params import Param, ParamRegistry, periods
from . import executive

COMMAND_RING_S = 1.28   # answers kept for FDIR (64 at 50 Hz, 256 at 200 Hz): a command held longer is not judged
_ZERO3 = (0.0, 0.0, 0.0)   # a zero torque as Python floats
_NO_SEGS = np.zeros((0, 10))   # law_cycle's profile segments when the profile is not a schedule


@njit(cache=True)
def note_sent(sent, sent_k, k, u):
    """Note ``u`` as the answer to frame ``k`` in the ring (``sent`` rows, ``sent_k`` their frame
    indices). A second, different answer under the same index (jets held off on a rejected
    frame after the last good one was answered) leaves the plant holding either: the slot is
    marked ambiguous (-k-3, which matches no index) and the period it reports is no evidence."""
    i = k % sent_k.shape[0]
    k_slot = sent_k[i]
    if k_slot == k:
        for j in range(u.shape[0]):
            if sent[i, j] != u[j]:
                sent_k[i] = -k - 3
                break
    elif k_slot != -k - 3:
        for j in range(u.shape[0]):
            sent[i, j] = u[j]
        sent_k[i] = k


@njit(cache=True)
def bank_short(bank_axis_B, u_cal_B, tau_alloc_B, short_min_Nm, short_frac):
    """The bank axis fell short: the torque delivered about it falls short of a demand above
    ``short_min_Nm`` by more than ``short_frac`` of that demand."""
    a = bank_axis_B
    d = a[0] * u_cal_B[0] + a[1] * u_cal_B[1] + a[2] * u_cal_B[2]
    got = a[0] * tau_alloc_B[0] + a[1] * tau_alloc_B[1] + a[2] * tau_alloc_B[2]
    return abs(d) > short_min_Nm and (d - got) * (1.0 if d > 0.0 else -1.0) > short_frac * abs(d)


@njit(cache=True)
def finish_cycle(tau_B, u_alloc, gate, jb, jc, jr, torques, short_frac, r, target_flag, alloc_ns, mode, degraded,
                 deploy, npc, guid_cycles, bank_cmd, pred, k, t_s, phi_r, phidot_r, bank_err_rad, sigma_RN, theta_hat,
                 eta, health):
    """The control cycle's tail after the allocation, in one compiled call: the allocated
    torque ``tau_B`` copied to ``tau_alloc_B``, the bank-shortfall test (``bank_short``; the torques,
    the axis and its floor in ``torques``: FlightSoftware's layout), the
    jet driver (jetdriver.py ``drive_jets`` on its buffers ``jb``, ``jc``, ``jr``: ``JetDriver.packed``),
    the answer noted in the ring the driver keeps (``note_sent``) and the output record ``r``
    filled (output.py ``fill_record``: the arguments from ``r`` on). Returns (propellant used
    [kg], bank axis short); the events those call for are the Python caller's."""
    inhibit, last, pulses, on_time_s, mdot_kgps, dt_s, sent, sent_k = packed_views(jb, jc, jr)
    u_cal_B, tau_alloc_B = torques[0:3], torques[3:6]
    for i in range(3):
        tau_alloc_B[i] = tau_B[i]
    short = bank_short(torques[6:9], u_cal_B, tau_alloc_B, torques[9], short_frac)
    used = drive_jets(u_alloc, gate, inhibit, last, pulses, on_time_s, mdot_kgps, dt_s)
    note_sent(sent, sent_k, k, last)
    fill_record(r, target_flag, last, short, torques, alloc_ns, mode, degraded, deploy, npc, guid_cycles, bank_cmd,
                pred, k, t_s, phi_r, phidot_r, bank_err_rad, sigma_RN, theta_hat, eta, health)
    return used, short


# intake_cycle's three buffers (numba's dispatch costs per array argument; the owners keep
# views under their own names: FlightSoftware.__init__ binds them). ``ro``, what it only reads, bytes
# holding: int64 [persist, model, oracle, n jets] (FDIR's persistence, navigation's density
# model, FDIR in oracle mode, the size); float64 [the monitor's limits (6 x 2), FDIR's
# thresholds (4), the planet's rotation rate, radius, rho0, scale height]; uint8 [jets off
# (n), FDIR's isolated health state (n, int8)]. ``wf``, floats it writes: [the monitor's out
# (5), FDIR's sum_dg (n), eta_new (n)]. ``wi``, int64 it writes: [the monitor's sequence (3),
# FDIR's counters (3 x n), new_kind (n)]. The rehearsal has its own ``wf``, ``wi`` (scratch) and
# reads ``ro``. The ring of answers FDIR judges by is the jet driver's, which the tail writes
# (its buffers ``jb``, ``jc``: jetdriver.py ``ring_views``).
RI_PERSIST, RI_MODEL, RI_ORACLE, RI_N, RI_END = 0, 1, 2, 3, 4
RF_LIMS, RF_THR, RF_OMEGA, RF_RADIUS, RF_RHO0, RF_H, RF_N = 0, 12, 16, 17, 18, 19, 20
WF_OUT, WF_SUM_DG = 0, 5
WI_SEQ, WI_CNT = 0, 3


def head_buffers(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``ro``, ``wf``, ``wi`` for ``n`` jets (zeros; the size set)."""
    nb = 8 * (RI_END + RF_N) + 2 * n
    ro = np.zeros(-(-nb // 8) * 8, dtype=np.uint8)
    hi = ro[0:8 * RI_END].view(np.int64)
    hi[RI_N] = n
    return ro, np.zeros(WF_SUM_DG + 2 * n), np.zeros(WI_CNT + 4 * n, dtype=np.int64)


def head_views(ro, wf, wi):
    """(header ints, floats, lims, thr, zero_u, iso_state, out, sum_dg, eta_new, seq, cnt,
    new_kind): views of ``head_buffers``' arrays (compiled too: ``intake_cycle`` unpacks its
    arguments with it)."""
    hi = ro[0:8 * RI_END].view(np.int64)
    n = hi[RI_N]
    o_b = 8 * (RI_END + RF_N)
    fl = ro[8 * RI_END:o_b].view(np.float64)
    return (hi, fl, fl[RF_LIMS:RF_LIMS + 12].reshape((6, 2)), fl[RF_THR:RF_THR + 4],
            ro[o_b:o_b + n], ro[o_b + n:o_b + 2 * n].view(np.int8),
            wf[WF_OUT:WF_OUT + 5], wf[WF_SUM_DG:WF_SUM_DG + n], wf[WF_SUM_DG + n:WF_SUM_DG + 2 * n],
            wi[WI_SEQ:WI_SEQ + 3], wi[WI_CNT:WI_CNT + 3 * n].reshape((3, n)), wi[WI_CNT + 3 * n:WI_CNT + 4 * n])


_head_views = njit(cache=True)(head_views)


@njit(cache=True)
def intake_cycle(x, ki, stale, next_apply, ro, wf, wi, nav_buf, jb, jc):
    """The control cycle's head in one compiled call, on a SENSORS record's floats ``x`` and
    its (k, t_ns, u_k) ``ki``: the frame check (monitors.py ``frame_check``: the limits, out,
    sequence, ``stale``), FDIR's jet monitor on the command in force (fdir.py ``jet_step``:
    the driver's ring in ``jb``, ``jc``, FDIR's state and counters, ``next_apply``) and navigation
    (navigation.py ``_nav_kernel``: the planet's constants, the NavState buffer ``nav_buf``, its
    time slot too); the rest in ``ro``, ``wf``, ``wi`` (``head_views``). Returns (code, t_s, k, V_rel, h,
    alpha, beta, bank, rho, qbar, mach): code < 0 a rejected frame (``frame_check``'s code;
    nothing past the check ran, the navigation figures are zeros), else frame_check's flags
    plus 4 times jet_step's (0: nothing for the Python caller to report or apply)."""
    hi, fl, lims, thr, zero_u, iso_state, out, sum_dg, eta_new, seq, cnt, new_kind = _head_views(ro, wf, wi)
    sent, sent_k = ring_views(jb, jc)
    k = ki[0]
    t_s = float(ki[1]) * 1e-9
    code = frame_check(x, k, lims, out, seq, stale)
    if code < 0:
        return code, t_s, k, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    step = jet_step(ki[2], sent, sent_k, zero_u, x[15:], hi[RI_ORACLE] != 0, t_s, next_apply, iso_state, cnt,
                    sum_dg, thr, hi[RI_PERSIST:RI_PERSIST + 1], new_kind, eta_new)
    nav_buf[_S_T] = t_s
    V, h, alpha, beta, bank, rho, qbar, mach = _nav_kernel(x, fl[RF_OMEGA], fl[RF_RADIUS], hi[RI_MODEL],
                                                           fl[RF_RHO0], fl[RF_H], nav_buf)
    return code + 4 * step, t_s, k, V, h, alpha, beta, bank, rho, qbar, mach


def _adopt(owner, name: str, view: np.ndarray) -> None:
    """``owner.name`` becomes ``view`` (a view of a packed buffer), holding its value."""
    view[...] = getattr(owner, name)
    setattr(owner, name, view)

def declarations() -> tuple[tuple[str, list[Param]], ...]:
    """Every FSW parameter, by the owner that declares it and applies a new value."""
    return (("AuthoritySupervisor", AuthoritySupervisor.PARAMS), ("SamiController", SamiController.PARAMS),
            ("EntryGuidance", NPC_PARAMS), ("DeployTrigger", DEPLOY_PARAMS), ("Allocator", Allocator.PARAMS), ("Fdir", Fdir.PARAMS),
            ("SensorMonitor", SensorMonitor.PARAMS),
            ("Failsafes", Failsafes.PARAMS), ("JetDriver", JetDriver.PARAMS), ("Executive", executive.PARAMS))


def all_params() -> list[Param]:
    return [p for _, plist in declarations() for p in plist]


class FlightSoftware(GroundCommands):
    """All FSW functions wired together. ``scenario`` supplies only what the FSW may know:
    the nominal vehicle and planet models, the guidance schedule, and parameter overrides.
    The ground's command API (``cmd_*``, ``set_param``) is GroundCommands'."""

    def __init__(self, scenario: Scenario, events: EventLog | None = None, start_mode: Mode = Mode.ENTRY,
                 armed: bool = True, param_overrides: dict | None = None, realtime: bool = False):
        """``realtime``: the allocator's table builds and the controllability LP run in the
        background after a health change (the loop never waits for them); lockstep and batch
        solve them in place, so they are deterministic."""
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
        # guidance mode (docs/fsw/entry-guidance.md): the scenario's bank schedule, or the
        # predictor-corrector's command through its shaper; the attitude chain is the same
        self.entry = None
        if scenario.guidance_mode == "npc":
            self.entry = EntryGuidance(scenario, self.params, self.events, self.dt_s, realtime=realtime)
            profile = self.entry.shaper
        else:
            profile = BankProfile(scenario.bank_schedule, scenario.bank_rate_limit_radps,
                                  scenario.bank_accel_limit_radps2)
        self.guidance = Guidance(profile, veh.aero.alpha_trim_rad, planet.omega_radps)
        # the parachute deploy trigger, when this FSW deploys (scenario.deploy_by "fsw")
        self.deploy = DeployTrigger(scenario, self.params, self.events) if scenario.deploy_by == "fsw" else None
        self.control = SamiController(self.params, veh, self.dt_s)
        self.allocator = Allocator(veh.torque_matrix_Nm, veh.thrust_N, self.params, async_rebuild=realtime)
        self.fdir = Fdir(self.params, self.dt_s, self.events)
        # the driver keeps the ring of answers (below) in its buffers, beside what it sent last
        self._ring = periods(COMMAND_RING_S, self.dt_s)
        self.driver = JetDriver(veh.thrust_N, veh.isp_s, planet.g0_mps2, self.dt_s, self.events, ring=self._ring)
        self.modes = ModeManager(self.events)
        self.monitor = SensorMonitor(self.events, self.dt_s, self.params, planet.radius_m)
        self.failsafes = Failsafes(self.params, self.modes)
        self.authority = AuthoritySupervisor(scenario, self.params, self.events, self.nav, self.control,
                                             self.guidance, self.allocator_health, lambda: self.t_s, realtime)

        self.driver.set_param("driver.arm_on_entry", self.params["driver.arm_on_entry"])
        reg = self.registry            # each owner applies its own parameters
        reg.bind("AuthoritySupervisor", self.authority.set_param)
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
        # the torques and the bank-shortfall test's constants in one buffer the tail's compiled
        # call takes whole (``finish_cycle``: [0:3] u_cal_B, [3:6] tau_alloc_B, [6:9] the bank
        # axis, [9] its shortfall floor); the names are views into it
        self.torques = np.zeros(10)
        self.u_cal_B = self.torques[0:3]
        self.tau_alloc_B = self.torques[3:6]
        # the bank axis (velocity direction at trim, body axes) and its jet quantum: a cycle is
        # short when the torque delivered about it falls short of the demand by more than
        # control.shortfall_frac of a demand worth two or more of the largest jet increments
        # (the rule SAMI's saturation awareness applies per body axis)
        self.torques[6:9] = velocity_dir_B(veh.aero.alpha_trim_rad)
        self.bank_axis_B = self.torques[6:9]
        self._bank_short_min_Nm = 2.0 * float(np.max(np.abs(self.bank_axis_B @ np.asarray(veh.torque_matrix_Nm))))
        self.torques[9] = self._bank_short_min_Nm
        # while the bank axis falls short, the duty-cycle LP's average realised over cycles
        # (fsw/allocation/dutycycle.py) instead of one pattern per cycle
        self.dutycycle = DutyCycleRealiser(self.bank_axis_B, veh.torque_matrix_Nm, veh.thrust_N)
        self.dutycycle.short_min_Nm = self._bank_short_min_Nm
        self.alloc_short = False
        self.alloc_short_cycles = 0
        self._omega_prev = np.zeros(3)
        # the RG2 residual compares the rate change over its interval with the torque the jets
        # gave over it: the mean of the interval's RG1 commands (the allocator's torque changes
        # from cycle to cycle; one cycle's sample misstates it). Each cycle adds the torque of
        # the cycle before it (the one that acted up to this frame); jets held off add zero.
        # (Python floats: the same additions as on arrays, a fraction of their per-call cost)
        self._tau_last = _ZERO3
        self._tau_sum = _ZERO3
        self._tau_n = 0
        self._tau_mean = np.zeros(3)
        self._have_prev = False
        self.alloc_ns = 0
        self.reconfig_times: list[float] = []
        self.cycles = 0
        self.bank_err_rad = 0.0
        self._zero_u = np.zeros(self.driver.n, dtype=np.uint8)   # jets off
        # the commands this FSW answered frames with, by frame index: FDIR judges each jet by
        # the command the plant reports it held (SENSORS.u_k), which in real time can be an
        # older one than the last sent (a late answer: the plant held the one before)
        self._sent = self.driver.sent                 # (ring, jets) uint8: the answers
        self._sent_k = self.driver.sent_k             # the frame index of each slot's answer
        self._drive_state = self.driver.packed()      # finish_cycle's buffers (the ring's too)
        # intake_cycle's buffers (``head_buffers``): the owners' arrays become views of them, under
        # their own names; the rehearsal's scratch (FDIR's, the monitor's) views of the second pair
        mon, fd, nav = self.monitor, self.fdir, self.nav
        ro, wf, wi = head_buffers(self.driver.n)
        _, wf_r, wi_r = head_buffers(self.driver.n)
        hi, fl, lims, thr, zero_u, iso, out, sum_dg, eta_new, seq, cnt, new_kind = head_views(ro, wf, wi)
        om, radius, model, rho0, scale_h = nav._consts
        fl[RF_OMEGA:RF_H + 1] = (om, radius, rho0, scale_h)
        hi[RI_MODEL] = model
        hi[RI_ORACLE] = fd.oracle
        for owner, name, view in ((fd, "_persist", hi[RI_PERSIST:RI_PERSIST + 1]),
                                  (self, "_zero_u", zero_u), (fd.health_isolated, "state", iso),
                                  (mon, "_lims", lims), (fd, "_thr", thr), (mon, "_out", out), (fd, "_sum_dg", sum_dg),
                                  (fd, "_eta_new", eta_new), (mon, "_seq", seq), (fd, "_cnt", cnt),
                                  (fd, "_new_kind", new_kind)):
            _adopt(owner, name, view)
        v_r = head_views(ro, wf_r, wi_r)
        for owner, name, view in ((fd, "_r_sum_dg", v_r[7]), (fd, "_r_eta", v_r[8]), (mon, "_r_seq", v_r[9]),
                                  (fd, "_r_cnt", v_r[10]), (fd, "_r_kind", v_r[11])):
            _adopt(owner, name, view)
        jb, jc, _ = self._drive_state                  # the ring: read only in the head
        self._intake_args = (ro, wf, wi, nav.state.buf, jb, jc)
        self._intake_scratch = (ro, wf_r, wi_r, nav._r_buf, jb, jc)
        self._zero3 = np.zeros(3)
        self._residual_ready = False                   # RG2 has one earlier sample to difference
        self.realtime = realtime
        # the outputs of each control cycle, one FSW_STATE record (interfaces/records.py) that
        # every reader takes: refilled in place at the end of control_step and no_frame
        self._output = OutputFiller(scenario)
        self.output = self._output.rec
        # scratch copies of what finish_cycle writes (the driver's buffers, the record, the
        # torques' buffer), for the tail's rehearsal
        # (the torques' copy is the law's rehearsal's too: each rehearsal refills it first)
        self._torques_scratch = self.torques.copy()
        self._tail_scratch = (*(a.copy() for a in self._drive_state), self._output.one.copy(),
                              self._torques_scratch)
        # law_cycle's two buffers (law.py LR_*, LW_*): the owners' arrays become views of them;
        # it reads tau_alloc_B from and writes u_cal_B into the torques' buffer. The rehearsal
        # writes a scratch copy of ``lw``, of the reference's outputs, of SAMI's state and of the
        # torques
        g, ctl = self.guidance, self.control
        lr, lw = np.zeros(LR_N), np.zeros(LW_N)
        lr[LR_ALPHA_TRIM] = g.alpha_trim_rad
        lr[LR_OMEGA] = g.omega_planet_radps
        lr[LR_MU] = g.mu_m3ps2
        lr[LR_DT] = self.dt_s
        for owner, name, view in ((self.authority, "trim", lr[LR_TRIM:LR_TRIM + 5]),
                                  (self.failsafes, "state", lw[LW_FS:LW_FS + 4]), (ctl, "chart", lw[LW_CHART:LW_CHART + 1]),
                                  (g, "trim_offset", lw[LW_TRIM_OFF:LW_TRIM_OFF + 2])):
            _adopt(owner, name, view)
        self._law_w = lw
        self._law_args = (lr, g._out, ctl._kb, ctl._sb, lw, self.torques)
        self._law_scratch = (np.zeros(18), np.zeros(LW_N), self._torques_scratch)
        self._law_rehearse_args = (lr, self._law_scratch[0], ctl._kb, ctl._rb, self._law_scratch[1],
                                   self._law_scratch[2])

    # ---------------------------------------------------------------- RG1
    def control_step(self, frame) -> np.ndarray:
        """One control cycle on a SENSORS record; returns the jet command (uint8, one per jet).
        Its outputs are in ``output`` afterwards."""
        return self._run_cycle(frame)

    def _run_cycle(self, frame) -> np.ndarray:
        self.cycles += 1
        self._count_torque()
        v = self.monitor.views(frame)
        if v is None:
            return self._rejected_format(frame)
        code, t_s, k, V, h, alpha, beta, bank, rho, qbar, mach = intake_cycle(
            v[0], v[1], self.monitor.stale, self.fdir._next_apply, *self._intake_args)
        if code < 0:
            self.monitor.settle(t_s, code, k)
            return self._held_off(t_s)
        self.k = k
        self.t_s = t_s
        reconfigured = code != 0 and self._intake_reports(t_s, code, k)
        nav = self.nav.state
        nav.t_s = t_s
        nav.V_rel_mps = V
        nav.h_m = h
        nav.alpha_rad = alpha
        nav.beta_rad = beta
        nav.bank_rad = bank
        nav.rho_kgpm3 = rho
        nav.qbar_pa = qbar
        nav.mach = mach
        if reconfigured or self.authority.due(t_s):
            self.authority.step(t_s, reconfigured)      # assessed with this cycle's navigation
        if self.entry is not None:
            self.entry.steer(nav)
            self.entry.shaper.observe(nav.bank_rad)
        if self.deploy is not None:
            self.deploy.update(nav, t_s, self.entry.estimator.k_rho if self.entry is not None else 1.0)
        # the held trim, the reference, the bank error, the tracking failsafe and SAMI in one
        # compiled call (law.py ``law_cycle``); a failsafe due or another mode than ENTRY
        # comes back here. No learning while FDIR holds a detection not yet reconfigured: the
        # torque commanded through the faulty jets is not what the tracking error saw.
        g = self.guidance
        entry = self.modes.mode is Mode.ENTRY
        pending = self.fdir.reconfig_pending
        if g.compiled_profile:
            prof = g.profile
            law, g.phi_r, g.phidot_r, g.phiddot_r, self.bank_err_rad = law_cycle(
                nav.buf, entry, self._have_prev, pending, True, prof.seg_array, prof.phi0_rad, 0.0, 0.0, 0.0,
                *self._law_args)
        else:
            law, g.phi_r, g.phidot_r, g.phiddot_r, self.bank_err_rad = law_cycle(
                nav.buf, entry, self._have_prev, pending, False, _NO_SEGS, 0.0, *g.profile.evaluate(nav.t_s),
                *self._law_args)
        if law == LAW_DONE:
            self.control.freeze = pending
        else:
            if law == LAW_SAFE_DUE:
                self.failsafes.enter_safe(t_s)
            mode = self.modes.mode
            if mode == Mode.ENTRY:
                self.control.freeze = not self.modes.adaptation_enabled or pending
                u_cal = self.control.update(nav, g, self.tau_alloc_B if self._have_prev else None)
            elif mode == Mode.SAFE:
                self.control.freeze = True
                u_cal = self.control.safe_torque(nav)
            else:
                u_cal = self._zero3
            self.u_cal_B[:] = u_cal
        self.dutycycle.short_frac = self.params["control.shortfall_frac"]
        dc = self.dutycycle
        u_alloc = dc.solve(self.allocator, self.u_cal_B)
        self.alloc_ns = dc.solve_ns
        if dc.rare:                  # the compiled path's ordinary answers call for no event
            if self.allocator.tables_version != self._tables_version:      # new tables in use
                self._tables_version = self.allocator.tables_version
                dc.reset()
                self.events.emit(t_s, EV.RECONFIGURED, rebuild_ms=self.allocator.rebuild_time_s * 1e3)
            if self.allocator.degraded:
                self.events.emit(t_s, EV.ALLOC_DEGRADED)
            if dc.fell_back:
                self.events.emit(t_s, EV.ALLOC_LP_FALLBACK)
        return self._finish(t_s, u_alloc)

    def _rejected_format(self, frame) -> np.ndarray:
        """Not a usable SENSORS record (the monitor's views refused it): rejected as a format error."""
        t_s = float(frame["t_ns"]) * 1e-9
        self.monitor.check(t_s, frame)
        return self._held_off(t_s)

    def _intake_reports(self, t_s: float, code: int, k: int) -> bool:
        """What ``intake_cycle``'s flags ``code`` (> 0) call for: the monitor's and FDIR's
        reports and declarations, and the allocator told of a reconfiguration. True when FDIR
        reconfigured."""
        self.monitor.settle(t_s, code & 3, k)
        reconfigured = self.fdir.settle(t_s, code >> 2)
        if reconfigured:
            self.allocator.set_health(self.fdir.health_active)
            self.reconfig_times.append(t_s)
        return reconfigured

    def _finish(self, t_s: float, u_alloc: np.ndarray) -> np.ndarray:
        """The rest of the cycle in one compiled call (``finish_cycle``), the events it calls
        for here; returns the command sent."""
        driver, out = self.driver, self._output
        used, short = finish_cycle(self.dutycycle.tau_B, u_alloc, driver.armed and self.modes.jets_enabled,
                                   *self._drive_state, self.torques, self.params["control.shortfall_frac"],
                                   out.one, out.target_flag, *out.fill_args(self))
        driver.count(used)
        self._check_bank_shortfall(t_s, short)
        self._tau_last = tuple(self.tau_alloc_B.tolist())       # this cycle's torque, as floats
        self._have_prev = True
        return driver.last_command

    def _held_off(self, t_s: float) -> np.ndarray:
        """The cycle's answer when the jets are held off (a rejected frame, stale sensors, a
        failsafe), noted and its outputs filled."""
        u = self._sent_for(self._hold_off(t_s))
        self._output.fill(self, u)
        return u

    def rehearse(self, frame, demand_B: np.ndarray) -> None:
        """Real time, shortly before a release (fsw/topology.py): the compiled kernels the
        rehearsal's spare warms as code run once more on this instance's own data, their
        answers discarded -- the cycle's head (``intake_cycle``: frame check, jet monitor,
        navigation) on ``frame`` (the record of the last frame this instance took), the law's
        stretch (``law_cycle``) on copies of its state with the last cycle's navigation and
        reference, the allocation's compiled call on its own tables for ``demand_B`` (the
        spare's demand on that frame), and the tail (``finish_cycle``) on copies of what it
        writes with the last cycle's answer and outputs. Nothing the next cycle reads changes."""
        fv = self._frame_views
        if fv[0] is frame:
            self._rehearse_intake(fv)
            if self._have_prev:
                self._rehearse_law()
        self.dutycycle.rehearse(self.allocator, demand_B)    # the allocation's compiled call
        if self._have_prev:
            self._rehearse_tail()

    def _rehearse_tail(self) -> None:
        """``finish_cycle`` as the last cycle called it (its answer, the same read-only arrays and
        outputs), writing into scratch copies of the driver's buffers, the record and the
        torques' buffer; its answers discarded."""
        jb, jc, jr, rec, torques = self._tail_scratch
        live = self._drive_state
        np.copyto(jb, live[0])
        np.copyto(jc, live[1])
        np.copyto(jr, live[2])
        np.copyto(torques, self.torques)
        out, dc = self._output, self.dutycycle
        np.copyto(rec, out.one)
        finish_cycle(dc.tau_B, dc.u if dc.modulated else self.allocator.u,
                     self.driver.armed and self.modes.jets_enabled, jb, jc, jr, torques,
                     self.params["control.shortfall_frac"], rec, out.target_flag, *out.fill_args(self))

    @property
    def _frame_views(self) -> tuple:
        """(record, its dtype, float view, view of k, t_ns, u_k) of the last record the monitor viewed."""
        return self.monitor._fviews

    def _rehearse_intake(self, fv: tuple) -> None:
        """``intake_cycle`` on the rehearsal's copies of the record's floats ``fv[2]``, the
        monitor's sequence (as if the frame were new), FDIR's counters and the navigation
        state; its answers discarded."""
        x, seq = self.monitor.rehearsal_copy(fv[2])
        self.fdir.rehearsal_copy()
        self.nav.rehearsal_copy()
        intake_cycle(x, fv[3], False, self.fdir._next_apply, *self._intake_scratch)

    def _sent_for(self, u: np.ndarray) -> np.ndarray:
        """Note ``u`` as this frame's answer (frame index self.k; ``note_sent``); returns u."""
        note_sent(self._sent, self._sent_k, self.k, u)
        return u

    def _check_bank_shortfall(self, t_s: float, short: bool) -> None:
        """Note whether the bank axis fell short this cycle (``bank_short``)."""
        self.alloc_short = short
        if short:
            self.alloc_short_cycles += 1
            self.events.emit(t_s, EV.ALLOC_SHORT)

    def no_frame(self, t_s: float) -> np.ndarray:
        """A control cycle in which no fresh sensor frame arrived (SIL): counts towards
        STALE and holds the jets off once stale. Its outputs are in ``output`` afterwards."""
        u = self._run_no_frame(t_s)
        self._output.fill(self, u)
        return u

    def _run_no_frame(self, t_s: float) -> np.ndarray:
        self.cycles += 1
        self._count_torque()
        self._tau_last = _ZERO3
        self.t_s = t_s
        self.monitor.tick(t_s, got_frame=False)
        # no frame, so no answer is sent and none is noted (stale or not): the plant still
        # holds the answer to frame k, which FDIR judges the next frame by
        if self.monitor.stale:
            return self._hold_off(t_s)
        return self.driver.command(self._zero_u, False)

    def _count_torque(self) -> None:
        s, last = self._tau_sum, self._tau_last
        self._tau_sum = (s[0] + last[0], s[1] + last[1], s[2] + last[2])
        self._tau_n += 1

    def _hold_off(self, t_s: float) -> np.ndarray:
        """Jets off, nothing learnt: a rejected frame or stale sensors."""
        self._have_prev = False
        self.u_cal_B[:] = 0.0
        self.dutycycle.reset()
        self.tau_alloc_B[:] = 0.0
        self._tau_last = _ZERO3
        self.alloc_short = False
        return self.driver.command(self._zero_u, False)

    def _rehearse_law(self) -> None:
        """``law_cycle`` on scratch copies of the state it writes (failsafes, SAMI, chart), with
        the last cycle's navigation and reference inputs; nothing the next cycle reads changes."""
        g, ctl = self.guidance, self.control
        np.copyto(self._law_scratch[1], self._law_w)
        np.copyto(self._law_scratch[2], self.torques)
        np.copyto(ctl._rb, ctl._sb)
        compiled = g.compiled_profile
        law_cycle(self.nav.state.buf, self.modes.mode is Mode.ENTRY, self._have_prev, ctl.freeze, compiled,
                  g.profile.seg_array if compiled else _NO_SEGS, g.profile.phi0_rad if compiled else 0.0,
                  g.phi_r, g.phidot_r, g.phiddot_r, *self._law_rehearse_args)

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
        self._tau_sum = _ZERO3
        self._tau_n = 0
        self._residual_ready = True

    def entry_guidance_step(self) -> None:
        """Slow rate group (mode "npc"): one predictor-corrector cycle on the latest navigation."""
        if self.entry is not None and self.cycles > 0:
            self.entry.cycle(self.nav.state, self.t_s)

    def reassess_step(self) -> None:
        """RG3: the authority asked again while a stuck-on bias needs it (AuthoritySupervisor.reassess)."""
        if self.cycles > 0:
            self.authority.reassess(self.t_s)

    # ---------------------------------------------------------------- the authority
    @property
    def controllability(self) -> Controllability | None:
        """The controllability LP's answer at the last reconfiguration (None before any)."""
        return self.authority.controllability

    def assess_controllability(self, t_s: float) -> None:
        """Ask the controllability LP about the health the allocator uses now (AuthoritySupervisor.assess)."""
        self.authority.assess(t_s)

    def health_changed(self) -> None:
        """Hand the allocator the health FDIR now holds (after an override, clear or inhibit)
        and ask the LP what the jets can do with it."""
        self.allocator.set_health(self.fdir.health_active)
        self.authority.assess(self.t_s)
    def close(self) -> None:
        """Stop background work (the allocator's table builder, the controllability LP, the
        guidance correction)."""
        self.allocator.close()
        self.authority.close()
        if self.entry is not None:
            self.entry.close()

    def warm_background(self, timeout_s: float = 10.0) -> bool:
        """Before the first real-time cycle: the allocator's single-fault pre-builds finished and
        the controllability LP solved once on each thread it runs on (answers discarded), so
        the first fault's reconfiguration finds nothing cold. True if both were ready in time."""
        lp_warm = self.authority.warm(timeout_s)
        return self.allocator.wait_idle(timeout_s) and lp_warm

    # ---------------------------------------------------------------- owners' hooks
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

