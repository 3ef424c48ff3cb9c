"""Numerical predictor-corrector entry guidance (docs/fsw/entry-guidance.md), after P. Lu,
"Entry Guidance: A Unified Method", JGCD 37(3), 2014 (FNPEG): ``EntryGuidance``, the
guidance mode ``npc`` that drives the package's pieces (predictor, corrector, density
estimator, lateral logic, bank shaper) from the rate groups, and the parameters they
take (``PARAMS``).
"""
from __future__ import annotations

import math
from typing import NotRequired, TypedDict

import numpy as np

from common import atmosphere
from common.model import Scenario
from common.events import EventLog
from interfaces.event_catalogue import EV, REVERSAL_RULE
from ..jobs import AWAITED, REALTIME, BackgroundJob
from ..params import Param
from .corrector import Correction, Corrector
from .estimator import DensityEstimator
from .geometry import heading_error, planet_fixed
from .lateral import LateralLogic
from .predictor import (C_G0, C_NLIM, C_QLIM, C_RN, C_T_MAX, N_O, SUTTON_GRAVES_MARS, path_limited_bank, predict,
                        predict_shaped)
from .shaper import BankShaper, shaper_accel, shaper_branch

# Ground-settable: EntryGuidance.set_param takes a new value, and the next guidance cycle
# applies it to the predictor, the corrector, the estimator, the path limits and the lateral
# logic before it starts its correction (never inside one).
PARAMS = [
    Param("npc.bank_final_deg", 0.0, 180.0, "deg", "bank magnitude at the deploy energy (phi_f)"),
    Param("npc.bank_min_deg", 0.0, 90.0, "deg", "lower bound of phi_0"),
    Param("npc.bank_max_deg", 90.0, 180.0, "deg", "upper bound of phi_0"),
    Param("npc.h_deploy_m", 0.0, 5e4, "m", "altitude that defines the deploy energy e_f"),
    Param("npc.dt_pred_s", 0.1, 10.0, "s", "predictor RK4 step"),
    Param("npc.max_iter", 1, 20, "", "predictions per guidance cycle (at most)", integer=True),
    Param("npc.tol_m", 1.0, 1e5, "m", "range miss accepted by the corrector"),
    Param("npc.k_tau_s", 0.1, 100.0, "s", "time constant of the density and L/D estimates"),
    Param("npc.k_min", 0.05, 1.0, "", "lower bound of the density and L/D scale estimates"),
    Param("npc.k_max", 1.0, 20.0, "", "upper bound of the density and L/D scale estimates"),
    Param("npc.k_drag_min", 0.0, 10.0, "m/s^2", "modelled drag below which the estimates hold"),
    Param("npc.dpsi_hi_deg", 0.0, 45.0, "deg", "heading corridor half-width at entry speed"),
    Param("npc.dpsi_lo_deg", 0.0, 45.0, "deg", "heading corridor half-width at deploy speed"),
    Param("npc.rev_gap_s", 0.0, 300.0, "s", "minimum time between bank reversals"),
    Param("npc.v_norev_mps", 0.0, 8000.0, "m/s", "no reversal below this speed"),
    Param("npc.limit_frac", 0.1, 1.0, "", "path limits enforced at this fraction of the vehicle's"),
    Param("npc.hdot_tau_s", 0.5, 200.0, "s", "altitude-rate feedback: time to close on the limit altitude"),
    Param("npc.hdot_gain", 0.0, 1.0, "s/m", "altitude-rate feedback: change of cos(bank) per m/s"),
    Param("npc.tgo_freeze_s", 0.0, 300.0, "s", "predicted time to deploy below which phi_0 is held"),
    Param("npc.h_floor_m", 0.0, 5e4, "m", "deploy altitude floor: the predicted deploy altitude is kept above it "
          "plus the margin, range traded (0: off)"),
    Param("npc.h_fire_m", 0.0, 5e4, "m", "predicted altitude at the deploy point (the target) kept above it by "
          "lifting up late, range kept (below it the trigger's altitude floor fires short of the target)",
          ground_settable=False),
    Param("npc.lift_final_min_deg", 0.0, 90.0, "deg", "lifting up late lowers phi_f no further (the lateral lift "
          "left at the end for the final reversal)", ground_settable=False),
    Param("npc.range_reserve_m", 0.0, 2e4, "m", "range trigger: the range solution aims this far beyond the target "
          "(a vehicle long by less still deploys at the target; one short by less still reaches it)",
          ground_settable=False),
    # design bounds of the floor's margin (the unit tests show the rule; the guided campaign sized them)
    Param("npc.floor_margin_k", 0.0, 10.0, "", "floor margin: this many times the measured prediction error",
          ground_settable=False),
    Param("npc.floor_margin_min_m", 0.0, 2e4, "m", "floor margin at least", ground_settable=False),
    Param("npc.floor_margin_max_m", 0.0, 2e4, "m", "floor margin at most", ground_settable=False),
    # a design bound of the floor's trade (the unit tests show it); no take-effect case from
    # the guided-nominal start, where no trade within any bound reaches a floor
    Param("npc.floor_miss_max_m", 0.0, 1e5, "m", "predicted deploy miss the altitude floor may trade up to",
          ground_settable=False),
]


