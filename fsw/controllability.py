"""What the jets can still do: a duty-cycle linear program over the jets FDIR holds usable.

Averaged over many control cycles an on/off jet acts as its duty cycle d_j in [0, 1], so the
torques the jets can hold on average form the polytope {b + sum_j eta_j T_j d_j}: failed and
inhibited jets are absent, degraded jets scale their column by eta_j, stuck-on jets are fixed
at d = 1 and form the bias b. Three questions are asked of it, each a small LP (HiGHS):

1. Trim. The smallest aerodynamic trim offset theta = (delta_alpha, beta) [rad] such that
   the jets and the aerodynamic moment cancel the bias on average:
       min s   s.t.  C d + A theta = -b,  |theta_i| <= s,  0 <= d <= 1,
   A [N m/rad] the static moment per radian of alpha offset and of sideslip
   (M = qbar S l (C_lbeta beta, C_malpha dalpha, C_nbeta beta), docs/fsw/index.md eqs 4-6).
   s = 0 when the jets alone cancel b; no solution (the bias outside what the jets and the
   aerodynamics can cancel) means no trim exists at this dynamic pressure.
2. Bank authority, each way. The largest average angular acceleration a about the velocity
   vector v (the bank axis) with the acceleration about the two axes normal to v held at zero
   on average (I omega_dot = tau with omega_dot = a v; the gyroscopic omega x I omega is second
   order at bank rates of a few deg/s and is neglected):
       C d + A theta - I v a = -b,  0 <= d <= 1.
   The trim theta is one offset held through a manoeuvre either way (a constant aerodynamic
   moment, not a control), within ``trim_max_deg`` whenever there is a stuck-on bias (none:
   zero, the guidance flies beta_r = 0). Once the jets alone cannot cancel the bias, the trim
   that maximises the weaker way (max t, a+ >= t, -a- >= t); while they can, the trim that
   maximises t - TRIM_WORTH sum |theta_i| with t at most ``weak_enough_radps2`` (what the
   reference can use): none when the jets alone give that, or when a trim buys next to nothing
   (a dynamic pressure near zero). (A trim allowed only once the jets cannot cancel the bias made
   the weaker way jump by two orders of magnitude across that edge: jets that cancel the bias at
   full duty leave the other way nothing, and a trim of a degree gives it back.) Each way's own
   maximum is then solved with that trim held.
3. The verdict: controllable when a trim exists within ``trim_max_deg`` and both authorities
   are above zero and reach ``authority_min_radps2`` (``schedule_accel_need_radps2``: what the
   bank schedule still needs; for a guided entry at least ``guided_accel_need_radps2``); else
   the reason.

Inputs are plain arrays, so the FSW (its nominal inertia estimate, its own density and
derivatives, its FDIR health) and the Monte Carlo (the plant's true inertia, aerodynamics and
fault list) ask the same program.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from interfaces.event_catalogue import EV

from .guidance.reference import _S2_MAX
from .health import STUCK_ON, JetHealth
from .lp import set_colwise_matrix, solve_or_none

# HiGHS feasibility tolerance on the torque rows [N m]: far below one jet's torque
_TOL_NM = 1e-7
# A trim the LP returns below this [rad] is no offset to fly (HiGHS's round-off of zero)
_TRIM_ZERO_RAD = 1e-9
# While the jets alone cancel a stuck-on bias, a trim is flown only where each radian of it buys
# the weaker way at least this much bank acceleration [rad/s^2 per rad]: a guided entry's need
# (GUIDED_TURN_S) over the default trim limit (5 deg) is 0.018. A trim at a dynamic pressure near
# zero buys next to nothing and is not worth its offset; at a few kPa a degree can buy
# deg/s^2 (module docstring, item 2)
TRIM_WORTH = 0.02
# The trim is an offset in a linear moment model about trim: an answer beyond a right angle is no
# attitude the vehicle can fly (it appears when the dynamic pressure is near 0 and A -> 0)
TRIM_PHYSICAL_DEG = 90.0


@dataclass(frozen=True)
class Controllability:
    """The LP's answer (angles in degrees, accelerations in rad/s^2)."""
    authority_pos_radps2: float    # bank acceleration available, positive way
    authority_neg_radps2: float    # ... negative way (a magnitude, >= 0)
    bias_B_Nm: tuple               # net stuck-on torque b in body axes [N m]
    residual_Nm: float             # |A theta*|: the part of b the jets cannot cancel, left to the aerodynamics
    trim_alpha_deg: float          # trim offset theta* (inf when no trim exists)
    trim_beta_deg: float
    trim_needed_deg: float         # max(|dalpha|, |beta|) of the smallest trim (inf when none exists)
    qbar_pa: float                 # dynamic pressure the trim was computed at
    controllable: bool
    reason: str                    # "" when controllable
    solve_s: float                 # wall time of the LPs

    @property
    def bias_Nm(self) -> float:
        return float(np.linalg.norm(self.bias_B_Nm))

    def event_args(self) -> dict:
        """The arguments of its catalogue event (EV.CONTROLLABILITY): bank authority each way
        [deg/s^2], stuck-on bias [N m], trim needed [deg] as text (INF, >90 or the value)."""
        tr = ("INF" if not math.isfinite(self.trim_needed_deg) else
              f">{TRIM_PHYSICAL_DEG:.0f}" if self.trim_needed_deg > TRIM_PHYSICAL_DEG else
              f"{self.trim_needed_deg:.1f}")
        return {"auth_pos": math.degrees(self.authority_pos_radps2), "auth_neg": math.degrees(self.authority_neg_radps2),
                "bias_Nm": self.bias_Nm, "trim": tr}

    def text(self) -> str:
        """Its event line as the catalogue renders it (<= 50 characters, one STATUSTEXT)."""
        return EV.CONTROLLABILITY.render(self.event_args())[1]


