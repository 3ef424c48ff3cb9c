"""The bank shaper: the commanded bank turned into the reference phi_r, phidot_r, phiddot_r
within the rate and acceleration limits the attitude chain is given (``BankShaper``), and
the same law compiled for the predictor (``shaped_transition``), so that the corrector
predicts a reversal as the vehicle will fly it.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def shaper_accel(phi, phid, target, rate_limit, accel_limit, dt):
    """The reference's acceleration towards target: bang-bang at the acceleration limit to
    the desired rate min(rate limit, sqrt(2 a |e|) (braking), |e|/dt), by sign of the error.
    One law for the BankShaper and the predictor (``shaper_accel_braked`` with the braking
    limit equal to the acceleration limit)."""
    return shaper_accel_braked(phi, phid, target, rate_limit, accel_limit, accel_limit, dt)


@njit(cache=True, nogil=True)
def shaper_accel_braked(phi, phid, target, rate_limit, accel_limit, brake_limit, dt):
    """``shaper_accel`` slowing down at b = brake_limit <= accel_limit: braking on
    sqrt(2 b |e|) onto the target, and turning round at most b while it moves away from the
    target (a new command behind it, e.g. a reversal commanded while it turns); it speeds up
    at the acceleration limit."""
    e = target - phi
    v_des = math.copysign(min(rate_limit, math.sqrt(2.0 * brake_limit * abs(e)), abs(e) / dt), e)
    a = max(-accel_limit, min(accel_limit, (v_des - phid) / dt))
    if phid * e < 0.0:                 # moving away from the target: turning round
        a = max(-brake_limit, min(brake_limit, a))
    return a


@njit(cache=True, nogil=True)
def _brake_of(shp):
    """The braking limit of a shaper state (shaped_transition's shp; its acceleration limit when
    the state has none)."""
    return shp[8] if shp.shape[0] > 8 else shp[5]


# a reversal goes through lift up unless the way through lift down is shorter by more than this
# [rad]: near a 90 deg magnitude the two ways take about the same time, and the one through lift
# down spends it with the lift down, which costs range the corrector then wins back by turning
# the reversal round (braked and flown back the other way, late on the timing the lateral
# decision set); 30 deg is ~4 s at the 8 deg/s rate limit, a reversal at up to 97.5 deg
REVERSAL_LIFT_UP_RAD = math.radians(30.0)


@njit(cache=True, nogil=True)
def _reversal_turn(phi, bank_signed):
    """The turn (a multiple of 2 pi) of a new reversal from phi to the other side's
    bank_signed: through lift up (cos < 0 never crossed), unless the way through lift down is
    shorter by more than REVERSAL_LIFT_UP_RAD."""
    turn = 2.0 * math.pi * round((phi - bank_signed) / (2.0 * math.pi))
    near = bank_signed + turn
    turn_other = turn - math.copysign(2.0 * math.pi, near - phi)
    # of two ways to the other side, the one through lift up has its mid-point at cos > 0
    up, down = (turn, turn_other) if math.cos(0.5 * (phi + near)) > 0.0 else (turn_other, turn)
    if abs(bank_signed + up - phi) - abs(bank_signed + down - phi) <= REVERSAL_LIFT_UP_RAD:
        return up
    return down


@njit(cache=True, nogil=True)
def shaper_branch(phi, sign_now, turn, bank_signed):
    """(sign, turn) of the reference's target bank_signed + turn (turn a multiple of 2 pi): a
    new reversal from the other side goes through lift up, or through lift down when that way
    is shorter by more than REVERSAL_LIFT_UP_RAD (``_reversal_turn``); a reversal commanded
    while the reference is on the new side already, and magnitude changes once it is on the
    commanded side, take the nearest way (they never cross 0 or 180 deg)."""
    s = 1.0 if bank_signed >= 0 else -1.0
    if s != sign_now and math.sin(phi) * s < 0.0:
        return s, _reversal_turn(phi, bank_signed)
    if s != sign_now or math.sin(phi) * s > 0.0:
        return s, 2.0 * math.pi * round((phi - bank_signed) / (2.0 * math.pi))
    return sign_now, turn


@njit(cache=True, nogil=True)
def arrival_s(dist, speed, rate_limit, accel_limit, brake_limit):
    """Time [s] for the law to come to rest at a target dist [rad] ahead, from the speed
    [rad/s] towards it (negative: moving away), speeding up at the acceleration limit and
    braking at the braking limit, within the rate limit. Moving away it first turns round
    (|speed|/b, v^2/2b further off); too fast to stop on the target it runs past, stops and
    comes back from rest."""
    w, a, b = rate_limit, accel_limit, brake_limit
    if w <= 0.0 or a <= 0.0 or b <= 0.0:
        return math.inf
    t = 0.0
    v = min(speed, w)
    if v < 0.0:                          # turn round first
        t = -v / b
        dist += v * v / (2.0 * b)
        v = 0.0
    stop = v * v / (2.0 * b)
    if stop > dist:                      # past the target, to rest, then back from there
        t += v / b
        dist, v = stop - dist, 0.0
    # speed up from v to the peak: (peak^2 - v^2)/2a + peak^2/2b = dist, within the rate limit
    peak = math.sqrt((dist + v * v / (2.0 * a)) / (1.0 / (2.0 * a) + 1.0 / (2.0 * b)))
    if peak <= w:
        return t + (peak - v) / a + peak / b
    cruise = dist - (w * w - v * v) / (2.0 * a) - w * w / (2.0 * b)
    return t + (w - v) / a + cruise / w + w / b


# going on by a full turn must spare at least this much time with the lift down [s]: it commits
# the reference to a turn through the other side, so between ways that differ by a few seconds
# (a turn round at the nominal braking limit) the one the branch rule gives is kept; the long
# turn round of a weak braking way after a reconfiguration costs tens of seconds
GO_ON_MARGIN_S = 10.0
# the step [s] at which the two ways are flown to compare their time with the lift down
_WAY_STEP_S = 0.1


@njit(cache=True, nogil=True)
def lift_down_s(phi, phid, target, rate_limit, accel_limit, brake_limit):
    """Time [s] the law spends with the lift down (cos phi < 0) on its way from (phi, phid) to
    rest on target, flown at a coarse step (a comparison of ways, not a prediction); at most
    10 min."""
    dt, t_down = _WAY_STEP_S, 0.0
    for _ in range(int(600.0 / dt)):
        if abs(target - phi) < 1e-3 and abs(phid) < 1e-3:
            break
        a = shaper_accel_braked(phi, phid, target, rate_limit, accel_limit, brake_limit, dt)
        phi += phid * dt + 0.5 * a * dt * dt
        phid += a * dt
        if math.cos(phi) < 0.0:
            t_down += dt
    return t_down


@njit(cache=True, nogil=True)
def shaper_branch_moving(phi, phid, sign_now, turn, bank_signed, rate_limit, accel_limit, brake_limit):
    """``shaper_branch`` for a reference moving at phid: when its target lies behind it (a
    command that reverses its motion), it goes on by a full turn (the turn one 2 pi further the
    way it moves) when that arrives sooner than turning round at the braking limit and spends
    GO_ON_MARGIN_S less with the lift down. With a weak braking way turning round is long: a
    reversal at the rate limit caught by a reconfiguration, then commanded back to lift up,
    would brake over v^2/2b through lift down and come all the way back. At rest, or moving
    towards the target, the branch is shaper_branch's."""
    s, turn = shaper_branch(phi, sign_now, turn, bank_signed)
    target = bank_signed + turn
    e = target - phi
    if phid * e < 0.0:
        ahead = 2.0 * math.pi - abs(e)
        if arrival_s(ahead, abs(phid), rate_limit, accel_limit, brake_limit) < \
                arrival_s(abs(e), -abs(phid), rate_limit, accel_limit, brake_limit):
            on = target + math.copysign(2.0 * math.pi, phid)
            if lift_down_s(phi, phid, on, rate_limit, accel_limit, brake_limit) + GO_ON_MARGIN_S < \
                    lift_down_s(phi, phid, target, rate_limit, accel_limit, brake_limit):
                turn += math.copysign(2.0 * math.pi, phid)
    return s, turn