class CorrectionFault(TypedDict):
    """A correction that raised: the previous command stays."""
    error: str
    t_s: NotRequired[float]
    sign: NotRequired[float]


class EntryGuidance(Corrector):
    """Guidance mode ``npc``: one predictor-corrector cycle per call of ``cycle`` (the slow
    rate group), the correction (Corrector.solve) off the loop, and the bank command
    applied every control period by ``steer`` (density estimate, path limits, reversal
    sign, then the shaper).

    The correction runs on a worker thread (the predictor releases the GIL) and its
    answer is due ``apply_delay_s`` after the cycle's release. Lockstep and batch
    (``realtime`` False) wait for it at that moment if it is not there yet, so every run
    applies the same answer at the same step: deterministic, and the control ticks in
    between run while it computes. In real time the control loop never waits: an answer
    not there when due is an overrun (event; the previous command stays until it
    arrives), and a cycle released while the previous one still computes is skipped."""

    STATS = 4096

    def __init__(self, scenario: Scenario, params: dict, events: EventLog, dt_control_s: float,
                 realtime: bool = False, apply_delay_s: float = 0.5):
        # its own copy of the parameters (Corrector): a ground set reaches it between
        # corrections (set_param, applied by the next cycle), never while the worker predicts
        super().__init__(scenario, params)
        self.events = events
        self._pending: dict[str, float] = {}
        veh = scenario.vehicle
        self.n_lim_g, self.q_lim_wm2 = self.constants[C_NLIM], self.constants[C_QLIM]
        self.estimator = DensityEstimator(params, veh.S_ref_m2, veh.mass_kg, veh.aero.C_L, veh.aero.C_D)
        bank0 = scenario.bank_schedule[0][1]
        v_f = scenario.end_speed_mps or scenario.end_mach * atmosphere.speed_of_sound(params["npc.h_deploy_m"])
        self.lateral = LateralLogic(params, scenario.speed_rel_mps, v_f, sign0=bank0)
        self.shaper = BankShaper(bank0, scenario.bank_rate_limit_radps, scenario.bank_accel_limit_radps2,
                                 dt_control_s)
        self.dt_control_s = dt_control_s
        self.bank0_cmd = abs(bank0)      # phi_0 commanded [rad]: the range solution, or the floor's
        self._line = (math.nan, abs(bank0), abs(bank0))   # the answer's profile flown: (e0, phi_0 of the
                                         # line, phi_f), clipped to the phi_0 bounds as predicted
        self.floor_cycles = 0            # cycles whose answer traded range for the deploy-altitude floor
        # the floor's margin, sized by the predictor's own measured error: the change of the
        # predicted deploy altitude from one answer to the next (what the prediction did not
        # foresee: density, L/D, the state), a random walk over the cycles still to fly
        self._h_pred_prev = math.nan
        self._sign_prev = math.nan       # bank sign the last answer was solved for
        self._dh_var = math.nan          # low-passed square of that change [m^2] ...
        self._dh_mean = 0.0              # ... and its low-passed mean [m]
        self._period_s = 1.0             # guidance cycle period
        self.floor_margin_m = params["npc.floor_margin_min_m"]
        self.held_cycles = 0             # cycles whose range solution holds a phi_0 bound (bank_profile)
        self.bank_cmd = abs(bank0)       # magnitude commanded now [rad] (after the path limits)
        self.miss_m = math.nan           # predicted range miss z of the last solution
        self.range_to_go_m = math.nan
        self.pred_impact = np.full(2, math.nan)   # predicted deploy point (lat, lon) [rad]
        self.pred_h_m = math.nan
        self.t_go_s = math.inf           # predicted time to deploy (last solution, from its state)
        self._t_answer = math.nan        # release time of the last answer applied (its state's time)
        self.xr_keep_m = math.nan        # predicted deploy crossrange, sign kept [+ left]
        self.xr_rev_m = math.nan         # ... reversed at the next cycle
        self.xr_keep_held_m = math.nan   # the same, this answer's magnitude held (LateralLogic)
        self.xr_rev_held_m = math.nan
        self._t_cycle = math.nan         # release time of the last cycle
        self.cycles = 0                  # corrections whose answers were applied
        self.no_root = 0
        self.calls = np.zeros(self.STATS, np.int32)
        self.compute_ns = np.zeros(self.STATS, np.int64)
        self.k_rho_hist = np.zeros(self.STATS)
        self.t_hist = np.zeros(self.STATS)
        self.bank0_hist = np.zeros(self.STATS)
        self.miss_hist = np.zeros(self.STATS)
        self._frozen = False
        self.realtime = realtime
        self.apply_delay_s = apply_delay_s
        self._warm_up()
        # the correction off the loop: due apply_delay_s after its release, awaited then in
        # lockstep and batch; a release while the previous one computes is skipped
        self.job = BackgroundJob(self.solve, "npc-guidance", mode=REALTIME if realtime else AWAITED,
                                 skip_while_busy=True, events=events,
                                 overrun_event=EV.GUIDANCE_OVERRUN, fault_event=EV.GUIDANCE_FAULT)

    def _warm_up(self) -> None:
        """Compile (or load from numba's cache) every kernel with the argument types flight
        uses, here at construction: a first compile inside a guidance cycle would hold
        lockstep for as long as it takes, longer than the plant waits for a silent FSW."""
        c = self.constants.copy()
        c[C_T_MAX] = 0.0                 # the initial derivative only
        x = np.array([self.radius_m + 1e5, 0.0, 0.0, 0.0, 1e3, 0.0])
        predict(x, c, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, np.zeros(N_O), 0.0)
        predict_shaped(x, c, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0, np.zeros(N_O),
                       np.array([0.0, 0.0, 1.0, 0.0, 0.1, 0.01, 0.02, 1.0]), 1.0)
        path_limited_bank(1.0, 1e4, -1.0, 1.0, 1.0, 1.0, 1.0, self.scale_height_m, 1.0, 0.0)
        shaper_accel(0.0, 0.0, 1.0, 1.0, 1.0, 0.02)
        shaper_branch(0.0, 1.0, 0.0, 1.0)

    # ------------------------------------------------------------------ rate groups
    def cycle(self, nav, t_s: float) -> None:
        """The guidance cycle (slow rate group): lateral decision, then the correction."""
        if self._pending:
            self._take_params(t_s)
        x = planet_fixed(nav.r_N, nav.v_N, t_s, self.omega_radps)
        dpsi, ang = heading_error(x, self.target_u)
        self.range_to_go_m = ang * self.radius_m
        V = nav.V_rel_mps
        # the crossranges were predicted from the last cycle's state, the reversal in them
        # commanded one cycle later (now); the time to deploy is aged from the answer's own
        # release (a late answer's is older than the last cycle)
        t_go = self.t_go_s - (t_s - self._t_answer) if math.isfinite(self._t_answer) else math.inf
        if self.lateral.update(t_s, V, dpsi, self.xr_keep_m, self.xr_rev_m, t_go,
                               self.shaper.reversal_s(self.bank_cmd), self.xr_keep_held_m, self.xr_rev_held_m):
            # for the sign just left
            self.xr_keep_m = self.xr_rev_m = self.xr_keep_held_m = self.xr_rev_held_m = math.nan
            self.events.emit(t_s, EV.BANK_REVERSAL, rule=REVERSAL_RULE.code_of(self.lateral.rules[-1].upper()),
                             dpsi_deg=math.degrees(dpsi))
        period = t_s - self._t_cycle if math.isfinite(self._t_cycle) else 1.0
        self._period_s = period
        self._t_cycle = t_s
        if self._frozen:
            return
        sign = self.lateral.sign
        # a reversal decided at the next cycle, flown through the shaper from its state now;
        # for the held pair in effect at once at its shaped transition's mid-point (half-way the
        # lateral lift has turned over)
        t_flip = period
        t_flip_held = period + 0.5 * self.shaper.reversal_s(self.bank_cmd)
        shp = self.shaper.state(self.bank_cmd)
        base = self.params["npc.h_floor_m"]
        self.job.submit(x, sign, self.estimator.k_rho, self.estimator.k_ld, t_flip, shp,
                        base + self.floor_margin_m if base > 0.0 else 0.0, t_flip_held, tag=sign, t_s=t_s, due_t=t_s + self.apply_delay_s - 1e-9)

    def _apply(self, res: Correction) -> None:
        i = self.cycles % self.STATS
        self.calls[i], self.compute_ns[i] = res["predictions"], res["compute_ns"]
        self.k_rho_hist[i], self.t_hist[i] = self.estimator.k_rho, res["t_s"]
        self.bank0_hist[i], self.miss_hist[i] = res["bank0_rad"], res["miss_m"]
        self.cycles += 1
        self.bank0, self._p_e0_jpkg = res["p_range_rad"], res["e0_jpkg"]
        self.f_lift_rad = res["f_family_rad"]
        self.bank0_cmd = res["bank0_rad"]
        self._line = (res["e0_jpkg"], res["bank_line_rad"], res["bank_final_rad"])
        if res["floor"]:
            if self.floor_cycles == 0:
                self.events.emit(res["t_s"], EV.DEPLOY_ALT_FLOOR, miss_km=res["miss_m"] / 1e3)
            self.floor_cycles += 1
        self.held_cycles += bool(res["held"])
        self.miss_m = res["miss_m"]
        self.pred_impact[:] = (res["lat_rad"], res["lon_rad"])
        # an answer for another bank sign than the last one, or with a reversal turned round,
        # predicts another flight: its change is the decision's, not a prediction error
        decided = res["sign"] != self._sign_prev or math.isfinite(res["turn_rad"])
        self._sign_prev = res["sign"]
        self._measure_prediction(res["h_box_m"], res["t_go_s"], decided)
        self.pred_h_m = res["h_final_m"]
        self.t_go_s, self._t_answer = res["t_go_s"], res["t_s"]
        if self.shaper.turn_round(res["turn_rad"], res["sign"]):
            # the reversal under way turned round (solve: no range solution the way it went)
            self.events.emit(res["t_s"], EV.REVERSAL_WAY, miss_km=res["miss_m"] / 1e3)
        if res["sign"] == self.lateral.sign:        # not for a sign left since the job started
            self.xr_keep_m, self.xr_rev_m = res["xr_keep_m"], res["xr_rev_m"]
            self.xr_keep_held_m, self.xr_rev_held_m = res["xr_keep_held_m"], res["xr_rev_held_m"]
        if not res["ok"]:
            self.no_root += 1
            self.events.emit(res["t_s"], EV.GUIDANCE_NO_ROOT, miss_km=res["miss_m"] / 1e3)
        if res["t_go_s"] < self.params["npc.tgo_freeze_s"]:
            self._frozen = True         # too close to the deploy for the range to respond

    DH_WEIGHT = 0.2                      # low-pass weight of one new change of the prediction
    DH_DRIFT_WEIGHT = 0.05               # ... and of its mean (a drift shows over tens of cycles)

    def _measure_prediction(self, h_m: float, t_go_s: float, decided: bool = False) -> None:
        """The floor's margin from the measured change per cycle of the predicted box-entry
        altitude, npc.floor_margin_k times: its downward drift (low-passed mean) carried over
        the cycles to the deploy (the part of the mean its own noise does not explain), plus the
        rest of it (low-passed RMS about that mean) as a random walk (sqrt of their number),
        within [floor_margin_min_m, floor_margin_max_m].
        A prediction that keeps falling (a density profile or L/D the estimates lag) is a bias,
        not noise: over n cycles it costs n times the drift, not sqrt(n) times.
        decided: the answer predicts another flight than the last one (another bank sign, a
        reversal turned round). Its change is the decision's (a reversal through lift down
        deploys kilometres lower, and is flown so), not what the last prediction failed to
        foresee: not measured, the next change is measured from it. Counted as error, one such
        jump holds the margin at its maximum for many cycles after a reversal, and the lift-up
        late it sets off leaves the final reversal too little bank to null the crossrange with."""
        p = self.params
        if math.isfinite(h_m) and math.isfinite(self._h_pred_prev) and not decided:
            d = h_m - self._h_pred_prev
            if not math.isfinite(self._dh_var):
                self._dh_var, self._dh_mean = d * d, 0.0
            else:
                self._dh_var = (1.0 - self.DH_WEIGHT) * self._dh_var + self.DH_WEIGHT * d * d
                self._dh_mean = (1.0 - self.DH_DRIFT_WEIGHT) * self._dh_mean + self.DH_DRIFT_WEIGHT * d
        self._h_pred_prev = h_m
        if math.isfinite(self._dh_var) and math.isfinite(t_go_s):
            n = max(1.0, t_go_s / max(self._period_s, 1e-3))
            rest = max(0.0, self._dh_var - self._dh_mean ** 2)
            w = self.DH_DRIFT_WEIGHT
            drift = max(0.0, -self._dh_mean - math.sqrt(rest * w / (2.0 - w)))   # beyond the mean's own noise
            m = p["npc.floor_margin_k"] * (drift * n + math.sqrt(rest * n))
            self.floor_margin_m = min(p["npc.floor_margin_max_m"], max(p["npc.floor_margin_min_m"], m))

    def steer(self, nav) -> None:
        """Every control period: the density estimate, the last answer's bank profile at today's
        energy, the path limits, then the shaper."""
        ans = self.job.take(nav.t_s)
        if ans is not None:
            res = ans.value
            res["t_s"], res["sign"] = ans.t_s, ans.tag
            self._apply(res)
        self.estimator.update(self.dt_control_s, nav.accel_B, nav.C_BN, nav.vrel_N, nav.rho_kgpm3)
        V = nav.V_rel_mps
        r = nav.r_N
        rn = math.sqrt(float(r @ r))
        hdot = float(nav.vrel_N @ r) / rn
        a, c = nav.accel_B, self.constants
        n_g = math.sqrt(float(a @ a)) / c[C_G0]
        q = SUTTON_GRAVES_MARS * math.sqrt(max(nav.rho_kgpm3, 0.0) * self.estimator.k_rho / c[C_RN]) * V ** 3
        # the answer's profile at today's energy (the bank its prediction flew), not its start held
        # for the cycle: the next answer, re-anchored, is then the same profile (profile_at)
        e0, b_line, b_f = self._line
        mag = self.bank0_cmd
        if math.isfinite(e0) and self.e_deploy_jpkg != e0:
            e = self.mu_m3ps2 / rn - 0.5 * V * V
            frac = min(1.0, max(0.0, (e - e0) / (self.e_deploy_jpkg - e0)))
            mag = min(self.bank_max_rad, max(self.bank_min_rad, b_line + (b_f - b_line) * frac))
        self.bank_cmd = path_limited_bank(mag, nav.h_m, hdot, n_g, q, self.n_lim_g, self.q_lim_wm2,
                                          self.scale_height_m, self.params["npc.hdot_tau_s"],
                                          self.params["npc.hdot_gain"])
        self.shaper.command(self.lateral.sign * self.bank_cmd)

    def close(self) -> None:
        self.job.close()

    @property
    def released(self) -> int:
        return self.job.released

    @property
    def overruns(self) -> int:
        return self.job.late + self.job.skipped

    @property
    def faults(self) -> int:
        return self.job.faults

    # ------------------------------------------------------------------ parameters
    def set_param(self, name: str, value: float) -> None:
        """Owner's hook (fsw/params.py): a new npc.* value, bounds already checked, applied by
        the next guidance cycle once no correction is running. ValueError (nothing changed)
        when it would leave the phi_0 bounds empty."""
        lo = value if name == "npc.bank_min_deg" else self._pending.get("npc.bank_min_deg", self.params["npc.bank_min_deg"])
        hi = value if name == "npc.bank_max_deg" else self._pending.get("npc.bank_max_deg", self.params["npc.bank_max_deg"])
        if not lo < hi:
            raise ValueError(f"{name}: needs bank_min < bank_max ({lo:g}, {hi:g})")
        self._pending[name] = float(value)

    def _take_params(self, t_s: float) -> None:
        """Apply the pending sets where the construction put each value (the worker is idle:
        lockstep has its answer; in real time a cycle with a correction still running waits)."""
        if self.job.busy:
            return
        p, scn = self.params, self.scenario
        p.update(self._pending)
        names, self._pending = set(self._pending), {}
        self.take_params(names)
        if "npc.h_deploy_m" in names:
            self.lateral.v_lo_mps = scn.end_speed_mps or scn.end_mach * atmosphere.speed_of_sound(p["npc.h_deploy_m"])
        self.n_lim_g, self.q_lim_wm2 = self.constants[C_NLIM], self.constants[C_QLIM]
        est = self.estimator
        est.tau_s, est.k_min, est.k_max, est.drag_min_mps2 = p["npc.k_tau_s"], p["npc.k_min"], p["npc.k_max"], \
            p["npc.k_drag_min"]
        lat = self.lateral
        lat.dpsi_hi_rad, lat.dpsi_lo_rad = math.radians(p["npc.dpsi_hi_deg"]), math.radians(p["npc.dpsi_lo_deg"])
        lat.gap_s, lat.v_norev_mps, lat.t_settle_s = p["npc.rev_gap_s"], p["npc.v_norev_mps"], p["npc.tgo_freeze_s"]
        for n in sorted(names):
            self.events.emit(t_s, EV.NPC_PARAM, param=n.upper(), value=p[n])

    def stats(self) -> dict:
        n = min(self.cycles, self.STATS)
        us = self.compute_ns[:n] / 1e3
        calls = self.calls[:n]

        def pct(a, q):
            return float(np.percentile(a, q)) if n else None
        return {"released": self.released, "cycles": self.cycles, "compute_p50_us": pct(us, 50),
                "compute_p99_us": pct(us, 99), "compute_max_us": float(us.max()) if n else None,
                "predictions_per_cycle_mean": float(calls.mean()) if n else None,
                "predictions_per_cycle_max": int(calls.max()) if n else None,
                "no_root": self.no_root, "floor_cycles": self.floor_cycles,
                "floor_margin_final_m": self.floor_margin_m, "held_cycles": self.held_cycles,
                "overruns": self.overruns, "faults": self.faults,
                "reversal_times_s": list(self.lateral.reversals), "reversal_rules": list(self.lateral.rules),
                "k_rho_final": self.estimator.k_rho, "k_ld_final": self.estimator.k_ld,
                "bank0_final_deg": math.degrees(self.bank0_cmd)}
