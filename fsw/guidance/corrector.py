"""The entry guidance's corrector (docs/fsw/entry-guidance.md): from a planet-fixed state, the bank
profile whose predicted deploy reaches the target.

- ``bank_profile``: the one-parameter family it searches (the line in energy from phi_0 to
  phi_f, a phi_0 bound held beyond it), with ``profile_span`` and ``profile_at``;
- ``solve_bank``: the root-finder, a safeguarded secant on the range miss z(phi_0);
- ``floor_bank``: the deploy-altitude floor's search, which trades range for altitude (after
  ``Corrector._lift_late``, which keeps the range and lifts up at the end, could not hold it);
- ``Corrector``: one correction (``solve``), its answer a ``Correction``.
"""
from __future__ import annotations

import math
import time
from typing import NotRequired, TypedDict

import numpy as np

from common.model import Scenario
from .geometry import central_angle, crossrange, unit_from_latlon
from .predictor import (C_H_FLOOR, C_KLD, C_KRHO, C_MACH_F, C_TGT, C_TRIG, GROUND, N_O, O_FLAG, O_H, O_H_BOX, O_R_TRIG,
                        O_T, O_XR_TRIG, REACHED, SKIPPED, TIMEOUT, deploy_energy, predict, predict_shaped,
                        predictor_constants)
from .shaper import reversal_other_way


def solve_bank(z, x_lo: float, x_hi: float, x0: float, tol: float, max_iter: int,
               dx0: float = math.radians(5.0)) -> tuple[float, float, int, bool]:
    """Root of a monotonic scalar function z on [x_lo, x_hi]: secant steps warm-started at
    x0; once two points of opposite sign are known, an iterate outside them is replaced by
    their midpoint (so it cannot diverge). Returns (x, z(x), evaluations, converged
    |z| <= tol). Without a root in the bounds the secant runs into a bound, tries the other
    bound once (no sign change there either: no root), and stops: the answer is then the
    point of smallest |z| seen, or of those within tol of it the one nearest x0 (converged
    False)."""
    pts: list[tuple[float, float]] = []

    def ev(x: float) -> float:
        zx = float(z(x))
        pts.append((x, zx))
        return zx

    x1 = min(max(x0, x_lo), x_hi)
    if abs(ev(x1)) <= tol:
        return x1, pts[0][1], 1, True
    ev(x1 + dx0 if x1 + dx0 <= x_hi else x1 - dx0)
    while len(pts) < max_iter:
        best = min(pts, key=lambda p: abs(p[1]))
        if abs(best[1]) <= tol:
            break
        (xa, za), (xb, zb) = pts[-2], pts[-1]
        xn = xb - zb * (xb - xa) / (zb - za) if zb != za else xb + dx0
        neg = [p[0] for p in pts if p[1] < 0.0]
        pos = [p[0] for p in pts if p[1] > 0.0]
        if neg and pos:
            a, b = min(((u, v) for u in neg for v in pos), key=lambda uv: abs(uv[0] - uv[1]))
            a, b = min(a, b), max(a, b)
            if not a < xn < b:
                xn = 0.5 * (a + b)
        else:
            xn = min(max(xn, x_lo), x_hi)
            if any(abs(xn - p[0]) < 1e-12 for p in pts):
                # pushed against a bound already tried: the other bound once, then no root
                # inside. Near a bound z can be flat to metres (a bound held for nearly all the
                # energy to go), and its slope there may point the secant the wrong way
                other = x_hi if xn == x_lo else x_lo if xn == x_hi else math.nan
                if math.isnan(other) or any(abs(other - p[0]) < 1e-12 for p in pts):
                    break
                xn = other
        ev(xn)
    best = min(pts, key=lambda p: abs(p[1]))
    if abs(best[1]) > tol:
        # no root: a point within tol of the smallest |z| is as good an answer, and the one
        # nearest the warm start (the profile flown) is taken. On a flat z (near the deploy,
        # or far beyond any reach) the bound the secant ran into differs by metres, and flying
        # it swings the bank across its range: lift down for a vehicle that is short
        best = min((p for p in pts if abs(p[1]) <= abs(best[1]) + tol), key=lambda p: abs(p[0] - x1))
    return best[0], best[1], len(pts), abs(best[1]) <= tol


HOLD_MAX = 1.0 - 1e-6    # bank_profile: a bound held to the deploy, within float reach