# A guided entry turns the bank wherever its range and its deploy altitude need it, lift down to
# lift up included; an authority that cannot turn the bank through 180 deg, rest to rest, within
# this time [s] cannot serve it (docs/decisions.md)
GUIDED_TURN_S = 90.0


def guided_accel_need_radps2(guidance_mode: str) -> float:
    """The bank acceleration [rad/s^2] a guided entry (guidance mode npc) needs each way: a
    rest-to-rest turn through 180 deg within GUIDED_TURN_S, 4 pi / T^2 (triangular rate). 0 for
    the paper's schedules (mode profile), whose need is the schedule's
    (``schedule_accel_need_radps2``)."""
    return 4.0 * math.pi / GUIDED_TURN_S ** 2 if guidance_mode == "npc" else 0.0


def schedule_accel_need_radps2(schedule, t_from_s: float) -> float:
    """The bank acceleration [rad/s^2] a minimum-jerk reference needs to fly every step of the
    schedule ((t_s, bank_rad) pairs) not yet finished at ``t_from_s`` before the next step is due
    (the last step: within the interval before it): max_k (10/sqrt 3) |dphi_k| / gap_k^2
    (guidance.reference.BankProfile's transition). 0 when no step remains. A perfect controller needs no
    more than this; the guidance keeps a margin on top (flightsoftware.FlightSoftware)."""
    t = [float(x[0]) for x in schedule]
    phi = [float(x[1]) for x in schedule]
    need = 0.0
    for k in range(1, len(t)):
        gap = (t[k + 1] - t[k]) if k + 1 < len(t) else (t[k] - t[k - 1])
        if t[k] + gap > t_from_s and phi[k] != phi[k - 1]:
            need = max(need, _S2_MAX * abs(phi[k] - phi[k - 1]) / gap ** 2)
    return need


def aero_moment_per_rad(qbar_pa: float, S_ref_m2: float, l_ref_m: float, C_lbeta: float, C_malpha: float,
                        C_nbeta: float) -> np.ndarray:
    """A (3x2) [N m/rad]: body moment per radian of alpha offset (column 0) and of sideslip
    (column 1), the static part of the paper's eqs 4-6."""
    q = qbar_pa * S_ref_m2 * l_ref_m
    return np.array([[0.0, q * C_lbeta], [q * C_malpha, 0.0], [0.0, q * C_nbeta]])


def velocity_dir_B(alpha_rad: float, beta_rad: float = 0.0) -> np.ndarray:
    """Unit velocity direction in body axes for C_BW = R2(alpha) R3(-beta) (common/frames.py)."""
    ca, sa, cb, sb = math.cos(alpha_rad), math.sin(alpha_rad), math.cos(beta_rad), math.sin(beta_rad)
    return np.array([ca * cb, sb, sa * cb])


def _lp(cost, M, row_lo, row_hi, lo, hi):
    """min cost.x s.t. row_lo <= M x <= row_hi, lo <= x <= hi; x, or None when infeasible."""
    import highspy
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", 1)
    h.setOptionValue("primal_feasibility_tolerance", _TOL_NM)
    lp = highspy.HighsLp()
    n = M.shape[1]
    lp.num_col_ = n
    lp.num_row_ = M.shape[0]
    lp.col_cost_ = np.asarray(cost, float)
    lp.col_lower_ = np.asarray(lo, float)
    lp.col_upper_ = np.asarray(hi, float)
    lp.row_lower_ = np.asarray(row_lo, float)
    lp.row_upper_ = np.asarray(row_hi, float)
    set_colwise_matrix(lp, M)
    return solve_or_none(h, lp)


