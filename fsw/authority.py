"""The authority supervisor: what the jets can still do after a reconfiguration, and what the
reference may ask of them.

After every change of the health the allocator uses, the controllability LP
(fsw/controllability.py) is asked with the FSW's own models what bank acceleration the jets
give each way and what aerodynamic trim would absorb a stuck-on bias they cannot cancel. Its
answer is reported, the reference bank profile is re-planned to the weaker way's authority,
and the trim offset is carried with the dynamic pressure. The LP takes tens of ms, longer than
a control period: in real time it runs off the loop (fsw/jobs.py) and its answer is applied
by the first cycle after it is ready; batch and lockstep solve it in place.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from common.events import EventLog
from common.model import Scenario
from interfaces.event_catalogue import EV

from .controllability import (Controllability, aero_moment_per_rad, controllability, guided_accel_need_radps2,
                              schedule_accel_need_radps2, velocity_dir_B)
from .health import JetHealth
from .jobs import IN_PLACE, REALTIME, BackgroundJob
from .params import Param

if TYPE_CHECKING:
    from .control import SamiController
    from .guidance.reference import Guidance
    from .navigation import Navigation


# the held trim as the compiled cycle reads it (``held_trim``): [dalpha, beta [rad], qbar [Pa] of
# the LP's trim, 1.0 when one is held, guidance.trim_max_deg in rad]
_T_HELD, _T_MAX = 3, 4


@njit(cache=True)
def held_trim(trim, qbar_pa, off):
    """``AuthoritySupervisor.hold_trim``'s rule, compiled: the offset ``off`` (alpha, beta [rad])
    the reference flies for the held trim ``trim`` (layout above) at dynamic pressure ``qbar_pa``."""
    if trim[_T_HELD] == 0.0:
        off[0] = 0.0
        off[1] = 0.0
        return
    k = trim[2] / qbar_pa if qbar_pa > 0.0 and math.isfinite(qbar_pa) else math.inf
    a0, a1 = abs(trim[0]), abs(trim[1])
    x = trim[_T_MAX] / (a1 if a1 > a0 else a0)       # the order of Python's max and min
    if x < k:
        k = x
    off[0] = trim[0] * k
    off[1] = trim[1] * k


class AuthoritySupervisor:
    """The controllability LP's answers turned into events, the reference's acceleration limit
    and its trim offset. ``health()``: the health the allocator solves with; ``now_s()``: the
    FSW's mission time (for a parameter set between cycles). ``lp.fn`` is the LP (tests wrap
    it to inject delays)."""

    PARAMS = [
        Param("guidance.authority_use", 0.05, 1.0, "",
              "after a reconfiguration the reference's bank acceleration is capped at this fraction of the weaker "
              "way of the controllability LP's bank authority (the rest is kept for the feedback)"),
        Param("guidance.trim_max_deg", 0.0, 30.0, "deg",
              "largest alpha/beta trim offset accepted to absorb a stuck-on bias the jets cannot cancel, or to give "
              "the weaker bank way authority while they can"),
        Param("guidance.npc_inertia_unc", 0.0, 0.9, "",
              "guidance mode npc: after a reconfiguration the reference brakes at its acceleration limit / (1 + this) "
              "(what the torque of that limit gives a bank-axis inertia this fraction above the nominal)",
              ground_settable=False),
    ]

    def __init__(self, scenario: Scenario, params: dict, events: EventLog, nav: Navigation,
                 control: SamiController, guidance: Guidance, health: Callable[[], JetHealth],
                 now_s: Callable[[], float], realtime: bool = False) -> None:
        self.scenario, self.params, self.events = scenario, params, events
        self.nav, self.control, self.guidance = nav, control, guidance
        self.health, self.now_s = health, now_s
        self.controllability: Controllability | None = None   # the LP's answer at the last reconfiguration
        self._trim_ref = None          # (dalpha, beta [rad], qbar [Pa]) of the LP's trim, None: none
        self.trim = np.zeros(5)        # the same for the compiled cycle (``held_trim``)
        self.trim[_T_MAX] = math.radians(params["guidance.trim_max_deg"])
        self.lp = BackgroundJob(controllability, "controllability", mode=REALTIME if realtime else IN_PLACE,
                                events=events, overrun_event=EV.CONTROLLABILITY_OVERRUN,
                                fault_event=EV.CONTROLLABILITY_FAULT)

    # ---------------------------------------------------------------- the cycle
    def step(self, t_s: float, health_changed: bool) -> None:
        """After navigation, in a cycle where FDIR changed the health or an answer is due
        (``due``): assess the new health; apply an answer that has become ready."""
        if health_changed:
            self.assess(t_s)
        self._take(t_s)

    def due(self, t_s: float) -> bool:
        """An answer of the LP may be taken at ``t_s`` (else ``step`` does nothing without a
        health change)."""
        return t_s >= self.lp.due_t

    def hold_trim(self, qbar_pa: float) -> None:
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

    # ---------------------------------------------------------------- the LP
    def lp_problem(self, t_s: float, held_trim_rad=None) -> tuple:
        """(schedule's need, arguments of controllability()) for the health the allocator uses (the
        verdict asked against the schedule's need and, for a guided entry, what it needs; while
        the jets alone cancel a stuck-on bias, a trim only as far as the weaker way the reference
        can use); the authority promised for every inertia within the vehicle's stated uncertainty about
        its nominal inertia (the box known to hold the truth). SAMI's inertia estimate is not
        used as that knowledge: with the dead zone it stays at nominal or drifts along what the
        tracking excites."""
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
        # the verdict also asks what a guided entry needs; the reference's floor stays the schedule's
        verdict_need = max(need, guided_accel_need_radps2(self.scenario.guidance_mode))
        # the weaker way the reference can use: beyond it the scenario's limit caps the reference
        # (``_reference_limit``); a trim that would buy more is not flown
        usable = self.scenario.bank_accel_limit_radps2 / self.params["guidance.authority_use"]
        args = (veh.torque_matrix_Nm, self.health().copy(), veh.inertia_kgm2, v_B, A,
                self.params["guidance.trim_max_deg"], verdict_need, float(nav.qbar_pa), veh.inertia_uncertainty_frac,
                held_trim_rad, usable)
        return need, args

    def assess(self, t_s: float, periodic: bool = False, held_trim_rad=None) -> None:
        """The duty-cycle LP on the health the allocator now uses, with the FSW's own models:
        inertia estimate, velocity direction from navigation, the aero moment of its density
        model, nominal derivatives and current factors d_hat. Real time: asked off the loop,
        applied by the first cycle after it is ready (a newer request makes an older one
        stale); batch and lockstep: applied here. ``periodic``: a re-assessment of the same
        health (``reassess``); ``held_trim_rad``: the authority with the trim offset the
        reference flies now (no new trim sought)."""
        need, args = self.lp_problem(t_s, held_trim_rad)
        self.lp.submit(*args, tag=(need, periodic, held_trim_rad is not None), t_s=t_s)
        if self.lp.mode == IN_PLACE:
            self._take(t_s)

    def reassess(self, t_s: float) -> None:
        """RG3 (1 Hz): the LP asked again while a stuck-on bias the jets cannot cancel has no
        trim yet (the aerodynamic moment grows with the dynamic pressure: a stuck-on jet found
        early, at qbar near 0, gets its trim once the air can give it). Once a trim exists it is
        carried by its qbar scaling (``hold_trim``) and the LP is not asked again: a fresh
        solve may return another of its equally good trims, and the reference's alpha/beta
        would jump between them.

        While a trim is held, the authority is asked again from that trim as flown now: the
        jets' share of the bias grows as the dynamic pressure falls (the offset is held within
        guidance.trim_max_deg) and the aerodynamic factors are learned, so neither the trim nor
        the authority found at the reconfiguration's dynamic pressure holds for a reversal flown
        at the entry's lowest. The LP moves the trim to the weak-way-best one closest to it
        (fsw/controllability.py), never to another equally good one."""
        r = self.controllability
        if r is None or r.bias_Nm == 0.0 or self.lp.busy or self.lp.ready:
            return
        if self._trim_ref is not None:
            g = self.guidance
            self.assess(t_s, periodic=True, held_trim_rad=(g.trim_offset_alpha_rad, g.trim_offset_beta_rad))
        elif not math.isfinite(r.trim_needed_deg):
            self.assess(t_s, periodic=True)

    def _take(self, t_s: float) -> None:
        ans = self.lp.take(t_s)
        if ans is not None:
            need, periodic, held = ans.tag
            self._apply_controllability(t_s, need, ans.value, periodic, held)     # re-planned from now

    def _apply_controllability(self, t_s: float, need: float, r: Controllability, periodic: bool = False,
                               held: bool = False) -> None:
        """Event and telemetry of the LP's answer; the guidance re-planned to the weaker way's
        authority times ``guidance.authority_use`` (the scenario's limit stays the ceiling), never
        below what the schedule still needs (the reference then keeps the schedule's pace: the
        tracking, not the reference, shows what the jets cannot do). A periodic re-assessment
        whose answer reads the same as the last (the event's precision: 0.01 deg/s^2, 1 N m,
        0.1 deg) and keeps its verdict changes nothing but the trim's dynamic pressure.
        ``held``: the answer with the held trim (``reassess``): the trim moves to the LP's (the
        weak-way-best trim closest to the one flown), and the reference is only ever slowed by
        it (the authority it needs is no longer there), never sped up again before the next reconfiguration (no re-shaping back and forth as the
        dynamic pressure falls and rises)."""
        last, self.controllability = self.controllability, r
        if held:
            self._set_trim_ref(r)          # the weak-way-best trim closest to the one flown
            if last is not None and r.controllable != last.controllable and not r.controllable:
                self.events.emit(t_s, EV.NOT_CONTROLLABLE, reason=r.reason)
            if self._reference_limit(need, r)[0] < self.guidance.profile.accel_limit_radps2:
                self._replan_to(t_s, need, r)      # says so when the limit's text changes
            return
        if periodic and last is not None and r.text() == last.text() and r.controllable == last.controllable:
            self._set_trim_ref(r)
            return
        self.events.emit(t_s, EV.CONTROLLABILITY, **r.event_args())
        self._set_trim_ref(r)
        if periodic and last is not None and r.controllable == last.controllable:
            self._replan_to(t_s, need, r)
            return
        if not r.controllable:
            self.events.emit(t_s, EV.NOT_CONTROLLABLE, reason=r.reason)
        self._replan_to(t_s, need, r)

    def _set_trim_ref(self, r: Controllability) -> None:
        trim = (math.radians(r.trim_alpha_deg), math.radians(r.trim_beta_deg))
        self._trim_ref = ((trim[0], trim[1], r.qbar_pa) if all(map(math.isfinite, (*trim, r.qbar_pa)))
                          and max(map(abs, trim)) > 0.0 and r.qbar_pa > 0.0 else None)
        tr = self._trim_ref
        self.trim[0:4] = (0.0, 0.0, 0.0, 0.0) if tr is None else (tr[0], tr[1], tr[2], 1.0)

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
            self.events.emit(t_s, EV.AUTHORITY_LOW, auth=float(np.degrees(weak)))
        if limit <= 0.0:
            return
        prof = self.guidance.profile
        # the same limit at the precision the event states (0.01 deg/s^2) is no new reference:
        # answers of equal LPs differ in their last bits, and each re-plan would say so again
        if _limit_text(limit) == _limit_text(prof.accel_limit_radps2):
            brake = self._brake_limit(prof.accel_limit_radps2)       # (the scenario's limit kept: braked all the same)
            if brake and brake[0] < prof.brake_limit_radps2:
                prof.replan(t_s, prof.rate_limit_radps, prof.accel_limit_radps2, *brake)
            return
        if prof.replan(t_s, prof.rate_limit_radps, limit, *self._brake_limit(limit)):
            self.events.emit(t_s, EV.REFERENCE_RESHAPED, limit=math.degrees(limit))

    def _brake_limit(self, limit: float) -> tuple:
        """The braking limit for the reference's acceleration limit, as replan's extra argument
        (none: the reference brakes at its acceleration limit). Mode npc: the limit over
        1 + guidance.npc_inertia_unc. The LP sizes the limit for the nominal inertia; a turn
        that sets off too fast for a heavier truth is held back by the shaper's governor, but
        a braking the truth cannot match carries the vehicle past a reference at rest, and the
        governor must not ease a braking reference (it would carry it past its target). The
        paper's schedules (mode profile) fly minimum-jerk transitions and keep their law."""
        if self.scenario.guidance_mode != "npc":
            return ()
        return (limit / (1.0 + self.params["guidance.npc_inertia_unc"]),)

    # ---------------------------------------------------------------- parameters, life cycle
    def set_param(self, name: str, value: float) -> None:
        """Owner's hook for guidance.*: the LP and the re-plan read them from ``params``
        (already holding the new value); after a reconfiguration, assess again so the
        reference uses it now."""
        if self.controllability is not None:
            self.assess(self.now_s())
        self.trim[_T_MAX] = math.radians(self.params["guidance.trim_max_deg"])   # (not if assess refused it)

    def warm(self, timeout_s: float) -> bool:
        """Before the first real-time cycle: the LP solved once on this thread (the loop's, where
        the duty-cycle realiser runs HiGHS) and once on the LP's own thread (HiGHS sets itself up
        per thread; cold, that first solve holds the GIL long enough to make the control cycle
        of the first fault slip). The answers are discarded. True if the LP's thread finished
        in time."""
        _, args = self.lp_problem(self.now_s())
        controllability(*args)
        return self.lp.warm(*args, timeout_s=timeout_s)

    def close(self) -> None:
        self.lp.close()


def _limit_text(accel_radps2: float) -> str:
    """The reference's acceleration limit as events state it [deg/s^2]."""
    return f"{math.degrees(accel_radps2):.2f}"