# a shaped transition longer than this is not modelled past it (the law takes over)
N_TRANSITION = 256


@njit(cache=True, nogil=True)
def shaped_transition(shp, bank_a, t_switch, bank_b, t_sample, tab):
    """The reference's bank [rad, signed, on the shaper's branch] every t_sample [s] from now
    while the BankShaper moves from its state towards bank_a and, from t_switch on, towards
    bank_b (a reversal commanded then): the same branch rule and acceleration law, stepped
    at the control period. shp: [phi, phidot, sign, turn, rate limit, acceleration limit,
    control period, the magnitude commanded now, braking limit (optional: the acceleration
    limit when absent)]. The branch (which way round) is the one
    the shaper takes for the command now, fixed for the prediction: in flight the new
    answer arrives after the reversal has set off, and a branch that followed the
    corrector's trial bank would flip near a 180 deg swing and make the miss function jump.
    Returns the number of samples written to tab; the last is the first at which the
    reference has settled on bank_b (<= 1 when it already has)."""
    phi, phid, s_now, turn = shp[0], shp[1], shp[2], shp[3]
    rate, accel, dtc, mag_now = shp[4], shp[5], shp[6], shp[7]
    brake = _brake_of(shp)
    s_now, turn = shaper_branch_moving(phi, phid, s_now, turn, math.copysign(mag_now, bank_a), rate, accel, brake)
    target = bank_a + turn
    switched = t_switch <= 0.0
    if switched:
        s_now, turn = shaper_branch_moving(phi, phid, s_now, turn, math.copysign(mag_now, bank_b), rate, accel, brake)
        target = bank_b + turn
    per = max(1, int(round(t_sample / dtc)))
    n = 0
    k = 0
    while n < tab.shape[0]:
        if not switched and k * dtc >= t_switch - 1e-9:
            switched = True
            s_now, turn = shaper_branch_moving(phi, phid, s_now, turn, math.copysign(mag_now, bank_b), rate, accel,
                                               brake)
            target = bank_b + turn
        if k % per == 0:
            tab[n] = phi
            n += 1
            if switched and abs(target - phi) < 1e-3 and abs(phid) < 1e-3:
                break
        a = shaper_accel_braked(phi, phid, target, rate, accel, brake, dtc)
        phi += phid * dtc + 0.5 * a * dtc * dtc
        phid += a * dtc
        k += 1
    return n