def bank_profile(p: float, lo: float, hi: float, f: float) -> tuple[float, float]:
    """The corrector's one-parameter family: (phi_0, phi_f) of the line in energy from the
    bank now to phi_f at the deploy energy, which the predictor clips to the phi_0 bounds
    [lo, hi]. Inside them phi_0 = p and phi_f = f. Beyond a bound (p up to profile_span's)
    the family goes on with the bound held for the fraction k = (p - hi) / (hi - f) of the
    energy to go (resp. (lo - p) / (f - lo)) and the line to f after it: phi_0 is then the
    line's start above hi (below lo) that reaches the bound at k; k = 1 holds it to the end.

    Why a held bound and not phi_0 pinned at it: the bank commanded is the profile's now,
    and the next cycle re-anchors the profile at its own energy. A profile "from hi now to f
    at the deploy" pinned at hi is re-anchored at hi every cycle and flown at hi to the end,
    while every prediction had the bank leave it: what was predicted is not what is flown.
    A held bound is a profile the next cycle finds again (the same line, clipped), so the
    predictions are the flight. Continuous at the bounds and monotonic in range as p is.
    All angles [rad]."""
    if p > hi and hi > f:
        k = min((p - hi) / (hi - f), HOLD_MAX)
        return (hi - f * k) / (1.0 - k), f
    if p < lo and f > lo:
        k = min((lo - p) / (f - lo), HOLD_MAX)
        return (lo - f * k) / (1.0 - k), f
    return p, f


def profile_span(lo: float, hi: float, f: float) -> tuple[float, float]:
    """The range of bank_profile's parameter: down to lo held to the end, up to hi held."""
    return lo - max(0.0, f - lo), hi + max(0.0, hi - f)


def profile_at(p: float, lo: float, hi: float, f: float, frac: float) -> float:
    """bank_profile(p)'s parameter re-anchored at the fraction frac of its energy span: the
    same profile from there on, as the next cycle's family writes it (its warm start: an
    answer still within tolerance is then the profile already flown, not a new one)."""
    b0, bf = bank_profile(p, lo, hi, f)
    b = b0 + (bf - b0) * min(1.0, max(0.0, frac))
    if b > hi and hi > f:
        return hi + (b - hi) / (b - bf) * (hi - f)
    if b < lo and f > lo:
        return lo - (lo - b) / (bf - b) * (f - lo)
    return b


FLOOR_STEP_RAD = math.radians(10.0)   # floor_bank's march down from the range solution
FLOOR_RES_RAD = math.radians(0.5)     # ... and its bisection's resolution


def floor_bank(deploy, h_floor_m: float, b_hi: float, h_hi_m: float, b_min: float, tol_m: float,
               max_iter: int, miss_max_m: float) -> tuple[float, int]:
    """(phi_0 [rad], predictions): the largest phi_0 below b_hi (whose prediction deploys at
    h_hi_m, below h_floor_m) whose predicted deploy altitude reaches h_floor_m, down to b_min.
    deploy(phi_0) flies the floor mode's profile (phi_0 held to the end when below phi_f) and
    returns (predicted deploy altitude [m], range miss [m]), the miss None when the
    prediction skips out or times out. The deploy altitude is not monotonic in phi_0 (a
    steeper dive also slows the vehicle higher up), so no secant: steps of FLOOR_STEP_RAD down
    to the first phi_0 that reaches the floor, then bisection between it and the last that
    did not (the crossing nearest the range solution, least range given up). A phi_0 that
    skips out or whose predicted miss exceeds miss_max_m is refused, and so is everything
    below it (more lift up flies further); without a crossing above the refused, the phi_0 of
    the highest deploy seen, and NaN when no phi_0 tried deploys higher than h_hi_m (then the
    range solution stays: the floor's profile from b_hi is another flight, not a trade; for
    a range solution that holds a phi_0 bound, the floor's line from that bound flies far
    long). The miss bound keeps the trade from running away: flown long, the next range
    solution needs more lift down, which deploys lower still."""
    b_bad, b_ok, b_lim, n = b_hi, math.nan, math.nan, 0
    best_b, best_h = b_hi, h_hi_m
    while n < max_iter:
        if not math.isnan(b_ok):
            b = 0.5 * (b_ok + b_bad)
        elif not math.isnan(b_lim):
            b = 0.5 * (b_lim + b_bad)
        else:
            b = max(b_min, b_bad - FLOOR_STEP_RAD)
        h, miss = deploy(b)
        n += 1
        if miss is None or abs(miss) > miss_max_m:
            b_lim = b
        elif h >= h_floor_m:
            b_ok = b
            if h - h_floor_m <= tol_m:
                break
        else:
            b_bad = b
            if h > best_h:
                best_b, best_h = b, h
        if not math.isnan(b_ok):
            if b_bad - b_ok < FLOOR_RES_RAD:
                break
        elif (not math.isnan(b_lim) and b_bad - b_lim < FLOOR_RES_RAD) or b <= b_min:
            break
    return (b_ok if not math.isnan(b_ok) else best_b if best_h > h_hi_m else math.nan), n


