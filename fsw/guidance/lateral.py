"""The entry guidance's lateral channel: when to reverse the bank's sign."""
from __future__ import annotations

import math


class LateralLogic:
    """Bank sign, two rules (docs/fsw/entry-guidance.md, lateral channel):

    - corridor: reverse when the heading error to the target leaves a corridor whose
      half-width narrows linearly with speed (dpsi_hi at v_hi, dpsi_lo at v_lo). Positive
      bank turns right (heading up), so an error beyond +corridor wants a negative bank
      and beyond -corridor a positive one. It keeps the heading near the target while the
      vehicle has more lateral reach left than it needs;
    - final reversal, by prediction: xr_keep and xr_rev are the predicted crossranges at
      the deploy point if the sign is kept to the end, resp. reversed now (and kept). The
      current sign pushes the deploy point towards xr_keep - xr_rev; once even a reversal
      now leaves it on that side of the target line (or on it), waiting only adds miss: it
      reverses. Two such pairs, and the reversal must be due for both: the flights the
      corrector would fly (the reversed one re-solved for its range, flown through the
      shaper), and the same with this answer's magnitude held and the reversal in effect at
      once (the "held" pair). Near the end they agree; early in the entry the re-solved
      pair nulls where the held one still overshoots by tens of kilometres: the crossrange
      then hinges on how the magnitude will move over minutes, and the corridor keeps the
      sign. After the final reversal the corridor is off: the heading error near the end
      grows geometrically as the target comes close (its bearing swings), and a corridor
      reversal then would undo the null the prediction set up. Only the prediction may
      reverse again (if the deploy crossrange drifts past what a reversal can null).

    Both at most one reversal per rev_gap_s, and none in the last stretch: below v_norev, or
    when the predicted time to deploy is shorter than the reversal itself plus the time
    the corrector holds still before the deploy (tgo_freeze_s): the vehicle deploys with
    its bank settled."""

    def __init__(self, params: dict, v_hi_mps: float, v_lo_mps: float, sign0: float = 1.0):
        self.dpsi_hi_rad = math.radians(params["npc.dpsi_hi_deg"])
        self.dpsi_lo_rad = math.radians(params["npc.dpsi_lo_deg"])
        self.gap_s = params["npc.rev_gap_s"]
        self.v_norev_mps = params["npc.v_norev_mps"]
        self.t_settle_s = params["npc.tgo_freeze_s"]
        self.v_hi_mps, self.v_lo_mps = v_hi_mps, v_lo_mps
        self.sign = 1.0 if sign0 >= 0 else -1.0
        self.t_last_s = -math.inf
        self.final = False            # the prediction has taken over (corridor off)
        self._xr_rev_prev_m = math.nan  # xr_rev of the last update ...
        self._xr_rev_held_prev_m = math.nan  # ... and the held pair's
        self.reversals: list[float] = []
        self.rules: list[str] = []    # which rule made each reversal

    def corridor(self, v_mps: float) -> float:
        """The corridor's half-width [rad] at speed v_mps."""
        f = (v_mps - self.v_lo_mps) / (self.v_hi_mps - self.v_lo_mps) if self.v_hi_mps != self.v_lo_mps else 1.0
        f = min(1.0, max(0.0, f))
        return self.dpsi_lo_rad + (self.dpsi_hi_rad - self.dpsi_lo_rad) * f

    def update(self, t_s: float, v_mps: float, dpsi_rad: float, xr_keep_m: float = math.nan,
               xr_rev_m: float = math.nan, t_go_s: float = math.inf, t_rev_s: float = 0.0,
               xr_keep_held_m: float = math.nan, xr_rev_held_m: float = math.nan) -> bool:
        """New sign from the heading error dpsi_rad at speed v_mps, the predicted deploy
        crossranges (NaN: no prediction; the held pair NaN: that pair not asked), the predicted
        time to deploy and the time a reversal takes; True when it reversed."""
        prev, self._xr_rev_prev_m = self._xr_rev_prev_m, xr_rev_m
        prev_held, self._xr_rev_held_prev_m = self._xr_rev_held_prev_m, xr_rev_held_m
        if v_mps < self.v_norev_mps or t_s - self.t_last_s < self.gap_s or t_go_s < t_rev_s + self.t_settle_s:
            return False
        held = math.isnan(xr_keep_held_m) and math.isnan(xr_rev_held_m) or \
            _reversal_due(xr_keep_held_m, xr_rev_held_m, prev_held)
        if held and _reversal_due(xr_keep_m, xr_rev_m, prev):
            rule = "final"
        elif not self.final and (dpsi_rad > self.corridor(v_mps) if self.sign > 0
                                 else dpsi_rad < -self.corridor(v_mps)):
            rule = "corridor"
        else:
            return False
        self.final = self.final or rule == "final"
        self.rules.append(rule)
        self.sign = -self.sign
        self.t_last_s = t_s
        self.reversals.append(t_s)
        return True


def _reversal_due(xr_keep_m: float, xr_rev_m: float, xr_rev_prev_m: float) -> bool:
    """The final rule on one pair (LateralLogic): even a reversal now leaves the deploy point
    on the side the sign pushes it to, or this is the cycle nearest the crossing: now, if
    waiting one more cycle (xr_rev extrapolated linearly from the last) would overshoot by
    more than reversing now falls short; the crossrange a cycle is worth grows with speed
    (~1 km per second of delay at 1.8 km/s). NaN: False."""
    push = xr_keep_m - xr_rev_m
    nxt = 2.0 * xr_rev_m - xr_rev_prev_m
    return push != 0.0 and (push * xr_rev_m >= 0.0 or (push * nxt >= 0.0 and abs(nxt) > abs(xr_rev_m)))