def reversal_other_way(shp: np.ndarray, sign: float) -> np.ndarray | None:
    """The shaper's state (shaped_transition's shp) with a reversal to ``sign`` going the
    other way round, or None: when no reversal is under way (the reference already on the
    side of ``sign``: magnitude changes take the nearest way), or when the other way is not
    the shorter one from the reference's state (braking included; through lift down, shorter
    by more than REVERSAL_LIFT_UP_RAD, the margin the reversal set off with). The way a reversal
    goes is chosen for the magnitude commanded when it starts; the corrector's next answer
    can make the other way the shorter (a reversal begun at 92 deg through 180 deg, then a
    10 deg command: 258 deg on through lift down, ~100 deg back through lift up). The way
    round is the turn (a multiple of 2 pi) added to the command; the shaper keeps a given
    turn until the reference has crossed to the commanded side."""
    phi, phid, decel, mag = float(shp[0]), float(shp[1]), float(_brake_of(shp)), float(shp[7])
    if math.sin(phi) * sign >= 0.0 or decel <= 0.0:
        return None
    s, turn = shaper_branch(phi, float(shp[2]), float(shp[3]), math.copysign(mag, sign))
    target = math.copysign(mag, sign) + turn
    other = target - math.copysign(2.0 * math.pi, target - phi)
    # moving towards the present target, the other way first turns round at the braking
    # limit b: v^2/2b out and back; a way through lift down must be shorter by more than
    # REVERSAL_LIFT_UP_RAD, as when the reversal set off (shaper_branch), or a turn round would
    # undo that rule's choice a cycle later
    brake = phid * phid / decel if phid * (target - phi) > 0.0 else 0.0
    margin = REVERSAL_LIFT_UP_RAD if math.cos(0.5 * (phi + other)) < 0.0 else 0.0
    if abs(other - phi) + brake + margin >= abs(target - phi):
        return None
    alt = shp.copy()
    alt[2], alt[3] = s, other - math.copysign(mag, sign)
    return alt