def range_reserve(scenario: Scenario, params: dict) -> float:
    """How far beyond the target the range solution aims its predicted deploy point [m]:
    npc.range_reserve_m when this flight software deploys by the range trigger, else 0.
    The range trigger deploys where the target comes abeam once inside the deploy box, so a
    vehicle that flies long by less than its stretch from the box entry to the deploy
    condition still deploys at the target; one that flies short goes on past the deploy
    condition, descending, until the trigger's altitude floor fires short of it. Aimed at the
    target, every error that shows late (a final reversal, a shift of the prediction, the
    lift-up late's range held at the edge of what lift up reaches) lands on the short side;
    aimed beyond it, the vehicle reaches the target higher and the same error is absorbed."""
    if scenario.deploy_by == "fsw" and params.get("deploy.trigger") == "range":
        return float(params["npc.range_reserve_m"])
    return 0.0


def trigger_reach_end(scenario: Scenario, params: dict) -> tuple[float, float] | None:
    """(Mach [-], altitude [m]) where the range trigger fires at the latest when the target is
    still ahead: the deploy box's Mach minimum plus deploy.mach_margin, and deploy.h_floor_m (or
    the box's altitude minimum plus deploy.h_margin_m, the higher). None: no range trigger, or a
    deploy condition that is a speed, not a Mach. The predictions end at the deploy condition
    (the scenario's end Mach), but the trigger flies on through the box until the target comes
    abeam: how far the vehicle reaches past that condition decides whether it still deploys on
    target (Corrector._reach)."""
    box = scenario.vehicle.deploy_box
    if (box is None or scenario.deploy_by != "fsw" or params.get("deploy.trigger") != "range"
            or scenario.end_speed_mps is not None):
        return None
    return (box.mach_min + float(params.get("deploy.mach_margin", 0.0)),
            max(float(params.get("deploy.h_floor_m", 0.0)), box.h_min_m + float(params.get("deploy.h_margin_m", 0.0))))


class Correction(TypedDict):
    """One answer of the corrector (Corrector.solve): the bank profile to fly from the
    state it answers, and what its prediction says of the deploy."""
    bank0_rad: float          # phi_0 commanded: the profile's bank now (the line clipped to the bounds)
    p_range_rad: float        # the range solution's parameter p (bank_profile): the next cycle's warm start ...
    f_family_rad: float       # ... and the family's phi_f it was solved with (lowered by a lift-up late)
    e0_jpkg: float            # energy mu/r - V^2/2 of the state answered: where the profile starts
    bank_line_rad: float      # the profile flown: phi_0 of its line ...
    bank_final_rad: float     # ... and its phi_f (the line clipped to the phi_0 bounds, as predicted)
    floor: bool               # the deploy-altitude floor traded range for altitude
    reach: bool               # the magnitude raised off the lift-up bound for the crossrange (_reach)
    held: bool                # the range solution holds a phi_0 bound (and no floor trade)
    miss_m: float             # predicted range miss, past the aim point (range_reserve beyond the target;
                              # NaN: the floor's profile does not reach the deploy)
    predictions: int          # predictor runs it took
    turn_rad: float           # the way round for the reversal under way, added to the command (NaN: kept)
    ok: bool                  # a range solution within tolerance, or a floor trade
    range_to_go_m: float      # great-circle range from the state answered to the target
    lat_rad: float            # predicted deploy point, planet-fixed
    lon_rad: float
    h_final_m: float          # predicted deploy altitude (at the deploy condition) ...
    h_box_m: float            # ... and where the deploy box is entered: the floor's (the highest deploy)
    t_go_s: float             # predicted time to deploy, from the state answered
    xr_keep_m: float          # predicted deploy crossrange (+ left; _deploy_crossrange), sign kept (NaN: not
                              # predicted) ...
    xr_rev_m: float           # ... and reversed t_flip from now (the range solved again for it)
    xr_keep_held_m: float     # the held pair: this answer's magnitude kept, sign kept ...
    xr_rev_held_m: float      # ... and reversed, in effect at once t_flip_held from now
    compute_ns: int           # the correction's wall time
    t_s: NotRequired[float]   # release time of the cycle it answers (added by the worker)
    sign: NotRequired[float]  # bank sign it was solved for (added by the worker)