def jet_columns(T_Nm: np.ndarray, health: JetHealth) -> tuple[np.ndarray, np.ndarray]:
    """(C, b): the usable jets' average-torque columns eta_j T_j (3 x p) and the stuck-on bias (3)."""
    T = np.asarray(T_Nm, float)
    usable = health.usable()
    C = T[:, usable] * health.effective_eta()[usable]
    b = T[:, health.state == STUCK_ON].sum(axis=1)
    return C, b


def inertia_corners(I_B: np.ndarray, v_B: np.ndarray, unc_frac: float) -> np.ndarray:
    """(K x 3) torques per unit bank acceleration, I v, for every inertia the FSW cannot tell
    from its estimate: each element I_ij within (1 +- unc_frac) I_ij. The set of I v is a
    zonotope; its bounding box's corners (8, or the one point I v when unc_frac is 0) hold it,
    and the bank authority is smallest at one of them (module docstring, item 2)."""
    I = np.asarray(I_B, float)
    v = np.asarray(v_B, float)
    Iv = I @ v
    if unc_frac <= 0.0:
        return Iv[None, :]
    half = unc_frac * (np.abs(I) @ np.abs(v))
    return np.array([Iv + half * np.array(s) for s in
                     ((-1, -1, -1), (-1, -1, 1), (-1, 1, -1), (-1, 1, 1), (1, -1, -1), (1, -1, 1), (1, 1, -1), (1, 1, 1))])


def bank_authority(C: np.ndarray, rhs: np.ndarray, W: np.ndarray) -> list[float]:
    """[a+, a-]: the largest bank acceleration each way that every torque column W[k] (from
    ``inertia_corners``) allows: C d_k - W[k] a = rhs for each k, 0 <= d_k <= 1 (one duty-cycle
    set per inertia: the controller closes its loop on the true one). 0 when infeasible."""
    p, K = C.shape[1], W.shape[0]
    M = np.zeros((3 * K, K * p + 1))
    for k in range(K):
        M[3 * k:3 * k + 3, k * p:(k + 1) * p] = C
        M[3 * k:3 * k + 3, -1] = -W[k]
    r = np.tile(rhs, K)
    lo, hi = np.concatenate([np.zeros(K * p), [-math.inf]]), np.concatenate([np.ones(K * p), [math.inf]])
    out = [0.0, 0.0]
    for k, sg in enumerate((1.0, -1.0)):
        cost = np.zeros(K * p + 1)
        cost[-1] = -sg
        x = _lp(cost, M, r, r, lo, hi)
        out[k] = max(0.0, sg * float(x[-1])) if x is not None else 0.0
    return out


def _trim_distance(M: np.ndarray, rhs: np.ndarray, held: np.ndarray, extra_rows: int = 0) -> tuple:
    """Item 2's LP with u_i >= |theta_i - held_i| (two columns, four rows) and ``extra_rows`` zero
    rows after them: (matrix, row_lo, row_hi) for x = [d+, d-, dalpha, beta, a+, a-, t, u0, u1];
    the extra rows' bounds are the caller's to append."""
    n = M.shape[1]
    j = n - 5                            # first trim column
    Mc = np.zeros((M.shape[0] + 4 + extra_rows, n + 2))
    Mc[:M.shape[0], :n] = M
    for k, (i, sg) in enumerate(((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0))):   # +-(theta_i - held_i) - u_i <= 0
        Mc[M.shape[0] + k, j + i] = sg
        Mc[M.shape[0] + k, n + i] = -1.0
    row_lo = np.concatenate([rhs, [0.0, 0.0], np.full(4, -math.inf)])
    row_hi = np.concatenate([rhs, [math.inf, math.inf], [held[0], -held[0], held[1], -held[1]]])
    return Mc, row_lo, row_hi


def _worth_trim(M: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray, t_max: float,
                held: np.ndarray) -> np.ndarray | None:
    """Item 2 for a bias the jets alone cancel: max t - TRIM_WORTH * sum |theta_i - held_i| with
    t <= ``t_max``: a trim moves from the one flown only while each radian buys the weaker way at
    least TRIM_WORTH, and only up to ``t_max``. x as item 2's, or None when HiGHS finds none."""
    n = M.shape[1]
    Mc, row_lo, row_hi = _trim_distance(M, rhs, held)
    cost = np.zeros(n + 2)
    cost[n - 1] = -1.0
    cost[n:] = TRIM_WORTH
    hi_t = np.concatenate([hi, [math.inf, math.inf]])
    hi_t[n - 1] = t_max
    x = _lp(cost, Mc, row_lo, row_hi, np.concatenate([lo, [0.0, 0.0]]), hi_t)
    return None if x is None else x[:n]


