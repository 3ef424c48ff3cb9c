"""The judgement batch and SIL share: the offline check of the allocation samples, the
figures that turn a history and the FSW's report into summary.json, the end reasons that
count as completed with their exit codes, and the summary's text. The batch runner
(ellipsled/batch.py) and the SIL launcher (ellipsled/sil/launcher.py) call the same
functions, so a lockstep SIL run is judged like its batch twin. FSW modules are imported
where they are used: the launcher starts without loading the flight software.
"""
from __future__ import annotations

import math

import numpy as np

from common.model import Scenario, inertia_vector
from interfaces.records import DEPLOY_EDGE, DEPLOY_FLOOR, DEPLOY_NONE, DEPLOY_RANGE, DEPLOY_VELOCITY
from interfaces.vocabulary import FAULT_HEALTH, NOMINAL

from .metrics import deploy_figures, summarize, wrap_deg
from .sil.history import History


def box_name(spill_jets: float) -> str:
    """The allocation box flown, as the report names it."""
    if spill_jets == 0.0:
        return "sign box (paper)"
    return f"spill box ({spill_jets:g} largest-jet torque per axis)"


def verify_allocations(scn: Scenario, params: dict, samples: list[dict]) -> tuple[float | None, int]:
    """Re-solve sampled demands by exhaustive enumeration: the largest objective gap seen."""
    from fsw.allocation.model import spill_of
    from fsw.allocation.reference import solve_enumeration
    from fsw.health import JetHealth
    veh = scn.vehicle
    w = np.array([params["allocator.w_roll"], params["allocator.w_pitch"], params["allocator.w_yaw"]])
    c = params["allocator.penalty_per_N"]   # per newton: c_k = c * thrust_k
    gap = 0.0
    n = 0
    for s in samples:
        if not math.isfinite(s["objective"]):
            continue
        h = JetHealth()
        h.state[:], h.eta[:], h.inhibited[:] = s["state"], s["eta"], s["inhibited"]
        _, ref, _ = solve_enumeration(veh.torque_matrix_Nm, veh.thrust_N, h, w, c, np.array(s["tau_d"]), True,
                                      spill_of(veh.torque_matrix_Nm, params["allocator.spill_jets"]))
        gap = max(gap, abs(s["objective"] - ref))
        n += 1
    return (gap if n else None), n


def adaptive_truth(scn: Scenario) -> np.ndarray:
    """The true values of SAMI's parameters [h (6) kg m^2; d (3)]: the truth inertia, and the
    aerodynamic factors the FSW's nominal moments are off by (density lumped with each
    coefficient, as the FSW's nominal atmosphere does)."""
    tr = scn.truth
    h = inertia_vector(scn.vehicle.inertia_kgm2) * tr.inertia_scale
    d = tr.density_scale * np.array([tr.C_lbeta_scale, tr.C_malpha_scale, tr.C_nbeta_scale])
    return np.concatenate((h, d))


