"""The batch runner: plant and flight software in one process, stepped in lockstep.

No transport: the plant's SENSORS record goes straight to FlightSoftware.control_step and
the jet command straight back. The SIL runs the same two objects in two processes.
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from common.model import Scenario, load_scenario
from fsw.events import EventLog
from fsw.flightsoftware import FlightSoftware
from fsw.health import FAILED_OFF, STUCK_ON, DEGRADED
from sim.plant import Plant

from .history import History
from .metrics import summarize

KIND_OF_STATE = {FAILED_OFF: "failed_off", STUCK_ON: "stuck_on", DEGRADED: "degraded"}
KIND_OF_FAULT = {"off": "failed_off", "stuck": "stuck_on", "degraded": "degraded"}


def prepare(scenario: Scenario | str, ft_off: bool = False, duration_s: float | None = None) -> Scenario:
    scn = load_scenario(scenario) if isinstance(scenario, (str, Path)) else scenario
    if ft_off:
        fsw = {k: (dict(v) if isinstance(v, dict) else v) for k, v in scn.fsw.items()}
        fsw.setdefault("allocator", {})["fault_tolerance"] = 0
        scn = scn.with_(fsw=fsw, name=scn.name if scn.name.endswith("-ft-off") else f"{scn.name}-ft-off")
    if duration_s is not None:
        scn = scn.with_(max_duration_s=float(duration_s))
    return scn


def record_step(h: History, plant_truth: dict, fsw: FlightSoftware, u: np.ndarray, compute_ns: int) -> None:
    """One History row from the plant truth and the FSW state of the same step."""
    i = h.row()
    a = h.a
    tr = plant_truth
    a["t_s"][i] = tr["t_s"]
    for k in ("bank_rad", "alpha_rad", "beta_rad", "h_m", "V_rel_mps", "gamma_rad", "psi_rad", "lat_rad",
              "lon_rad", "mach", "qbar_pa", "decel_g"):
        a[k][i] = tr[k]
    a["omega_BN_B"][i] = tr["omega_BN_B"]
    a["sigma_BN"][i] = tr["sigma_BN"]
    a["tau_jets_B"][i] = tr["tau_jets_B"]
    g = fsw.guidance
    a["bank_ref_rad"][i] = g.phi_r
    a["bankdot_ref_radps"][i] = g.phidot_r
    a["sigma_RN"][i] = g.sigma_RN
    a["u_cal_B"][i] = fsw.u_cal_B
    a["tau_alloc_B"][i] = fsw.tau_alloc_B
    a["theta_hat"][i] = fsw.control.theta_hat
    a["jets_cmd"][i] = u
    a["health"][i] = fsw.health.state
    a["mode"][i] = int(fsw.modes.mode)
    a["alloc_degraded"][i] = fsw.allocator.degraded
    a["compute_us"][i] = compute_ns * 1e-3
    a["alloc_us"][i] = fsw.alloc_ns * 1e-3


def fsw_extra(fsw: FlightSoftware, plant_faults: list[tuple[float, int, str]], compute_us: np.ndarray,
              alloc_us: np.ndarray, degraded: np.ndarray, slips: int) -> dict:
    """The summary figures only the FSW knows, and FDIR judged against the injected truth."""
    injected = {}
    for t, jet, kind in plant_faults:
        injected.setdefault(jet, (t, kind))
    detections = [{"jet": int(d["jet"]), "kind": d["kind"], "t_s": round(float(d["t_s"]), 6),
                   **({"eta_hat": round(float(d["eta_hat"]), 4)} if d.get("eta_hat") is not None else {})}
                  for d in fsw.fdir.detections]
    false_alarms = sum(1 for d in detections
                       if d["jet"] not in injected or KIND_OF_FAULT.get(injected[d["jet"]][1]) != d["kind"])
    missed = sorted(j for j, (t, kind) in injected.items()
                    if kind != "clear" and not any(d["jet"] == j for d in detections))

    def pct(x, q):
        return float(np.percentile(x, q)) if len(x) else None

    return {
        "control_cycle": {"compute_p50_us": pct(compute_us, 50), "compute_p99_us": pct(compute_us, 99),
                          "compute_max_us": float(np.max(compute_us)) if len(compute_us) else None},
        "allocator": {"solves": int(len(alloc_us)), "p50_us": pct(alloc_us, 50), "p99_us": pct(alloc_us, 99),
                      "max_us": float(np.max(alloc_us)) if len(alloc_us) else None,
                      "degraded": int(np.sum(degraded)),
                      "optimality_gap_max": fsw.allocator_gap_max if hasattr(fsw, "allocator_gap_max") else None,
                      "optimality_checked": getattr(fsw, "allocator_checked", 0)},
        "fdir": {"detections": detections, "false_alarms": false_alarms, "missed": missed},
        "propellant_kg": float(fsw.driver.propellant_kg),
        "jet_pulses": int(np.sum(fsw.driver.pulses)),
        "jet_pulses_per_jet": [int(x) for x in fsw.driver.pulses],
        "cycle_slips": slips,
        "events": len(fsw.events.history),
    }


def verify_allocations(fsw: FlightSoftware, demands: list[tuple[np.ndarray, object, float]]) -> tuple[float, int]:
    """Re-solve sampled demands by exhaustive enumeration: the largest objective gap seen."""
    from fsw.allocation import solve_enumeration
    veh = fsw.scenario.vehicle
    gap = 0.0
    for tau_d, health, obj in demands:
        _, ref, _ = solve_enumeration(veh.torque_matrix_Nm, veh.thrust_N, health, fsw.allocator.w,
                                      fsw.allocator.c, tau_d, fsw.allocator.fault_tolerance)
        gap = max(gap, abs(obj - ref))
    return gap, len(demands)


def run(scenario: Scenario | str, seed: int | None = None, ft_off: bool = False, duration_s: float | None = None,
        verify_every: int = 1000) -> tuple[dict, History, FlightSoftware]:
    """Fly one scenario; returns (summary, history, fsw)."""
    scn = prepare(scenario, ft_off, duration_s)
    seed = scn.seed if seed is None else seed
    plant = Plant(scn, seed)
    events = EventLog()
    fsw = FlightSoftware(scn, events)
    n_est = int(math.ceil(scn.max_duration_s / scn.dt_control_s)) + 2
    h = History(n_est)
    rg2 = int(fsw.params["executive.rg2_divisor"])
    rg3 = int(fsw.params["executive.rg3_divisor"])
    period_ns = int(round(scn.dt_control_s * 1e9))
    slips = 0
    samples = []
    frame = plant.sensors
    wall0 = time.perf_counter()
    end_reason = "timeout"
    k = 0
    while True:
        t0 = time.perf_counter_ns()
        u = fsw.control_step(frame)
        if k % rg2 == 0:
            fsw.slow_step()
        if k % rg3 == 0:
            fsw.housekeeping()
        dt_ns = time.perf_counter_ns() - t0
        if dt_ns > period_ns:
            slips += 1
        if verify_every and k % verify_every == 0:
            samples.append((fsw.u_cal_B.copy(), fsw.health.copy(), float(fsw.allocator.objective)))
        record_step(h, plant.truth(), fsw, u, dt_ns)
        done, reason = plant.done()
        if done:
            end_reason = reason
            break
        frame = plant.step(u)
        k += 1
    wall = time.perf_counter() - wall0
    if samples:
        fsw.allocator_gap_max, fsw.allocator_checked = verify_allocations(fsw, samples)
    faults = [(f.t_s, j, f.kind) for f in scn.faults for j in f.jets]
    extra = fsw_extra(fsw, faults, h["compute_us"], h["alloc_us"], h["alloc_degraded"], slips)
    extra["wall_s"] = wall
    extra["realtime_factor"] = (h["t_s"][-1] / wall) if wall > 0 else None
    completed = end_reason in ("mach", "altitude") or (duration_s is not None and end_reason == "timeout")
    if duration_s is not None and end_reason == "timeout":
        end_reason = "duration"
    summary = summarize(h, scenario=scn.name, seed=seed, end_reason=end_reason, completed=completed,
                        fault_t_s=min((f.t_s for f in scn.faults), default=None),
                        reconfig_t_s=fsw.reconfig_times[0] if fsw.reconfig_times else None,
                        alpha_trim_rad=scn.vehicle.aero.alpha_trim_rad,
                        schedule_t=[t for t, _ in scn.bank_schedule], extra=extra)
    return summary, h, fsw


def write_outputs(summary: dict, h: History, out: Path, plots: bool = True) -> None:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    h.save(out / "history.npz")
    if plots:
        from .plots import plot_run
        plot_run(h, out, summary["scenario"])


def main(args) -> int:
    summary, h, fsw = run(args.scenario, seed=args.seed, ft_off=args.ft_off, duration_s=args.duration)
    write_outputs(summary, h, Path(args.out), plots=not args.no_plots)
    print(format_summary(summary))
    print(f"wrote {Path(args.out) / 'summary.json'}")
    return 0 if summary["completed"] else 1


def format_summary(s: dict) -> str:
    def f(x, fmt="{:.2f}"):
        return "n/a" if x is None else fmt.format(x)
    a = s["allocator"]
    return "\n".join([
        f"{s['scenario']} (seed {s['seed']}): {'completed' if s['completed'] else 'NOT completed'} "
        f"({s['end_reason']}) at t = {s['t_end_s']:.1f} s, {f(s.get('realtime_factor'), '{:.0f}')}x real time",
        f"  bank error: max after fault {f(s['bank_err_max_after_fault_deg'])} deg, RMS {f(s['bank_err_rms_deg'])} deg,"
        f" settle after reconfiguration {f(s['settle_time_after_reconfig_s'])} s",
        f"  alpha dev max {f(s['alpha_dev_max_deg'])} deg, beta dev max {f(s['beta_dev_max_deg'])} deg",
        f"  propellant {s['propellant_kg']:.2f} kg, {s['jet_pulses']} pulses, effort cmd {s['control_effort_cmd']:.3g}"
        f" applied {s['control_effort_applied']:.3g}",
        f"  allocator: {a['solves']} solves, p50 {f(a['p50_us'], '{:.1f}')} us, p99 {f(a['p99_us'], '{:.1f}')} us,"
        f" degraded {a['degraded']}, optimality gap {f(a['optimality_gap_max'], '{:.2g}')}",
        f"  FDIR: {len(s['fdir']['detections'])} detections, {s['fdir']['false_alarms']} false alarms,"
        f" missed {s['fdir']['missed']}; cycle slips {s['cycle_slips']}",
    ])
