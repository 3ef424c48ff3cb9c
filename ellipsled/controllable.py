"""Could a perfect controller fly this run? The FSW's controllability LP asked with the truth.

The same program the FSW runs at every reconfiguration (fsw/controllability.py), given what
only the simulation knows: the faults the plant applied (its fault log, with the scenario's
thrust factors), the truth inertia and aerodynamic derivatives, and the truth dynamic pressure
of the flight. The trim is judged at the lowest dynamic pressure flown after the fault (where a
bias the jets cannot cancel needs the largest alpha/beta offset), the authority against what the
bank schedule still needs after the fault (a guided entry: at least what a turn from lift down
to lift up needs, fsw/controllability.py ``guided_accel_need_radps2``); the weaker way's trim is
sought as far as it is worth, without the FSW's ceiling of what its reference can use (a perfect
controller uses all that the jets and a trim give). A run labelled not
controllable is out of reach of any controller of these jets; the campaign reports success over all runs and over the others.
"""
from __future__ import annotations

import math

import numpy as np

from common.model import Scenario, inertia_matrix, inertia_vector
from fsw.controllability import (aero_moment_per_rad, controllability, guided_accel_need_radps2,
                                 schedule_accel_need_radps2, velocity_dir_B)
from fsw.health import JetHealth
from interfaces.vocabulary import FAULT_HEALTH


def truth_health(scn: Scenario, faults_applied: list) -> JetHealth:
    """The jets' true state at the end of the run: the scenario's fault events the plant applied
    ((t_s, jet, kind) in its fault log), in order."""
    applied = {(int(j), k) for _, j, k in faults_applied}
    h = JetHealth()
    for ev in sorted(scn.faults, key=lambda e: e.t_s):
        for j in ev.jets:
            if (int(j), ev.kind) in applied:
                h.set(int(j), FAULT_HEALTH[ev.kind], ev.eta)
    return h


def truth_controllability(scn: Scenario, faults_applied: list, t_s: np.ndarray, qbar_pa: np.ndarray,
                          trim_max_deg: float) -> dict:
    """The label as plain JSON values (degrees, deg/s^2, N m; None for "no trim exists")."""
    if not faults_applied:
        return {"controllable": True, "reason": ""}
    veh, tr = scn.vehicle, scn.truth
    t_fault = min(t for t, _, _ in faults_applied)
    after = np.asarray(t_s) >= t_fault
    q = float(np.min(np.asarray(qbar_pa)[after])) if np.any(after) else 0.0
    a = veh.aero
    A = aero_moment_per_rad(q, veh.S_ref_m2, veh.l_ref_m, a.C_lbeta * tr.C_lbeta_scale,
                            a.C_malpha * tr.C_malpha_scale, a.C_nbeta * tr.C_nbeta_scale)
    I_truth = inertia_matrix(inertia_vector(veh.inertia_kgm2) * tr.inertia_scale)
    need = max(schedule_accel_need_radps2(scn.bank_schedule, t_fault), guided_accel_need_radps2(scn.guidance_mode))
    r = controllability(veh.torque_matrix_Nm, truth_health(scn, faults_applied), I_truth,
                        velocity_dir_B(a.alpha_trim_rad), A, trim_max_deg, need, q)

    def num(x):
        return float(x) if math.isfinite(x) else None
    return {"controllable": r.controllable, "reason": r.reason,
            "authority_pos_degps2": math.degrees(r.authority_pos_radps2),
            "authority_neg_degps2": math.degrees(r.authority_neg_radps2),
            "need_degps2": math.degrees(need), "bias_Nm": r.bias_Nm, "residual_Nm": num(r.residual_Nm),
            "trim_needed_deg": num(r.trim_needed_deg), "qbar_min_pa": q}