class BankShaper:
    """The commanded bank turned into a reference phi_r, phidot_r, phiddot_r that respects
    the rate and acceleration limits: a second-order tracker (bang-bang towards the
    target, braking on sqrt(2 a |e|)), stepped once per control period. A reversal (sign
    change) goes the shorter way round (through lift up below 90 deg, lift down above);
    magnitude changes keep the branch. Same interface as reference.BankProfile for the
    attitude chain: evaluate(t) and replan(t, rate, accel). Told the vehicle's bank each
    cycle (observe), it is also a reference governor (_govern)."""

    # the governor's lag band [deg]: above the attitude loop's own tracking error in a
    # fault-free entry (about 0.1 deg), below the 1 deg the faulted loop is held to
    LAG_FREE_DEG = 0.15
    LAG_MAX_DEG = 0.4

    def __init__(self, phi0_rad: float, rate_limit_radps: float, accel_limit_radps2: float, dt_s: float):
        self.rate_limit_radps = float(rate_limit_radps)
        self.accel_limit_radps2 = float(accel_limit_radps2)
        self.brake_limit_radps2 = self.accel_limit_radps2     # braking (replan), <= the acceleration limit
        self.dt_s = float(dt_s)
        self.phi = float(phi0_rad)
        self.phid = 0.0
        self.phidd = 0.0
        self.target = self.phi
        self._sign = 1.0 if phi0_rad >= 0 else -1.0
        self._turn = 0.0            # target = command + turn (a multiple of 2 pi)
        self._t = None
        # the reference governor (_govern): the vehicle's bank (observe; None: not governed)
        self.vehicle_rad: float | None = None
        self.lag_free_rad = math.radians(self.LAG_FREE_DEG)
        self.lag_max_rad = math.radians(self.LAG_MAX_DEG)
        self.governed_cycles = 0    # control cycles whose acceleration the governor changed

    def command(self, bank_signed_rad: float) -> None:
        self._sign, self._turn = shaper_branch_moving(self.phi, self.phid, self._sign, self._turn,
                                                      float(bank_signed_rad), self.rate_limit_radps,
                                                      self.accel_limit_radps2, self.brake_limit_radps2)
        self.target = bank_signed_rad + self._turn

    def state(self, mag_rad: float) -> np.ndarray:
        """The state shaped_transition starts from (its shp), mag_rad the magnitude commanded now."""
        return np.array([self.phi, self.phid, self._sign, self._turn, self.rate_limit_radps, self.accel_limit_radps2,
                         self.dt_s, mag_rad, self.brake_limit_radps2])

    def turn_round(self, turn_rad: float, sign: float) -> bool:
        """Take another way round (turn_rad, as reversal_other_way's; NaN: none) for the
        reversal to ``sign`` while it is under way (the reference not yet on that side);
        True if taken."""
        if not (math.isfinite(turn_rad) and sign == self._sign and math.sin(self.phi) * self._sign < 0.0):
            return False
        self.target += turn_rad - self._turn
        self._turn = turn_rad
        return True

    def _step(self) -> None:
        dt, a = self.dt_s, self.phidd
        self.phi += self.phid * dt + 0.5 * a * dt * dt
        self.phid += a * dt

    def evaluate(self, t_s: float) -> tuple[float, float, float]:
        if self._t is None:
            self._t = t_s
        n = int(round((t_s - self._t) / self.dt_s))
        for _ in range(max(0, n)):
            self._step()
        self._t += n * self.dt_s if n > 0 else 0.0
        self.phidd = shaper_accel_braked(self.phi, self.phid, self.target, self.rate_limit_radps,
                                         self.accel_limit_radps2, self.brake_limit_radps2, self.dt_s)
        if self.vehicle_rad is not None:
            self._govern()
        return self.phi, self.phid, self.phidd

    def observe(self, bank_rad: float) -> None:
        """The vehicle's bank now (navigation), for the governor of the next evaluate; a
        non-finite one leaves the reference ungoverned."""
        b = float(bank_rad)
        self.vehicle_rad = b if math.isfinite(b) else None

    def _govern(self) -> None:
        """The reference does not run away from a vehicle that lags it. The lag is the
        reference minus the vehicle's bank (the shorter way); the reference runs away while
        it moves to the lag's side. Then, beyond lag_free_rad, its acceleration to that side
        fades linearly to zero at lag_max_rad, and beyond lag_max_rad it brakes, at up to its
        acceleration limit (reached one band's width further). So the reference keeps, at
        most, the pace the vehicle shows it can fly and the loop's whole authority closes the
        gap, instead of the reference leaving at an acceleration the jets cannot match (their
        authority is estimated for the nominal inertia and is an average over cycles).
        A reference at rest, or moving towards the vehicle (a vehicle ahead of it, pushed by a
        torque the jets cannot hold), follows the law: the vehicle never drags it along."""
        lag = math.remainder(self.phi - self.vehicle_rad, 2.0 * math.pi)
        a, band = abs(lag), self.lag_max_rad - self.lag_free_rad
        s = 1.0 if lag > 0.0 else -1.0
        if not (a > self.lag_free_rad and self.phid * s > 0.0):   # (NaN: no valid bank)
            return
        if a > self.lag_max_rad:
            brake = -s * self.accel_limit_radps2 * min(1.0, (a - self.lag_max_rad) / band)
            self.phidd = min(self.phidd, brake) if s > 0.0 else max(self.phidd, brake)
            self.governed_cycles += 1
        elif self.phidd * s > 0.0:
            self.phidd *= (self.lag_max_rad - a) / band
            self.governed_cycles += 1

    def transition_s(self, angle_rad: float) -> float:
        """Time [s] of a rest-to-rest turn through angle_rad within the rate, acceleration and
        braking limits (trapezoidal rate, triangular when the rate limit is not reached)."""
        w, a, b, d = self.rate_limit_radps, self.accel_limit_radps2, self.brake_limit_radps2, abs(angle_rad)
        if w <= 0.0 or a <= 0.0 or b <= 0.0:
            return math.inf
        h = a if b == a else 2.0 * a * b / (a + b)     # the harmonic mean: d = v^2/2a + v^2/2b = v^2/h
        return d / w + w / h if d >= w * w / h else 2.0 * math.sqrt(d / h)

    def reversal_s(self, mag_rad: float) -> float:
        """Time [s] of a reversal from rest at bank magnitude mag_rad, the way shaper_branch
        takes: through 0 (2 |mag|) unless through 180 deg is shorter by more than
        REVERSAL_LIFT_UP_RAD."""
        m = abs(mag_rad)
        up, down = 2.0 * m, 2.0 * (math.pi - m)
        return self.transition_s(up if up - down <= REVERSAL_LIFT_UP_RAD else down)

    def replan(self, t_now: float, rate_limit_radps: float, accel_limit_radps2: float,
               brake_limit_radps2: float | None = None) -> bool:
        """New limits from now; the braking limit (None: the acceleration limit) is held within
        the acceleration limit. True if any changed."""
        brake = accel_limit_radps2 if brake_limit_radps2 is None else min(brake_limit_radps2, accel_limit_radps2)
        new = (float(rate_limit_radps), float(accel_limit_radps2), float(brake))
        changed = new != (self.rate_limit_radps, self.accel_limit_radps2, self.brake_limit_radps2)
        self.rate_limit_radps, self.accel_limit_radps2, self.brake_limit_radps2 = new
        return changed
