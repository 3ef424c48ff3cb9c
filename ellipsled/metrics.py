"""Figures of merit of one run (docs/scenarios.md), from its History alone.

Pure functions: the batch runner and the SIL launcher call the same code, so a lockstep
SIL run and a batch run of the same seed produce the same summary.json figures.
"""
from __future__ import annotations

import math

import numpy as np

from .sil.history import History

SETTLE_BAND_DEG = 1.0     # |e_phi| below this counts as settled
SETTLE_HOLD_S = 2.0       # ... and must stay below it this long
FINE_BAND_DEG = 0.2       # the tighter band a fault-tolerance claim is judged by (docs/scenarios.md)
TRANSIENT_S = 10.0        # the initial bank error's decay is over by then (bank_err_max_after_transient_deg)
RECOVERED_FRAC = 0.1      # recovered: the fault-attributable error back within this fraction of its peak
RECOVERY_WINDOW_S = 5.0   # ... the peak of the fault's own transient: within this long after reconfiguration
RECOVERY_FLOOR_DEG = 0.01 # a peak below this is nothing to recover from
THETA_NAMES = ("I11", "I22", "I33", "I12", "I13", "I23", "d_roll", "d_pitch", "d_yaw")


def wrap_deg(x: np.ndarray) -> np.ndarray:
    return (x + 180.0) % 360.0 - 180.0


def bank_error_deg(h: History) -> np.ndarray:
    return wrap_deg(np.degrees(h["bank_rad"] - h["bank_ref_rad"]))


def settle_time(t: np.ndarray, err_deg: np.ndarray, t0: float, band_deg: float = SETTLE_BAND_DEG) -> float | None:
    """Seconds after t0 until |err| enters the band and stays there SETTLE_HOLD_S."""
    idx = np.nonzero(t >= t0)[0]
    if len(idx) == 0:
        return None
    dt = t[1] - t[0] if len(t) > 1 else 0.02
    hold = max(1, int(round(SETTLE_HOLD_S / dt)))
    inside = np.abs(err_deg[idx]) < band_deg
    run = 0
    for j, ok in enumerate(inside):
        run = run + 1 if ok else 0
        if run >= hold:
            return float(t[idx[j - hold + 1]] - t0)
    return None