def judge(h: History, scn: Scenario, seed: int, end_reason: str, rep: dict, faults_applied: list,
          params: dict, ref: History | None = None, deploy: dict | None = None) -> dict:
    """summary.json: figures of merit from the history, FDIR judged against the faults the
    plant actually applied (its ``fault_log``). The same function serves batch and SIL.
    ``ref``: the fault-free twin (reference.fault_free_history) for the fault-attributable figures.
    ``deploy``: the plant's deploy report (sim/plant.py Plant.deploy_report), when the FSW deploys."""
    from .controllable import truth_controllability     # the FSW's LP: not in the plant process
    injected = {}
    for t, jet, kind in faults_applied:
        injected.setdefault(jet, (t, kind))
    dets = rep["detections"]
    false_alarms = sum(1 for d in dets
                       if d["jet"] not in injected or injected[d["jet"]][1] != d["kind"])     # kinds are health words
    missed = sorted(j for j, (t, kind) in injected.items()
                    if FAULT_HEALTH[kind] != NOMINAL and not any(d["jet"] == j for d in dets))
    cu, au = h["compute_us"], h["alloc_us"]

    def pct(x, q):
        return float(np.percentile(x, q)) if len(x) else None

    gap, checked = verify_allocations(scn, params, rep["alloc_samples"])
    extra = {
        "control_cycle": {"compute_p50_us": pct(cu, 50), "compute_p99_us": pct(cu, 99),
                          "compute_max_us": float(np.max(cu)) if len(cu) else None,
                          # cycles whose compute took longer than the control period: a host figure
                          # in lockstep (the plant waits), a cycle slip in real time
                          "compute_overruns": int(np.sum(cu > scn.dt_control_s * 1e6))},
        "allocator": {"solves": int(len(au)), "p50_us": pct(au, 50), "p99_us": pct(au, 99),
                      "max_us": float(np.max(au)) if len(au) else None,
                      "degraded": int(np.sum(h["alloc_degraded"])),
                      "short": int(np.sum(h["alloc_short"])),
                      # cycles flown by the duty-cycle modulator (fsw/allocation/dutycycle.py)
                      "modulated": rep.get("alloc_modulated"),
                      "box": box_name(params["allocator.spill_jets"]),
                      "optimality_gap_max": gap, "optimality_checked": checked},
        "fdir": {"detections": dets, "false_alarms": false_alarms, "missed": missed},
        "propellant_kg": rep["propellant_kg"],
        "jet_pulses": int(sum(rep["jet_pulses_per_jet"])),
        "jet_pulses_per_jet": rep["jet_pulses_per_jet"],
        "cycle_slips": rep["cycle_slips"],
        "events": rep["events"],
        "bank_err_sched_max_after_fault_deg": schedule_error_max_deg(h, scn, faults_applied),
        "controllability": truth_controllability(scn, faults_applied, h["t_s"], h["qbar_pa"],
                                                 params["guidance.trim_max_deg"]),
    }
    extra["identification"] = params.get("fdir.mode", "detect")
    if extra["identification"] == "oracle":
        extra["test_mode"] = "oracle identification: the plant's fault log given to FDIR at the fault time"
    completed = end_reason in COMPLETED_END_REASONS
    if scn.target_lat_rad is not None:
        g = rep.get("guidance", {})
        extra.update(deploy_figures(h, target_lat_rad=scn.target_lat_rad, target_lon_rad=scn.target_lon_rad,
                                    radius_m=scn.planet.radius_m, nose_radius_m=scn.vehicle.nose_radius_m,
                                    entry_altitude_m=scn.altitude_m))
        extra["guidance_mode"] = scn.guidance_mode
    if scn.deploy_by == "fsw":
        extra["deploy"] = deploy_summary(h, scn, end_reason, deploy)
        extra["reversal_count"] = len(g.get("reversal_times_s", []))
        extra["guidance"] = g
        extra["limits"] = {"load_g": scn.vehicle.max_load_g, "heat_rate_wcm2": scn.vehicle.max_heat_rate_wcm2}
    return summarize(h, scenario=scn.name, seed=seed, end_reason=end_reason, completed=completed,
                     fault_t_s=min((t for t, _, _ in faults_applied), default=None),
                     reconfig_t_s=rep["reconfig_times_s"][0] if rep["reconfig_times_s"] else None,
                     alpha_trim_rad=scn.vehicle.aero.alpha_trim_rad,
                     schedule_t=[t for t, _ in scn.bank_schedule], extra=extra, ref=ref,
                     theta_truth=adaptive_truth(scn))


DEPLOY_RULES = {DEPLOY_NONE: None, DEPLOY_RANGE: "range", DEPLOY_VELOCITY: "velocity", DEPLOY_EDGE: "fsw_box_edge",
                DEPLOY_FLOOR: "altitude_floor"}


def deploy_summary(h: History, scn: Scenario, end_reason: str, plant: dict | None) -> dict:
    """The parachute deploy of a run whose FSW deploys: the FSW's rule (range, velocity, or its
    own box-edge backstop), whether the plant deployed on the command inside the box ('ok')
    or at the box's edge without one (a failure: 'edge' says which), and where."""
    n = len(h["t_s"])
    code = int(h["deploy"][-1]) if n else DEPLOY_NONE
    plant = plant or {}
    return {"rule": DEPLOY_RULES.get(code), "ok": end_reason == "deploy", "by": plant.get("by"),
            "edge": plant.get("edge"), "refused_outside_box": plant.get("refused_outside_box", 0),
            "mach": float(h["mach"][-1]) if n else None, "qbar_pa": float(h["qbar_pa"][-1]) if n else None,
            "alt_km": float(h["h_m"][-1]) / 1e3 if n else None}


