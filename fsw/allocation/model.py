"""The allocation problem (docs/fsw/index.md "Fault-tolerant discrete control allocation";
paper section 3): the model a jet-health configuration leaves, and the problem's checks.

Problem, per control cycle, for demand tau_d (3,) [N m]:

    minimise   sum_i w_i |tau_d,i - tau_i| + sum_k c_k u_k          (c_k = penalty_per_N * F_k)
    over       u in {0,1}^p  (usable jets: nominal, or degraded with column eta_k T_k)
    where      tau = b + sum_k eta_k T_k u_k,  b = sum_{stuck-on} T_k
    subject to min(0, tau_d,i) - e_i <= tau_i <= max(0, tau_d,i) + e_i

The box: e = 0 is the paper's sign box (every axis between zero and its demand: no torque
of the wrong sign, no overshoot). The spill box (e_i = allocator.spill_jets x the largest
single-jet torque of axis i) admits a bounded wrong-sign or overshooting torque, which the
vehicle's static aerodynamic stability (pitch, yaw) and the next cycles' feedback take
out: once failures remove the jet pairs that cancel exactly, every jet that still turns
the vehicle one way adds pitch or yaw (or a little roll), and the sign box then leaves
almost no torque that way, or none that cancels a stuck-on bias. The objective is the
same in both; spill costs its weighted error.

If no u satisfies the box (possible only with a stuck-on bias) the same objective is
minimised without it and the answer is flagged ``degraded``. Ties (objectives within the
tie tolerance) are broken by the smaller penalty sum, then by the smaller jet-bit pattern
sum_k u_k 2^(k-1) (jet 1 = bit 0). The constant penalty of stuck-on jets is not part of
the objective (it does not change the argmin).

Tolerances: a torque is inside the box if it overshoots a bound by at most TOL_BOX_NM;
two objectives tie if they differ by at most TOL_TIE + TIE_REL * sum_i w_i |tau_d,i| (the
relative term covers rounding of huge demands); two penalties tie within TOL_PEN.

Fault tolerance off (paper figure 5): the model assumes every jet nominal (usable,
eta = 1, nothing stuck, nothing inhibited) whatever the health says; the jet driver still
applies the ground inhibit mask.
"""
from __future__ import annotations

import numpy as np

from fsw.health import DEGRADED, STUCK_ON, JetHealth

N_AXES = 3
TOL_BOX_NM = 1e-9          # allowed overshoot of a sign-box bound [N m]
TOL_TIE = 1e-9             # absolute objective tie tolerance [N m]
TIE_REL = 32 * np.finfo(float).eps   # per unit of sum_i w_i |tau_d,i|: rounding of huge demands
TOL_PEN = 1e-9             # penalty tie tolerance [N m]


def spill_of(T: np.ndarray, spill_jets: float) -> np.ndarray:
    """The box's allowance e (3,) [N m]: spill_jets times the largest single-jet torque of
    each axis (0: the sign box)."""
    return float(spill_jets) * np.max(np.abs(np.asarray(T, dtype=float)), axis=1)



def effective_model(T: np.ndarray, thrust: np.ndarray, health: JetHealth | None,
                    penalty_per_N: float, fault_tolerance: bool = True):
    """The allocation model for a health configuration (docs/fsw/index.md):
    (usable bool[n], columns eta_k T_k (3, n) with zeros for unusable jets,
    stuck-on bias b (3,), per-jet penalty c (n,)). Health is ignored when fault
    tolerance is off or health is None."""
    T = np.asarray(T, dtype=float)
    thrust = np.asarray(thrust, dtype=float)
    n = T.shape[1]
    c = float(penalty_per_N) * thrust
    if not fault_tolerance or health is None:
        return np.ones(n, dtype=bool), T.copy(), np.zeros(N_AXES), c
    if len(health.state) != n:
        raise ValueError(f"health: {len(health.state)} jets, torque matrix has {n}")
    usable = health.usable()
    eta = np.where(health.state == DEGRADED, health.eta, 1.0)
    cols = np.where(usable[None, :], T * eta[None, :], 0.0)
    stuck = health.state == STUCK_ON
    b = T[:, stuck].sum(axis=1) if stuck.any() else np.zeros(N_AXES)
    return usable, cols, b, c


def validate_problem(T, thrust, w, penalty_per_N):
    """The problem data as float arrays and a float penalty; ValueError names the bad one."""
    T = np.asarray(T, dtype=float)
    thrust = np.asarray(thrust, dtype=float)
    if T.ndim != 2 or T.shape[0] != N_AXES or T.shape[1] > 62:
        raise ValueError(f"torque_matrix_Nm: expected shape (3, n<=62), got {T.shape}")
    if thrust.shape != (T.shape[1],):
        raise ValueError(f"thrust_N: expected shape ({T.shape[1]},), got {thrust.shape}")
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(thrust))):
        raise ValueError("torque_matrix_Nm/thrust_N: must be finite")
    if np.any(thrust < 0):
        raise ValueError("thrust_N: must be >= 0")
    w = np.asarray(w, dtype=float)
    if w.shape != (N_AXES,) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"w: expected 3 finite weights >= 0, got {w!r}")
    if not np.isscalar(penalty_per_N) or not np.isfinite(penalty_per_N) or penalty_per_N < 0:
        raise ValueError(f"c (penalty per N): expected a finite scalar >= 0, got {penalty_per_N!r}")
    return T, thrust, w, float(penalty_per_N)