def fault_attributable_error_deg(case: History, ref: History) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], e_case - e_ref [deg]) on the control steps both runs flew, aligned on the
    step index k: the part of the bank error the faults caused, e_ref being the same
    scenario, seed and reference flown without faults (docs/scenarios.md)."""
    kc, kr = case["k"], ref["k"]
    common = np.intersect1d(kc, kr)
    ic, ir = np.searchsorted(kc, common), np.searchsorted(kr, common)
    d = wrap_deg(bank_error_deg(case)[ic] - bank_error_deg(ref)[ir])
    return case["t_s"][ic], d


def fault_attributable_max_deg(case: History, ref: History, t_fault_s: float) -> float | None:
    """max over t >= t_fault of |e_case(t) - e_ref(t)| [deg]; None if no common step follows the fault."""
    t, d = fault_attributable_error_deg(case, ref)
    m = t >= t_fault_s - 1e-9
    return float(np.max(np.abs(d[m]))) if np.any(m) else None


def recovery_time(t: np.ndarray, d: np.ndarray, t_fault: float, t_reconfig: float) -> float | None:
    """Seconds from reconfiguration until the fault-attributable error ``d`` first falls back
    within RECOVERED_FRAC of its peak, the peak taken over [t_fault, t_reconfig +
    RECOVERY_WINDOW_S] (the fault's own transient, not a later reversal): the paper's "time
    for the error to reduce to zero" (6.4). 0 if that peak is below RECOVERY_FLOOR_DEG; None if
    the error never comes back."""
    w = np.nonzero((t >= t_fault - 1e-9) & (t <= t_reconfig + RECOVERY_WINDOW_S))[0]
    if not len(w):
        return None
    ip = w[int(np.argmax(np.abs(d[w])))]
    peak = abs(float(d[ip]))
    if peak < RECOVERY_FLOOR_DEG:
        return 0.0
    after = np.nonzero((np.arange(len(t)) >= ip) & (t >= t_reconfig) & (np.abs(d) <= RECOVERED_FRAC * peak))[0]
    return float(t[after[0]] - t_reconfig) if len(after) else None


def _window_max(t: np.ndarray, y: np.ndarray, t0: float, t1: float) -> float | None:
    m = (t >= t0) & (t < t1)
    return round(float(np.max(np.abs(y[m]))), 2) if np.any(m) else None


def reversal_errors(h: History, schedule_t: list[float], window_s: float = 40.0,
                    ref: History | None = None) -> list[dict]:
    """Max |e_phi| in the window after each scheduled bank step (the reversals), at 0.01 deg
    resolution; with ``ref`` (the fault-free twin) also the fault-attributable max there."""
    t, e = h["t_s"], bank_error_deg(h)
    ta, da = fault_attributable_error_deg(h, ref) if ref is not None else (None, None)
    out = []
    for ts in schedule_t[1:]:
        m = _window_max(t, e, ts, ts + window_s)
        if m is not None:
            r = {"t_s": ts, "bank_err_max_deg": m}
            if ref is not None:
                r["bank_err_fault_attrib_max_deg"] = _window_max(ta, da, ts, ts + window_s)
            out.append(r)
    return out


def _integral(t: np.ndarray, y2: np.ndarray) -> float:
    if len(t) < 2:
        return 0.0
    return float(np.sum(y2[:-1] * np.diff(t)))   # zero-order hold over each period


def effort(h: History) -> dict:
    """Control effort: applied ∫τᵀτ dt (the jets' torque on the truth: the figure of merit),
    commanded ∫u_calᵀu_cal dt beside it, and the undeliverable share ∫|u_cal - τ_alloc|² dt /
    ∫|u_cal|² dt: the part of the demand the allocator could not give with the jets it had."""
    t, u = h["t_s"], h["u_cal_B"]
    cmd = _integral(t, np.sum(u ** 2, axis=1))
    applied = _integral(t, np.sum(h["tau_jets_B"] ** 2, axis=1))
    miss = _integral(t, np.sum((u - h["tau_alloc_B"]) ** 2, axis=1))
    return {"control_effort_applied": applied, "control_effort_cmd": cmd,
            "control_effort_undeliverable_share": (miss / cmd) if cmd > 0 else None}


def adaptive_vs_truth(th: np.ndarray, truth: np.ndarray | None) -> dict:
    """Final estimate vs truth per element, relative error, and drift (relative change over
    the last 20 % of the run) per element."""
    n = len(th)
    if n == 0:
        return {}
    i0 = int(0.8 * n)
    base = np.where(np.abs(th[i0]) > 1e-12, np.abs(th[i0]), 1.0)
    drift = np.abs(th[-1] - th[i0]) / base
    out = {"names": list(THETA_NAMES), "final": th[-1].tolist(), "drift_last20pct": drift.tolist()}
    if truth is not None:
        tr = np.asarray(truth, dtype=float)
        scale = np.where(np.abs(tr) > 1e-12, np.abs(tr), 1.0)
        out["truth"] = tr.tolist()
        out["rel_err"] = ((th[-1] - tr) / scale).tolist()
    return out


def summarize(h: History, *, scenario: str, seed: int, end_reason: str, completed: bool,
              fault_t_s: float | None, reconfig_t_s: float | None, alpha_trim_rad: float,
              schedule_t: list[float], extra: dict, ref: History | None = None,
              theta_truth: np.ndarray | None = None) -> dict:
    """The summary.json dictionary. ``extra`` carries what only the FSW knows
    (allocator statistics, FDIR detections, propellant, pulses, cycle slips). ``ref`` is the
    same scenario and seed flown without faults (None: fault-attributable figures not computed);
    ``theta_truth`` the true values of the adaptive parameters."""
    t = h["t_s"]
    e = bank_error_deg(h)
    t_fault = fault_t_s if fault_t_s is not None else 2.5   # the paper's fault time, for nominal runs too
    after = t >= t_fault
    th = h["theta_hat"]
    n = len(t)
    adaptive = adaptive_vs_truth(th, theta_truth)
    drift = float(max(adaptive["drift_last20pct"])) if n > 10 else None
    t_recfg = reconfig_t_s if reconfig_t_s is not None else t_fault
    settle = settle_time(t, e, t_recfg)
    late = t >= TRANSIENT_S
    attrib = settle_attrib = recovery = t_attrib_max = None
    if ref is not None:
        attrib = fault_attributable_max_deg(h, ref, t_fault)
        ta, da = fault_attributable_error_deg(h, ref)
        settle_attrib = settle_time(ta, da, t_recfg, FINE_BAND_DEG)
        recovery = recovery_time(ta, da, t_fault, t_recfg)
        m = ta >= t_fault - 1e-9
        if np.any(m):
            i_max = np.nonzero(m)[0][int(np.argmax(np.abs(da[m])))]
            t_attrib_max = float(ta[i_max])
    s = {
        "scenario": scenario,
        "seed": seed,
        "completed": completed,
        "end_reason": end_reason,
        "t_end_s": float(t[-1]) if n else 0.0,
        "bank_err_max_after_fault_deg": float(np.max(np.abs(e[after]))) if np.any(after) else None,
        "bank_err_rms_deg": float(np.sqrt(np.mean(e ** 2))) if n else None,
        "bank_err_fault_attrib_max_deg": attrib,
        "bank_err_fault_attrib_t_max_s": t_attrib_max,
        "bank_err_max_after_transient_deg": float(np.max(np.abs(e[late]))) if np.any(late) else None,
        "bank_err_rms_after_transient_deg": float(np.sqrt(np.mean(e[late] ** 2))) if np.any(late) else None,
        "settle_time_after_reconfig_s": settle,
        "settle_time_0p2deg_s": settle_time(t, e, t_recfg, FINE_BAND_DEG),
        "settle_time_fault_attrib_0p2deg_s": settle_attrib,
        "recovery_time_fault_attrib_s": recovery,
        "fault_t_s": fault_t_s,
        "reconfig_t_s": reconfig_t_s,
        "alpha_dev_max_deg": float(np.max(np.abs(np.degrees(h["alpha_rad"] - alpha_trim_rad)))) if n else None,
        "beta_dev_max_deg": float(np.max(np.abs(np.degrees(h["beta_rad"])))) if n else None,
        # the same after the initial 5-degree transient (the paper's set-up): what the faults
        # and their handling cause, not the start-up transient every run shares
        "alpha_dev_max_after_transient_deg": (float(np.max(np.abs(np.degrees(h["alpha_rad"][late] - alpha_trim_rad))))
                                              if np.any(late) else None),
        "beta_dev_max_after_transient_deg": (float(np.max(np.abs(np.degrees(h["beta_rad"][late]))))
                                             if np.any(late) else None),
        "omega_err_max_degps": None,
        **effort(h),
        "reversals": reversal_errors(h, schedule_t, ref=ref),
        "adaptive_param_drift_last20pct": drift,
        "theta_hat_final": th[-1].tolist() if n else None,
        "adaptive": adaptive,
        "h_end_m": float(h["h_m"][-1]) if n else None,
        "mach_end": float(h["mach"][-1]) if n else None,
        "qbar_max_pa": float(np.max(h["qbar_pa"])) if n else None,
        "nonfinite": bool(n and not np.all(np.isfinite(h["bank_rad"]))),
    }
    s.update(extra)
    return _finite_json(s)


SUTTON_GRAVES_MARS = 1.9027e-4     # q = k sqrt(rho / R_n) V^3 [SI] (docs/fsw/entry-guidance.md)


def deploy_figures(h: History, *, target_lat_rad: float, target_lon_rad: float, radius_m: float,
                   nose_radius_m: float, entry_altitude_m: float) -> dict:
    """Figures of a guided entry (docs/fsw/entry-guidance.md), from the truth in the history:
    the miss at the last row (the deploy trigger) as a great-circle distance and split along
    and across the vehicle's heading there (downrange positive beyond the target,
    crossrange positive to the right), peak load factor, peak Sutton-Graves heat rate, and
    skip (gamma positive while above the entry altitude minus 10 km)."""
    n = len(h["t_s"])
    if not n:
        return {}
    lat, lon = float(h["lat_rad"][-1]), float(h["lon_rad"][-1])
    p = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    q = np.array([math.cos(target_lat_rad) * math.cos(target_lon_rad),
                  math.cos(target_lat_rad) * math.sin(target_lon_rad), math.sin(target_lat_rad)])
    miss = math.atan2(float(np.linalg.norm(np.cross(p, q))), float(p @ q)) * radius_m
    # target -> vehicle in the vehicle's local plane (north, east), against its heading
    east = np.array([-math.sin(lon), math.cos(lon), 0.0])
    north = np.cross(p, east)
    d = p - q
    dn, de = float(d @ north) * radius_m, float(d @ east) * radius_m
    psi = float(h["psi_rad"][-1])
    down = dn * math.cos(psi) + de * math.sin(psi)
    cross = -dn * math.sin(psi) + de * math.cos(psi)
    V = h["V_rel_mps"]
    rho = 2.0 * h["qbar_pa"] / np.maximum(V, 1e-6) ** 2
    heat = SUTTON_GRAVES_MARS * np.sqrt(rho / nose_radius_m) * V ** 3 / 1e4
    high = h["h_m"] > entry_altitude_m - 10_000.0
    return {
        "deploy_miss_km": miss / 1e3,
        "deploy_alt_km": float(h["h_m"][-1]) / 1e3,
        "downrange_err_km": down / 1e3,
        "crossrange_err_km": cross / 1e3,
        "peak_heat_rate_wcm2": float(np.max(heat)),
        "peak_load_g": float(np.max(h["decel_g"])),
        "skip": bool(np.any(high & (h["gamma_rad"] > 0.0))),
        "gamma_positive_max_alt_km": (float(np.max(h["h_m"][h["gamma_rad"] > 0.0])) / 1e3
                                      if np.any(h["gamma_rad"] > 0.0) else None),
    }


def _finite_json(x):
    """NaN/inf are not JSON: turn them into None so summary.json stays valid."""
    if isinstance(x, dict):
        return {k: _finite_json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite_json(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