def schedule_error_max_deg(h: History, scn: Scenario, faults_applied: list) -> float | None:
    """max |bank - the scenario's own smoothed schedule| after the fault [deg]: the bank error
    against the reference before any re-plan (the FSW's re-planned reference may lag it)."""
    from fsw.guidance.reference import BankProfile
    t = h["t_s"]
    t_f = min((tf for tf, _, _ in faults_applied), default=2.5)
    m = t >= t_f
    if not np.any(m):
        return None
    prof = BankProfile(scn.bank_schedule, scn.bank_rate_limit_radps, scn.bank_accel_limit_radps2)
    ref = np.array([prof.evaluate(float(x))[0] for x in t[m]])
    return float(np.max(np.abs(wrap_deg(np.degrees(h["bank_rad"][m] - ref)))))


# End reasons of a run that completed: the deploy conditions (Mach, speed, the FSW's deploy
# command, the deploy box's edge, altitude) or the requested duration. Any other (timeout, non_finite, fsw_timeout, no_fsw, stopped) did not.
COMPLETED_END_REASONS = ("mach", "speed", "deploy", "box_edge", "altitude", "duration")
EXIT_COMPLETED, EXIT_NOT_COMPLETED = 0, 1

EXIT_CODES_HELP = f"""\
exit codes (batch and run alike, for the same request):
  {EXIT_COMPLETED}    the run completed: it reached deployment (end reason mach, speed,
       deploy, box_edge or altitude) or the requested --duration (end reason duration)
  {EXIT_NOT_COMPLETED}    the run did not complete: the scenario's time cap reached first
       (timeout), a non-finite state (non_finite), the flight software silent
       (fsw_timeout, no_fsw), stopped, or no complete records to judge
  2    bad command line or configuration (nothing flown)
  130  interrupted (Ctrl-C)"""


def exit_code(end_reason: str) -> int:
    """The process exit code of a run that ended for ``end_reason`` (batch and SIL)."""
    return EXIT_COMPLETED if end_reason in COMPLETED_END_REASONS else EXIT_NOT_COMPLETED


def format_summary(s: dict) -> str:
    def f(x, fmt="{:.2f}"):
        return "n/a" if x is None else fmt.format(x)
    a = s["allocator"]
    rt = s.get("realtime_factor")
    return "\n".join([
        f"{s['scenario']} (seed {s['seed']}): {'completed' if s['completed'] else 'NOT completed'} "
        f"({s['end_reason']}) at t = {s['t_end_s']:.1f} s" + (f", {rt:.0f}x real time" if rt else "")
        + (f"  [TEST MODE: {s['test_mode']}]" if s.get("test_mode") else ""),
        f"  bank error: max after fault {f(s['bank_err_max_after_fault_deg'])} deg, due to the faults"
        f" {f(s.get('bank_err_fault_attrib_max_deg'))} deg, after t = 10 s {f(s['bank_err_max_after_transient_deg'])} deg,"
        f" RMS {f(s['bank_err_rms_deg'])} deg, settle after reconfiguration {f(s['settle_time_after_reconfig_s'])} s",
        f"  alpha dev max {f(s['alpha_dev_max_deg'])} deg, beta dev max {f(s['beta_dev_max_deg'])} deg",
        f"  propellant {s['propellant_kg']:.2f} kg, {s['jet_pulses']} pulses, effort applied"
        f" {s['control_effort_applied']:.3g} (commanded {s['control_effort_cmd']:.3g},"
        f" undeliverable {f(s['control_effort_undeliverable_share'], '{:.0%}')})",
        f"  allocator: {a['solves']} solves, p50 {f(a['p50_us'], '{:.1f}')} us, p99 {f(a['p99_us'], '{:.1f}')} us,"
        f" degraded {a['degraded']}, short on the bank axis {a.get('short')}, modulated {a.get('modulated')}, optimality gap {f(a['optimality_gap_max'], '{:.2g}')} ({a['optimality_checked']} checked)",
        f"  FDIR: {len(s['fdir']['detections'])} detections, {s['fdir']['false_alarms']} false alarms,"
        f" missed {s['fdir']['missed']}; cycle slips {s['cycle_slips']}",
    ] + ([f"  deploy: miss {s['deploy_miss_km']:.2f} km (downrange {s['downrange_err_km']:+.2f}, crossrange "
          f"{s['crossrange_err_km']:+.2f}) at {s['deploy_alt_km']:.2f} km; peak load {s['peak_load_g']:.2f} g, "
          f"heat {s['peak_heat_rate_wcm2']:.1f} W/cm2; skip {s['skip']}; {s['reversal_count']} reversals; guidance "
          f"cycle p99 {f(s['guidance'].get('compute_p99_us'), '{:.0f}')} us"] if "deploy_miss_km" in s else []))