class Corrector:
    """One correction from a planet-fixed state (``solve``): phi_0 of the family
    ``bank_profile`` by ``solve_bank`` on the predicted range miss, warm-started at the last
    answer's profile; a reversal under way turned round when the other way misses by less;
    the deploy-altitude floor (on the predicted box-entry altitude: first a lift-up late with the
    range kept, then a range trade); and the deploy crossranges for the lateral logic.
    ``params``: its own copy of the npc.* values, ``take_params`` applies new ones."""

    def __init__(self, scenario: Scenario, params: dict):
        if scenario.target_lat_rad is None:
            raise ValueError(f"{scenario.file}: target: guidance mode \"npc\" needs a [target]")
        self.scenario, self.params = scenario, dict(params)
        pl = scenario.planet
        self.constants = predictor_constants(scenario, params)     # the predictor's (indices C_*)
        self.mu_m3ps2, self.radius_m, self.omega_radps = pl.mu_m3ps2, pl.radius_m, pl.omega_radps
        self.scale_height_m = pl.scale_height_m
        self.e_deploy_jpkg = deploy_energy(scenario, params["npc.h_deploy_m"])
        self.bank_final_rad = math.radians(params["npc.bank_final_deg"])
        self.bank_min_rad = math.radians(params["npc.bank_min_deg"])
        self.bank_max_rad = math.radians(params["npc.bank_max_deg"])
        self.p_min_rad, self.p_max_rad = profile_span(self.bank_min_rad, self.bank_max_rad, self.bank_final_rad)
        self.target_u = unit_from_latlon(scenario.target_lat_rad, scenario.target_lon_rad)
        self.reserve_m = range_reserve(scenario, params)
        self.bank0 = abs(scenario.bank_schedule[0][1])   # the range solution's parameter p [rad]
                                         # (bank_profile: phi_0 within the bounds): the next warm start
        self.f_lift_rad = self.bank_final_rad   # the family's phi_f now: lowered by the floor's lift-up
                                         # late (_lift_late), kept lowered for the rest of the entry
        self._p_e0_jpkg = math.nan       # energy at which bank0's profile starts
        self._shp = None                 # the reference shaper's state the predictions start from
        self._out = np.zeros(N_O)
        self._c_reach = np.zeros_like(self.constants)   # _reach's: the prediction flown on to the box's edge ...
        self._out_reach = np.zeros(N_O)                  # ... and its output (self._out keeps the answer's)
        self._reach_end = trigger_reach_end(scenario, params)
        self.reach_rad = math.nan        # the last answer's lateral magnitude (_reach), NaN: none

    def take_params(self, names: set[str]) -> None:
        """Apply self.params (``names``: the ones just set) where the construction put them."""
        p, scn = self.params, self.scenario
        self.bank_final_rad = math.radians(p["npc.bank_final_deg"])
        self.bank_min_rad, self.bank_max_rad = math.radians(p["npc.bank_min_deg"]), math.radians(p["npc.bank_max_deg"])
        self.p_min_rad, self.p_max_rad = profile_span(self.bank_min_rad, self.bank_max_rad, self.bank_final_rad)
        self.f_lift_rad = min(self.f_lift_rad, self.bank_final_rad) if "npc.bank_final_deg" not in names \
            else self.bank_final_rad
        self.bank0 = min(self.p_max_rad, max(self.p_min_rad, self.bank0))      # the warm start within them
        if "npc.h_deploy_m" in names:
            self.e_deploy_jpkg = deploy_energy(scn, p["npc.h_deploy_m"])
        c = predictor_constants(scn, p)                 # path limits and their feedback
        c[C_KRHO], c[C_KLD] = self.constants[C_KRHO], self.constants[C_KLD]
        self.constants[:] = c

    def _z(self, x, e0, s_togo, sign, t_switch=0.0, f=None):
        """The corrector's miss function z(p) [m]: predicted range past the target (f: the
        family's phi_f, None: npc.bank_final_deg)."""
        out = self._out
        f = self.bank_final_rad if f is None else f

        def z(p):
            b0, bf = bank_profile(p, self.bank_min_rad, self.bank_max_rad, f)
            self._predict(x, b0, bf, e0, sign, out, t_switch)
            if out[O_FLAG] == SKIPPED or out[O_FLAG] == TIMEOUT:
                # out of the atmosphere: far long. Its range so far says little, so the miss
                # is made 1000 km plus a slope towards more bank: the corrector then walks
                # out of the skip region instead of stalling on a flat function
                return 1e6 + (self.p_max_rad - p) * 1e6
            return central_angle(x[:3], out[:3]) * self.radius_m - s_togo
        return z

    def _predict(self, x, b0, bf, e0, sign, out, t_switch=0.0, constants=None):
        """The corrector's prediction: from the reference shaper's state when one is given
        (the transition in progress flown within the attitude chain's limits; a reversal to
        ``sign`` commanded at t_switch > 0), else the law from the start (a reversal to ``sign``
        in effect at t_switch). ``constants``: the predictor's, None: self.constants."""
        c = self.constants if constants is None else constants
        if self._shp is None:
            predict(x, c, b0, bf, e0, self.e_deploy_jpkg, sign, self.params["npc.dt_pred_s"], out, float(t_switch))
        else:
            predict_shaped(x, c, b0, bf, e0, self.e_deploy_jpkg, sign, self.params["npc.dt_pred_s"],
                           out, self._shp, float(t_switch))

    def _floor_bank(self, x, e0, s_togo, sign, h_floor, b_hi, h_hi):
        """floor_bank over the floor mode's profile (phi_0 held to the end when below phi_f)."""
        out = self._out

        def deploy(b):
            self._predict(x, b, min(self.bank_final_rad, b), e0, sign, out)
            if out[O_FLAG] == SKIPPED or out[O_FLAG] == TIMEOUT:
                return out[O_H_BOX], None
            return out[O_H_BOX], central_angle(x[:3], out[:3]) * self.radius_m - s_togo
        return floor_bank(deploy, h_floor, b_hi, h_hi, self.bank_min_rad, self.params["npc.tol_m"],
                          int(self.params["npc.max_iter"]), self.params["npc.floor_miss_max_m"])

    LIFT_STEPS = 4                        # _lift_late's bisection on phi_f

    def _lift_min(self) -> float:
        """The lowest phi_f a lift-up late flies [rad]: phi_0's lower bound, or
        npc.lift_final_min_deg above it. The bank's sine at the end of the entry is the lateral
        lift the final reversal has left to null the crossrange with; lowered to the bound the
        vehicle deploys high and off to the side by what the last minute drifted."""
        return max(self.bank_min_rad, math.radians(self.params["npc.lift_final_min_deg"]))

    def _lift_late(self, x, e0, s_togo, sign, h_floor, h_fire, p_warm, tol, n_max):
        """(p, phi_f, miss, predictions): the range solution of the family with phi_f lowered
        towards _lift_min (lift up at the end of the entry, which deploys higher)
        whose predicted box-entry altitude reaches h_floor and whose predicted deploy altitude
        (at the target: where the range trigger fires) reaches h_fire, phi_f the largest found
        that does (least change). p None when even phi_f at its lowest does not reach h_floor
        with the range solved (then only a range trade can: the floor's); phi_f at its lowest
        when that reaches h_floor but not h_fire (the most a lift-up late gives). Bisection on
        phi_f, each a range solution warm-started at the last."""
        lo, hi, f_nom = self.bank_min_rad, self.bank_max_rad, self.f_lift_rad
        out, n = self._out, 0
        f_lo = self._lift_min()
        f_ok, f_bad, best = f_lo, f_nom, None
        f = f_lo
        for i in range(self.LIFT_STEPS + 1):
            p_lo, p_hi = profile_span(lo, hi, f)
            p, zb, k, ok = solve_bank(self._z(x, e0, s_togo, sign, f=f), p_lo, p_hi, p_warm, tol, n_max)
            n += k
            b0, bf = bank_profile(p, lo, hi, f)
            self._predict(x, b0, bf, e0, sign, out)
            n += 1
            box_ok = ok and out[O_FLAG] == REACHED and out[O_H_BOX] >= h_floor
            if box_ok and out[O_H] >= h_fire:
                best, f_ok, p_warm = (p, f, zb), f, p
            elif i == 0:
                # at the lowest: the floor unreachable (range to trade) or the most lift-up late gives
                return (p, f, zb, n) if box_ok else (None, f, zb, n)
            else:
                f_bad = f
            f = 0.5 * (f_ok + f_bad)
        return (best[0], best[1], best[2], n)

    REACH_STEP_RAD = math.radians(10.0)   # _reach's first step up from the lift-up bound ...
    REACH_RES_RAD = math.radians(0.5)     # ... and the resolution it stops at

    def _reach_xr(self, x, b0, bf, e0, sign, h_floor, h_fire) -> float:
        """The crossrange [m, + left] where the range trigger fires on the profile (b0, bf) flown on
        past the deploy condition to the trigger's last point (trigger_reach_end), NaN when it does
        not fire at the target there: the target passed above the box (fired at its entry, behind
        it), or not reached before the trigger's Mach or altitude floor (short), or fired below
        h_fire, or the box entered below h_floor (the range solution's own altitude criteria)."""
        c, out = self._c_reach, self._out_reach
        c[:] = self.constants
        c[C_MACH_F], c[C_H_FLOOR] = self._reach_end
        self._predict(x, b0, bf, e0, sign, out, constants=c)
        if out[O_FLAG] != REACHED and out[O_FLAG] != GROUND or out[O_H_BOX] < h_floor:
            return math.nan
        # not fired: O_R_TRIG is the final position (predict)
        if out[O_R_TRIG] == out[0] and out[O_R_TRIG + 1] == out[1] and out[O_R_TRIG + 2] == out[2]:
            return math.nan
        rt = out[O_R_TRIG:O_R_TRIG + 3]
        xr = float(out[O_XR_TRIG])
        d = central_angle(rt, self.target_u) * self.radius_m
        if d * d - xr * xr > self.params["npc.tol_m"] ** 2 or math.sqrt(float(rt @ rt)) - self.radius_m < h_fire:
            return math.nan
        return xr

    def _reach(self, x, e0, sign, b0, bf, h_floor, h_fire, n_max) -> tuple[float, int]:
        """(phi [rad], predictions): the bank magnitude held to the end that nulls the crossrange
        where the range trigger fires (_reach_xr), searched from the answer's bank now towards
        90 deg (the most lateral lift), NaN when none does better than the answer by more than
        npc.tol_m. For an answer at the lift-up bound (a range solution held there short of the
        aim point, or a lift-up late whose line ends there): the range trigger deploys where the
        target comes abeam anywhere in the box, so the range the bound buys past that point is
        not needed, while the bank's sine at the bound (0.17 at 10 deg) is all the lateral lift the
        sign kept has to null the crossrange with: 4.9 km left at the deploy of 1732050 run 56,
        whose prediction at 140 s nulled it at 25 deg and still deployed at the target at 9.9 km.
        Every magnitude tried must still fire at the target with the range solution's altitude
        criteria (the feasible ones are those nearer the bank now than the first that does not).
        Secant on the crossrange from the answer's, inside a bracket once one is found; stops when
        the crossrange stops shrinking (the sign kept pushes the other way, or the most lateral
        lift is reached)."""
        tol = self.params["npc.tol_m"]
        g0 = self._reach_xr(x, b0, bf, e0, sign, h_floor, h_fire)
        n = 1
        if not abs(g0) > tol:           # on target already, or not firing at the target: no reach to use
            return math.nan, n
        top = 0.5 * math.pi
        base = min(self.bank_max_rad, max(self.bank_min_rad, b0))
        d = 1.0 if base <= top else -1.0    # towards 90 deg from the bank now: t = d (phi - base)
        t_top = abs(top - base)
        a_t, a_g = 0.0, g0              # same side as g0, nearest the null
        c_t = c_g = math.nan            # the other side (a bracket), once found
        bad = math.inf                  # nearest magnitude that does not fire at the target
        prev_t = prev_g = math.nan
        t_w = d * (self.reach_rad - base)
        t = t_w if 0.0 < t_w < t_top else min(t_top, self.REACH_STEP_RAD)
        best_t, best_g = math.nan, g0
        while n < n_max and t > 0.0:
            phi = base + d * t
            g = self._reach_xr(x, phi, phi, e0, sign, h_floor, h_fire)
            n += 1
            if math.isnan(g):
                bad = t
            else:
                if abs(g) < abs(best_g):
                    best_t, best_g = t, g
                if abs(g) <= tol:
                    break
                if g * g0 > 0.0:
                    if abs(g) >= abs(a_g) and math.isnan(c_t):
                        break           # shrinking no more: the most this sign reaches
                    prev_t, prev_g, a_t, a_g = a_t, a_g, t, g
                else:
                    c_t, c_g = t, g
            hi_lim = min(bad, t_top) if math.isnan(c_t) else c_t
            if hi_lim - a_t < self.REACH_RES_RAD:
                break
            if not math.isnan(c_t):
                nxt = a_t - a_g * (c_t - a_t) / (c_g - a_g)
            elif not math.isnan(prev_t) and a_g != prev_g:
                nxt = a_t - a_g * (a_t - prev_t) / (a_g - prev_g)
            else:
                nxt = a_t + self.REACH_STEP_RAD
            t = nxt if a_t < nxt < hi_lim else 0.5 * (a_t + hi_lim)
        if abs(best_g) < abs(g0) - tol:
            return base + d * best_t, n
        return math.nan, n

    def _deploy_crossrange(self, x: np.ndarray, out: np.ndarray) -> float:
        """The predicted deploy crossrange [m, + left] of the prediction out from x: with the range
        trigger across the track where it fires (O_XR_TRIG: the deploy miss when the target
        comes abeam), else off the great circle from x to the target at the prediction's end.
        The trigger's figure counts only where that point lies within the range reserve of the
        target along the track: a track that turns more than 90 deg off the target's bearing
        before the box passes it "abeam" far out (the box entry then, the target behind), and
        one that ends short by more has its crossrange still to fly."""
        xr = float(out[O_XR_TRIG])
        if self.constants[C_TRIG] != 0.0 and math.isfinite(xr):
            d = central_angle(out[O_R_TRIG:O_R_TRIG + 3], self.target_u) * self.radius_m
            if d * d - xr * xr <= self.reserve_m * self.reserve_m:
                return xr
        return crossrange(x[:3], self.target_u, out[:3], self.radius_m)

    def _missed(self, z_m: float) -> bool:
        """A range miss the guidance does not fly to: short beyond the range reserve (with the
        range trigger its altitude floor then fires short of the target), or beyond
        npc.floor_miss_max_m either way (the most it trades anywhere). NaN: missed."""
        return (self.reserve_m > 0.0 and z_m < -self.reserve_m) or not abs(z_m) <= self.params["npc.floor_miss_max_m"]

    def _reversal_loses_range(self, z_rev_m: float, z_keep_m: float) -> bool:
        """The reversed flight of the lateral pair has no range solution (z_rev_m, past the aim
        point) where the kept one has (z_keep_m): a reversal now would be flown to a deploy
        short or long by more than the guidance accepts (_missed), at whatever bank the
        corrector then finds least bad. Its crossrange is then not one the final rule may null:
        that flight is not the one that follows (the next answers, re-solved from the states
        the reversal passes through, turn or change the way it goes)."""
        return self._missed(z_rev_m) and abs(z_rev_m) > abs(z_keep_m) + self.params["npc.tol_m"]

    def solve(self, x: np.ndarray, sign: float, k_rho: float, k_ld: float, t_flip: float = math.nan,
              shp: np.ndarray | None = None, h_floor_m: float | None = None,
              t_flip_held: float = math.nan) -> Correction:
        """One correction from the planet-fixed state x: phi_0 and the predicted deploy. With
        t_flip given, the lateral logic's final reversal gets its pair (deploy crossranges with
        the sign kept, and reversed: a reversal commanded t_flip from now, the range solved
        again for it); with t_flip_held given too, the held pair (this answer's magnitude, the
        reversal in effect at once t_flip_held from now). shp: the reference shaper's state at
        x (shaped_transition), None: the bank follows the law at once (and a reversal takes
        effect at t_flip). h_floor_m: the predicted deploy altitude to keep (range traded for
        it), None: npc.h_floor_m."""
        t0 = time.perf_counter_ns()
        self._shp = shp
        c = self.constants
        c[C_KRHO], c[C_KLD] = k_rho, k_ld
        c[C_TGT:C_TGT + 3] = self.target_u          # the range trigger's point (O_XR_TRIG) is judged on it
        r = math.sqrt(float(x[:3] @ x[:3]))
        e0 = self.mu_m3ps2 / r - 0.5 * float(x[3:] @ x[3:])
        s_togo = central_angle(x[:3], self.target_u) * self.radius_m
        s_aim = s_togo + self.reserve_m          # the aim point: range_reserve beyond the target
        lo, hi, f = self.bank_min_rad, self.bank_max_rad, self.f_lift_rad
        p_span = profile_span(lo, hi, f)
        p_warm = self.bank0
        if math.isfinite(self._p_e0_jpkg) and self.e_deploy_jpkg != self._p_e0_jpkg:
            p_warm = profile_at(p_warm, lo, hi, f, (e0 - self._p_e0_jpkg) / (self.e_deploy_jpkg - self._p_e0_jpkg))
        tol, n_max = self.params["npc.tol_m"], int(self.params["npc.max_iter"])
        p, zb, n, ok = solve_bank(self._z(x, e0, s_aim, sign, f=f), *p_span, p_warm, tol, n_max)
        turn = math.nan
        alt = None
        if shp is not None and self._missed(zb):
            alt = reversal_other_way(shp, sign)
        if alt is not None:
            # a reversal in progress whose way round costs more range than the guidance
            # trades anywhere (npc.floor_miss_max_m), or, with the range trigger, leaves the
            # vehicle short of the target itself (beyond the reserve: the trigger's altitude
            # floor then fires short, while a vehicle turned long still deploys at the target):
            # the other way (the reference braked and turned back, as the shaper would fly it)
            # if that one's answer misses by less. Not for less: the lateral decision timed
            # the reversal for the way it began, and turning round delays it, which costs
            # crossrange
            self._shp = alt
            pa, za, na, oka = solve_bank(self._z(x, e0, s_aim, sign, f=f), *p_span, p_warm, tol, n_max)
            n += na
            if abs(za) < abs(zb) - tol:
                p, zb, ok, turn = pa, za, oka, float(alt[3])
            else:
                self._shp = shp
        b_range = p
        b0, bf = bank_profile(p, lo, hi, f)
        held = not lo <= p <= hi
        # the prediction of the answer (the root-finder's last call may have been another)
        self._predict(x, b0, bf, e0, sign, self._out)
        floor = False
        h_floor = self.params["npc.h_floor_m"] if h_floor_m is None else h_floor_m
        h_fire = self.params["npc.h_fire_m"] if h_floor > 0.0 else 0.0
        if (h_floor > 0.0 and self._out[O_FLAG] == REACHED and f > self._lift_min()
                and (self._out[O_H_BOX] < h_floor or self._out[O_H] < h_fire)):
            # the range solution deploys too low (or reaches the target only below h_fire, where
            # the trigger's own floor fires short of it): first lift up late, range kept (phi_f
            # lowered, phi_0 solved again for the range: lift down before, lift up at the end)
            lift = self._lift_late(x, e0, s_aim, sign, h_floor, h_fire, p, tol, n_max)
            n += lift[3]
            if lift[0] is not None:
                p, f, zb = lift[0], lift[1], lift[2]
                b_range = p
                b0, bf = bank_profile(p, lo, hi, f)
                held = not lo <= p <= hi
            self._predict(x, b0, bf, e0, sign, self._out)
        if h_floor > 0.0 and self._out[O_FLAG] != SKIPPED and self._out[O_H_BOX] < h_floor and p > lo:
            # the range solution deploys too low: trade range for altitude (more lift up, so
            # long). In this mode the profile holds phi_0 to the end when phi_0 < phi_f (the
            # fixed phi_f would otherwise take the lift-up away just where it counts), and
            # phi_0 is the largest bank whose predicted deploy altitude reaches the floor
            b_fl, nh = self._floor_bank(x, e0, s_aim, sign, h_floor, min(p, hi), self._out[O_H_BOX])
            n += nh
            if math.isnan(b_fl):        # no trade deploys higher: the range solution's prediction again
                self._predict(x, b0, bf, e0, sign, self._out)
            else:
                floor = True
                b0, bf = b_fl, min(f, b_fl)
                self._predict(x, b0, bf, e0, sign, self._out)
                zb = (central_angle(x[:3], self._out[:3]) * self.radius_m - s_aim if self._out[O_FLAG] == REACHED
                      else math.nan)
                ok = False
        reach = False
        if self._reach_end is not None and h_floor > 0.0 and self._out[O_FLAG] == REACHED:
            # the answer flies the lift-up bound now and over the first half of the energy to go
            # (a range solution held there), or its line ends there (a lift-up late at its lowest):
            # the magnitude for the crossrange too
            lift = self._lift_min() + 1e-9
            if min(hi, max(lo, b0)) <= lift and min(hi, max(lo, 0.5 * (b0 + bf))) <= lift or bf <= lift:
                phi, nr = self._reach(x, e0, sign, b0, bf, h_floor, h_fire, n_max)
                n += nr
                self.reach_rad = phi
                if not math.isnan(phi):
                    self._predict(x, phi, phi, e0, sign, self._out)
                    if self._out[O_FLAG] == REACHED:
                        reach = True
                        b0 = bf = phi
                        zb = central_angle(x[:3], self._out[:3]) * self.radius_m - s_aim
                    else:                   # the answer's prediction again
                        self._predict(x, b0, bf, e0, sign, self._out)
            else:
                self.reach_rad = math.nan
        rf = self._out[:3].copy()
        # phi_0 commanded: the profile's bank now (the line clipped to the bounds, as predicted)
        res = Correction(bank0_rad=min(hi, max(lo, b0)), p_range_rad=b_range, f_family_rad=f, e0_jpkg=e0, bank_line_rad=b0,
                         bank_final_rad=bf, floor=floor, reach=reach, held=held and not floor, miss_m=zb, predictions=n + 1,
                         turn_rad=turn, ok=ok or floor, range_to_go_m=s_togo,
                         lat_rad=math.asin(rf[2] / math.sqrt(float(rf @ rf))), lon_rad=math.atan2(rf[1], rf[0]),
                         h_final_m=float(self._out[O_H]), h_box_m=float(self._out[O_H_BOX]), t_go_s=float(self._out[O_T]), xr_keep_m=math.nan,
                         xr_rev_m=math.nan, xr_keep_held_m=math.nan, xr_rev_held_m=math.nan, compute_ns=0)
        if self._out[O_FLAG] == REACHED and math.isfinite(t_flip):
            # the lateral decision's pair, each the flight the corrector would fly: "keep" is this
            # answer's own prediction (its profile, through the shaper); "reverse" is the range
            # solution for the other sign with the reversal commanded t_flip from now and flown
            # through the shaper from its present state (the way round it takes, a reference
            # still moving or beyond 90 deg), re-solved because the next answers will be: a
            # reversal costs or gains range, the magnitude after it moves (towards lift up after
            # one through lift down), and a pair flown with this answer's magnitude and an
            # instant flip promised a null the flight then lost. Their crossranges are the deploy's
            # (_deploy_crossrange): with the range trigger the miss where the target comes
            # abeam, not the offset of where the prediction ends (the aim point, range_reserve
            # and the box's stretch further on) off the great circle to the target: a track that
            # meets that circle at an angle nulls one and not the other
            out = self._out
            res["xr_keep_m"] = self._deploy_crossrange(x, out)
            p_rev, z_rev, n_rev, _ = solve_bank(self._z(x, e0, s_aim, -sign, t_flip, f), *profile_span(lo, hi, f),
                                                p, tol, n_max)
            b0_rev, bf_rev = bank_profile(p_rev, lo, hi, f)
            self._predict(x, b0_rev, bf_rev, e0, -sign, out, t_flip)
            res["predictions"] += n_rev + 1
            if out[O_FLAG] == REACHED and not self._reversal_loses_range(z_rev, zb):
                res["xr_rev_m"] = self._deploy_crossrange(x, out)
            if math.isfinite(t_flip_held):
                # the held pair: this answer's magnitude kept, the reversal in effect at once at
                # t_flip_held (LateralLogic: a final reversal must be due for both pairs)
                dt, ef = self.params["npc.dt_pred_s"], self.e_deploy_jpkg
                predict(x, c, b0, bf, e0, ef, sign, dt, out, 0.0)
                res["predictions"] += 1
                if out[O_FLAG] == REACHED:
                    res["xr_keep_held_m"] = self._deploy_crossrange(x, out)
                    predict(x, c, b0, bf, e0, ef, -sign, dt, out, t_flip_held)
                    res["predictions"] += 1
                    if out[O_FLAG] == REACHED:
                        res["xr_rev_held_m"] = self._deploy_crossrange(x, out)
        res["compute_ns"] = time.perf_counter_ns() - t0
        return res