def _closest_trim(M: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray, t_best: float,
                  held: np.ndarray) -> np.ndarray | None:
    """Item 2 again with the weaker way held at its best ``t_best``: of the trims that give it,
    the one closest (sum of |theta_i - held_i|) to the trim flown, so that a trim carried
    through the entry moves only as far as the flight condition makes it, never between equally
    good trims. x as item 2's, or None when HiGHS finds none (then item 2's own answer stands)."""
    n = M.shape[1]
    Mc, row_lo, row_hi = _trim_distance(M, rhs, held, extra_rows=1)
    Mc[-1, n - 1] = 1.0                  # t >= t_best, less HiGHS's tolerance
    t_floor = t_best - 1e-9 * max(1.0, abs(t_best))
    row_lo = np.concatenate([row_lo, [t_floor]])
    row_hi = np.concatenate([row_hi, [math.inf]])
    cost = np.zeros(n + 2)
    cost[n:] = 1.0
    x = _lp(cost, Mc, row_lo, row_hi, np.concatenate([lo, [0.0, 0.0]]), np.concatenate([hi, [math.inf, math.inf]]))
    return None if x is None else x[:n]


def controllability(T_Nm: np.ndarray, health: JetHealth, I_B: np.ndarray, v_B: np.ndarray, A_aero: np.ndarray,
                    trim_max_deg: float, authority_min_radps2: float, qbar_pa: float = float("nan"),
                    inertia_unc_frac: float = 0.0, held_trim_rad=None,
                    weak_enough_radps2: float = math.inf) -> Controllability:
    """The duty-cycle LP (module docstring) for one jet health and flight condition.

    ``T_Nm`` (3 x n) torque matrix, ``I_B`` (3x3) inertia [kg m^2], ``v_B`` velocity direction
    in body axes, ``A_aero`` (3x2) from ``aero_moment_per_rad`` (zeros: jets only);
    ``qbar_pa`` is only recorded. ``inertia_unc_frac``: the authority holds for every inertia
    within that fraction of ``I_B``, element by element (``inertia_corners``; 0: ``I_B`` is
    the truth). ``held_trim_rad`` (dalpha, beta): the trim flown now; of the trims that give the
    weaker way its best (item 2), the one closest to it is returned with its authority (the
    best trim turns with the flight condition: held unchanged, the offset is no longer the
    one that balances the bias, and the weaker way can fall to nothing while another trim
    within ``trim_max_deg`` still gives it); the held trim itself when no trim exists.
    ``weak_enough_radps2``: while the jets alone cancel the bias, no trim is sought for more
    weak-way authority than this (inf: as much as is worth a trim; module docstring, item 2)."""
    t0 = time.perf_counter()
    C, b = jet_columns(T_Nm, health)
    p = C.shape[1]
    A = np.asarray(A_aero, float)
    v = np.asarray(v_B, float)
    v = v / np.linalg.norm(v)
    Iv = np.asarray(I_B, float) @ v
    inf = math.inf
    # 1. the smallest trim: x = [d (p), dalpha, beta, s]; rows C d + A theta = -b
    if not np.any(b):
        theta, s_star = np.zeros(2), 0.0
    else:
        M = np.zeros((3 + 4, p + 3))
        M[:3, :p], M[:3, p:p + 2] = C, A
        for k, (i, sg) in enumerate(((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0))):   # +-theta_i - s <= 0
            M[3 + k, p + i] = sg
            M[3 + k, p + 2] = -1.0
        cost = np.zeros(p + 3)
        cost[p + 2] = 1.0
        lo = np.concatenate([np.zeros(p), [-inf, -inf, 0.0]])
        hi = np.concatenate([np.ones(p), [inf, inf, inf]])
        x = _lp(cost, M, np.concatenate([-b, np.full(4, -inf)]), np.concatenate([-b, np.zeros(4)]), lo, hi)
        if x is None:
            theta, s_star = np.full(2, inf), inf
        else:
            theta, s_star = x[p:p + 2], float(x[p + 2])
    residual = float(np.linalg.norm(A @ theta)) if math.isfinite(s_star) else inf
    trim_deg = math.degrees(s_star) if math.isfinite(s_star) else inf
    # 2. one trim theta held through a manoeuvre either way, chosen for the weaker way:
    #    x = [d+ (p), d- (p), dalpha, beta, a+, a-, t]; max t, a+ >= t, -a- >= t. The trim may use
    #    the whole allowed offset whenever there is a bias (none: beta_r = 0)
    auth = [0.0, 0.0]
    held = None if held_trim_rad is None else np.asarray(held_trim_rad, float)
    if math.isfinite(s_star):
        box = (max(s_star, math.radians(trim_max_deg)) * (1.0 + 1e-9) + 1e-12) if np.any(b) else 0.0
        M = np.zeros((8, 2 * p + 5))
        M[0:3, 0:p], M[3:6, p:2 * p] = C, C
        M[0:3, 2 * p:2 * p + 2] = M[3:6, 2 * p:2 * p + 2] = A
        M[0:3, 2 * p + 2] = -Iv
        M[3:6, 2 * p + 3] = -Iv
        M[6, 2 * p + 2], M[6, 2 * p + 4] = 1.0, -1.0
        M[7, 2 * p + 3], M[7, 2 * p + 4] = -1.0, -1.0
        cost = np.zeros(2 * p + 5)
        cost[-1] = -1.0
        lo = np.concatenate([np.zeros(2 * p), [-box, -box, -inf, -inf, -inf]])
        hi = np.concatenate([np.ones(2 * p), [box, box, inf, inf, inf]])
        rhs = np.concatenate([-b, -b])
        if s_star == 0.0 and np.any(b):
            # the jets alone cancel the bias: a trim only as far as it is worth (TRIM_WORTH) away
            # from the one flown (none: zero), for no more than what the reference can use
            x = _worth_trim(M, rhs, lo, hi, weak_enough_radps2, np.zeros(2) if held is None else held)
            if x is not None and held is None:      # HiGHS's round-off of no trim is no trim
                x[2 * p:2 * p + 2] = np.where(np.abs(x[2 * p:2 * p + 2]) <= _TRIM_ZERO_RAD, 0.0, x[2 * p:2 * p + 2])
        else:
            x = _lp(cost, M, np.concatenate([rhs, [0.0, 0.0]]), np.concatenate([rhs, [inf, inf]]), lo, hi)
            if x is not None and held is not None:
                x_near = _closest_trim(M, rhs, lo, hi, x[-1], held)
                x = x if x_near is None else x_near
        if x is not None:
            theta = x[2 * p:2 * p + 2]
            # 3. each way's own maximum with that trim held, for every inertia the FSW cannot
            #    tell from its estimate
            auth = bank_authority(C, -b - A @ theta, inertia_corners(I_B, v, inertia_unc_frac))
    if held is not None and (not math.isfinite(s_star) or x is None):    # no trim to move to: the one flown
        theta = held
        auth = bank_authority(C, -b - A @ theta, inertia_corners(I_B, v, inertia_unc_frac))
    if not math.isfinite(s_star):
        reason = (f"stuck-on bias {np.linalg.norm(b):.0f} N m beyond what the jets and the aerodynamics "
                  f"can cancel at qbar {qbar_pa:.0f} Pa")
    elif trim_deg > max(trim_max_deg, TRIM_PHYSICAL_DEG):
        reason = (f"no trim offset within {TRIM_PHYSICAL_DEG:.0f} deg absorbs the {residual:.0f} N m the jets cannot "
                  f"cancel at qbar {qbar_pa:.0f} Pa (limit {trim_max_deg:g} deg)")
    elif trim_deg > trim_max_deg:
        reason = f"trim offset {trim_deg:.1f} deg needed to absorb {residual:.0f} N m (limit {trim_max_deg:g} deg)"
    elif min(auth) < authority_min_radps2 or min(auth) <= _TOL_NM / float(np.linalg.norm(Iv)):
        # an authority within the LP's own tolerance of zero (the torque rows' tolerance over the
        # inertia about v) is zero: a bias that uses up one way's jets exactly leaves round-off there
        way = "+" if auth[0] < auth[1] else "-"
        reason = (f"bank authority {way}{math.degrees(min(auth)):.2f} deg/s2 below "
                  f"{math.degrees(authority_min_radps2):.2f} deg/s2")
    else:
        reason = ""
    return Controllability(
        authority_pos_radps2=auth[0], authority_neg_radps2=auth[1], bias_B_Nm=tuple(float(x) for x in b),
        residual_Nm=residual, trim_alpha_deg=math.degrees(theta[0]) if math.isfinite(theta[0]) else inf,
        trim_beta_deg=math.degrees(theta[1]) if math.isfinite(theta[1]) else inf, trim_needed_deg=trim_deg,
        qbar_pa=float(qbar_pa), controllable=not reason, reason=reason, solve_s=time.perf_counter() - t0)
