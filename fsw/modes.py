"""Modes (docs/fsw/index.md "Modes") and the ordered failsafe list.

STANDBY: the loop runs, jets inhibited.  ENTRY: closed loop, adaptation on.
SAFE: rate damping only, adaptation frozen, jets enabled.

Allowed transitions: STANDBY -> ENTRY, ENTRY <-> SAFE, any -> STANDBY. A request for the
current mode is accepted as a no-op (no event). A refused request returns False and
raises a WARNING event; an accepted one a NOTICE event (source "modes").

Failsafes (PX4 style: one explicit ordered list, first match wins), evaluated once per
control period by the executive:

| # | condition                                           | action                                 |
|---|-----------------------------------------------------|----------------------------------------|
| 1 | sensor frames stale (SensorMonitor.stale)           | HOLD_JETS_OFF, mode unchanged          |
| 2 | in ENTRY: tracking error > fdir.safe_track_deg for fdir.safe_track_s | request SAFE       |

Leaving SAFE is a ground decision (request ENTRY); nothing returns to ENTRY by itself.
"""
from __future__ import annotations

import math
from enum import IntEnum

import numpy as np
from numba import njit

from common.events import EventLog
from interfaces.event_catalogue import EV
from interfaces.vocabulary import Mode

from .params import Param


_ALLOWED = {
    (Mode.STANDBY, Mode.ENTRY),
    (Mode.ENTRY, Mode.SAFE),
    (Mode.SAFE, Mode.ENTRY),
    (Mode.ENTRY, Mode.STANDBY),
    (Mode.SAFE, Mode.STANDBY),
}


class ModeManager:
    """The current mode and what it implies for the rest of the FSW."""

    def __init__(self, events: EventLog, initial: Mode = Mode.STANDBY) -> None:
        self.events = events
        self.mode = Mode(initial)
        self.transitions: list[tuple[float, Mode, Mode, str]] = []   # (t_s, from, to, reason)

    def request(self, t_s: float, mode, reason: str) -> bool:
        """Ask for ``mode`` (a Mode or its int/name). True if now in that mode."""
        try:
            target = Mode[mode.upper()] if isinstance(mode, str) else Mode(mode)
        except (KeyError, ValueError):
            self.events.emit(t_s, EV.MODE_REFUSED, request=str(mode))
            return False
        reason = str(reason)
        if target == self.mode:
            return True
        if (self.mode, target) not in _ALLOWED:
            self.events.emit(t_s, EV.MODE_REFUSED, current=self.mode, target=target)
            return False
        self.transitions.append((t_s, self.mode, target, reason))
        before, self.mode = self.mode, target
        self.events.emit(t_s, EV.MODE_CHANGE, current=before, target=target, reason=reason)
        return True

    @property
    def jets_enabled(self) -> bool:
        return self.mode != Mode.STANDBY

    @property
    def adaptation_enabled(self) -> bool:
        return self.mode == Mode.ENTRY

    @property
    def closed_loop(self) -> bool:
        return self.mode == Mode.ENTRY

    @property
    def rate_damping(self) -> bool:
        return self.mode == Mode.SAFE


class FailsafeAction(IntEnum):
    NONE = 0
    HOLD_JETS_OFF = 1   # command zero this period; mode unchanged
    SAFE = 2            # switch to SAFE (rate damping, adaptation frozen)


# the failsafes' state as the compiled cycle reads it (``tracking_rule``): seconds beyond the
# tracking limit, the rule that matched last (_RULES), the limit [rad], the persistence [s]
_F_ABOVE, _F_RULE, _F_LIMIT, _F_PERSIST = range(4)
_RULES = ("", "sensors_stale", "tracking_error")


@njit(cache=True)
def tracking_rule(tracking_error_rad, entry, dt_s, st):
    """Rule 2 of ``Failsafes.evaluate`` with fresh sensors, compiled, on its state ``st``
    (layout above; ``entry``: the mode is ENTRY). True when SAFE is due: the caller requests it."""
    beyond = not (math.isfinite(tracking_error_rad) and abs(tracking_error_rad) <= st[_F_LIMIT])
    if entry and beyond:
        st[_F_ABOVE] += dt_s
        if st[_F_ABOVE] >= st[_F_PERSIST] - 1e-9:
            st[_F_ABOVE] = 0.0
            st[_F_RULE] = 2.0
            return True
    else:
        st[_F_ABOVE] = 0.0
    st[_F_RULE] = 0.0
    return False


class Failsafes:
    """The ordered failsafe list above. ``evaluate`` returns the action of the first rule
    that holds and applies a SAFE transition through the ModeManager itself."""

    PARAMS = [
        Param("fdir.safe_track_deg", 0.1, 180.0, "deg", "tracking error (rotation angle) beyond which SAFE is entered"),
        Param("fdir.safe_track_s", 0.0, 600.0, "s", "... for this long"),
    ]

    def __init__(self, params: dict[str, float], modes: ModeManager) -> None:
        self.state = np.zeros(4)          # (``tracking_rule``)
        for p in self.PARAMS:
            if p.name not in params:
                raise ValueError(f"{p.name}: missing")
            self.set_param(p.name, params[p.name])
        self.modes = modes

    @property
    def last_rule(self) -> str:
        """The rule that matched at the last evaluation ("" none)."""
        return _RULES[int(self.state[_F_RULE])]

    @property
    def limit_rad(self) -> float:
        return float(self.state[_F_LIMIT])

    @property
    def persist_s(self) -> float:
        return float(self.state[_F_PERSIST])

    def set_param(self, name: str, value: float) -> float:
        """Owner's hook: a new limit, used from the next evaluation on; ValueError if not ours."""
        q = next((p for p in self.PARAMS if p.name == name), None)
        if q is None:
            raise ValueError(f"{name}: not a failsafe parameter")
        v = q.check(value)
        if name == "fdir.safe_track_deg":
            self.state[_F_LIMIT] = math.radians(v)
        else:
            self.state[_F_PERSIST] = v
        return v

    def evaluate(self, t_s: float, dt_s: float, *, sensors_stale: bool, tracking_error_rad: float) -> FailsafeAction:
        """Once per control period. A non-finite tracking error counts as beyond the limit."""
        if sensors_stale:                                                   # rule 1
            self.state[_F_ABOVE] = 0.0
            self.state[_F_RULE] = 1.0
            return FailsafeAction.HOLD_JETS_OFF
        if tracking_rule(tracking_error_rad, self.modes.mode == Mode.ENTRY, dt_s, self.state):   # rule 2
            self.enter_safe(t_s)
            return FailsafeAction.SAFE
        return FailsafeAction.NONE

    def enter_safe(self, t_s: float) -> None:
        """Rule 2 matched (``tracking_rule`` said so): SAFE requested."""
        self.modes.request(t_s, Mode.SAFE, "track err")
