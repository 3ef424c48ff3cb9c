"""Figures of merit of one run (spec 30-scenarios.md), from its History alone.

Pure functions: the batch runner and the SIL launcher call the same code, so a lockstep
SIL run and a batch run of the same seed produce the same summary.json figures.
"""
from __future__ import annotations

import math

import numpy as np

from .history import History

SETTLE_BAND_DEG = 1.0     # |e_phi| below this counts as settled
SETTLE_HOLD_S = 2.0       # ... and must stay below it this long


def wrap_deg(x: np.ndarray) -> np.ndarray:
    return (x + 180.0) % 360.0 - 180.0


def bank_error_deg(h: History) -> np.ndarray:
    return wrap_deg(np.degrees(h["bank_rad"] - h["bank_ref_rad"]))


def settle_time(t: np.ndarray, err_deg: np.ndarray, t0: float) -> float | None:
    """Seconds after t0 until |err| enters the band and stays there SETTLE_HOLD_S."""
    idx = np.nonzero(t >= t0)[0]
    if len(idx) == 0:
        return None
    dt = t[1] - t[0] if len(t) > 1 else 0.02
    hold = max(1, int(round(SETTLE_HOLD_S / dt)))
    inside = np.abs(err_deg[idx]) < SETTLE_BAND_DEG
    run = 0
    for j, ok in enumerate(inside):
        run = run + 1 if ok else 0
        if run >= hold:
            return float(t[idx[j - hold + 1]] - t0)
    return None


def reversal_errors(h: History, schedule_t: list[float], window_s: float = 40.0) -> list[dict]:
    """Max |e_phi| in the window after each scheduled bank step (the reversals)."""
    t, e = h["t_s"], bank_error_deg(h)
    out = []
    for ts in schedule_t[1:]:
        m = (t >= ts) & (t < ts + window_s)
        if np.any(m):
            out.append({"t_s": ts, "bank_err_max_deg": float(np.max(np.abs(e[m])))})
    return out


def _integral(t: np.ndarray, y2: np.ndarray) -> float:
    if len(t) < 2:
        return 0.0
    return float(np.sum(y2[:-1] * np.diff(t)))   # zero-order hold over each period


def summarize(h: History, *, scenario: str, seed: int, end_reason: str, completed: bool,
              fault_t_s: float | None, reconfig_t_s: float | None, alpha_trim_rad: float,
              schedule_t: list[float], extra: dict) -> dict:
    """The summary.json dictionary. ``extra`` carries what only the FSW knows
    (allocator statistics, FDIR detections, propellant, pulses, cycle slips)."""
    t = h["t_s"]
    e = bank_error_deg(h)
    t_fault = fault_t_s if fault_t_s is not None else 2.5   # the paper's fault time, for nominal runs too
    after = t >= t_fault
    th = h["theta_hat"]
    n = len(t)
    drift = None
    if n > 10:
        i0 = int(0.8 * n)
        ref = np.where(np.abs(th[i0]) > 1e-12, np.abs(th[i0]), 1.0)
        drift = float(np.max(np.abs(th[-1] - th[i0]) / ref))
    settle = settle_time(t, e, reconfig_t_s if reconfig_t_s is not None else t_fault)
    s = {
        "scenario": scenario,
        "seed": seed,
        "completed": completed,
        "end_reason": end_reason,
        "t_end_s": float(t[-1]) if n else 0.0,
        "bank_err_max_after_fault_deg": float(np.max(np.abs(e[after]))) if np.any(after) else None,
        "bank_err_rms_deg": float(np.sqrt(np.mean(e ** 2))) if n else None,
        "settle_time_after_reconfig_s": settle,
        "fault_t_s": fault_t_s,
        "reconfig_t_s": reconfig_t_s,
        "alpha_dev_max_deg": float(np.max(np.abs(np.degrees(h["alpha_rad"] - alpha_trim_rad)))) if n else None,
        "beta_dev_max_deg": float(np.max(np.abs(np.degrees(h["beta_rad"])))) if n else None,
        "omega_err_max_degps": None,
        "control_effort_cmd": _integral(t, np.sum(h["u_cal_B"] ** 2, axis=1)),
        "control_effort_applied": _integral(t, np.sum(h["tau_jets_B"] ** 2, axis=1)),
        "reversals": reversal_errors(h, schedule_t),
        "adaptive_param_drift_last20pct": drift,
        "theta_hat_final": th[-1].tolist() if n else None,
        "h_end_m": float(h["h_m"][-1]) if n else None,
        "mach_end": float(h["mach"][-1]) if n else None,
        "qbar_max_pa": float(np.max(h["qbar_pa"])) if n else None,
        "nonfinite": bool(n and not np.all(np.isfinite(h["bank_rad"]))),
    }
    s.update(extra)
    return _finite_json(s)


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
