"""MAVLink to the FlightSoftware: COMMAND_LONG to its command API (``cmd_*``), the
parameter protocol to its parameter registry. This layer only checks what is MAVLink's
(a field that must carry an integer code, the failure unit) and translates; the FSW judges
the request. Whatever a handler raises, the ground gets MAV_RESULT_FAILED and a STATUSTEXT
saying so (interfaces/mavlink/README.md, "Commands").
"""
from __future__ import annotations

import logging
import math
from collections.abc import Callable

from interfaces.event_catalogue import EV
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.framing import printable_text
from interfaces.records import FAULT_NAMES
from interfaces.vocabulary import MARK_KINDS, N_JETS, CommandResult, Mode

log = logging.getLogger(__name__)

Reply = tuple[int, str]                                  # (MAV_RESULT, reason for the operator)
InjectFn = Callable[[int, str, float], bool]
MARK_NAMES = {code: kind for kind, code in MARK_KINDS.items()}    # ELLIPSLED_CMD_FDIR_MARK_JET p2 -> kind
PARAM_ID_LEN = 16


def _is_int_in(x: float, lo: int, hi: int) -> bool:
    return math.isfinite(x) and float(x).is_integer() and lo <= x <= hi


def _on_off(p: float, what: str, words: str) -> bool | Reply:
    if not _is_int_in(p, 0, 1):
        return CommandResult.DENIED, f"{what} {p:g} DENIED ({words})"
    return bool(p)


class CommandTranslator:
    """COMMAND_LONG -> FlightSoftware command API. ``inject`` forwards a fault injection
    to the plant (None: this vehicle has none to forward to)."""

    def __init__(self, fsw, inject: InjectFn | None = None) -> None:
        self.fsw = fsw
        self.inject = inject
        self.handlers: dict[int, Callable[[list[float]], Reply]] = {
            mav.MAV_CMD_INJECT_FAILURE: self._inject,
            mav.ELLIPSLED_CMD_SET_MODE: self._mode,
            mav.ELLIPSLED_CMD_ARM_JETS: self._arm,
            mav.MAV_CMD_COMPONENT_ARM_DISARM: self._arm,
            mav.ELLIPSLED_CMD_FAULT_TOLERANCE: self._fault_tolerance,
            mav.ELLIPSLED_CMD_FDIR_MARK_JET: self._mark,
            mav.ELLIPSLED_CMD_FDIR_CLEAR: self._clear,
            mav.ELLIPSLED_CMD_FDIR_SET_DELAY: self._delay,
        }

    def execute(self, command: int, params: list[float]) -> Reply:
        """(MAV_RESULT, reason) of one COMMAND_LONG; never raises."""
        handler = self.handlers.get(command)
        if handler is None:
            return CommandResult.UNSUPPORTED, f"CMD {command} UNSUPPORTED"
        try:
            result, why = handler(params)
            return int(result), why
        except Exception as e:                   # a bug must reach the ground as FAILED, not silence
            log.exception("command %d failed", command)
            return CommandResult.FAILED, f"CMD {command} FAILED: {type(e).__name__}"

    # -------------------------------------------------------------- one per command
    def _mode(self, p) -> Reply:
        if not _is_int_in(p[0], 0, 255) or int(p[0]) not in Mode._value2member_map_:
            return CommandResult.DENIED, f"MODE {p[0]:g} DENIED ({', '.join(f'{int(m)} {m.name}' for m in Mode)})"
        return self.fsw.cmd_mode(Mode(int(p[0])))

    def _arm(self, p) -> Reply:
        on = _on_off(p[0], "ARM", "1 ARM, 0 DISARM")
        return on if isinstance(on, tuple) else self.fsw.cmd_arm(on)

    def _fault_tolerance(self, p) -> Reply:
        on = _on_off(p[0], "FAULT TOLERANCE", "1 ON, 0 OFF")
        return on if isinstance(on, tuple) else self.fsw.cmd_fault_tolerance(on)

    def _mark(self, p) -> Reply:
        jet, code, eta = p[0], p[1], p[2]
        if not _is_int_in(jet, 1, N_JETS):
            return CommandResult.DENIED, f"MARK JET {jet:g} DENIED (1..{N_JETS})"
        if not _is_int_in(code, 0, 255) or int(code) not in MARK_NAMES:
            return CommandResult.DENIED, f"MARK KIND {code:g} DENIED (0..{max(MARK_NAMES)})"
        return self.fsw.cmd_mark(int(jet), MARK_NAMES[int(code)], float(eta))

    def _clear(self, p) -> Reply:
        if not _is_int_in(p[0], 0, N_JETS):
            return CommandResult.DENIED, f"CLEAR JET {p[0]:g} DENIED (0..{N_JETS})"
        return self.fsw.cmd_clear(int(p[0]))

    def _delay(self, p) -> Reply:
        return self.fsw.cmd_delay(p[0])

    def _inject(self, p) -> Reply:
        """MAV_CMD_INJECT_FAILURE, forwarded to the plant: ACCEPTED if ``inject`` took it,
        TEMPORARILY_REJECTED if it returned False (no plant now), DENIED if the plant
        refused the values (ValueError), FAILED on any other exception."""
        unit, ftype, jet, eta = p[0], p[1], p[2], p[3]
        if not _is_int_in(unit, 0, 1000) or int(unit) != mav.FAILURE_UNIT_SYSTEM_MOTOR:
            return CommandResult.UNSUPPORTED, f"INJECT UNIT {unit:g} UNSUPPORTED (101=JET)"
        if not _is_int_in(ftype, 0, 1000) or int(ftype) not in FAULT_NAMES:
            return CommandResult.UNSUPPORTED, f"INJECT TYPE {ftype:g} UNSUPPORTED"
        if not _is_int_in(jet, 0, N_JETS):
            return CommandResult.DENIED, f"INJECT JET {jet:g} DENIED (1..{N_JETS}, 0=ALL)"
        kind = FAULT_NAMES[int(ftype)]
        if kind == "degraded":
            if not (math.isfinite(eta) and 0.0 < eta < 1.0):
                return CommandResult.DENIED, f"INJECT ETA {eta:g} DENIED (0<ETA<1)"
            eta = float(eta)
        else:
            eta = 1.0
        if self.inject is None:
            return CommandResult.UNSUPPORTED, "INJECT UNSUPPORTED: NO PLANT LINK"
        jet = int(jet)
        try:
            ok = self.inject(jet, kind, eta)
        except ValueError as e:
            return CommandResult.DENIED, f"INJECT DENIED BY PLANT: {e}"
        if ok is not True:
            return CommandResult.TEMPORARILY_REJECTED, "INJECT REJECTED: PLANT UNAVAILABLE"
        self.fsw.events.emit(self.fsw.t_s, EV.INJECT, jets=jet, kind=int(ftype),
                             **({"eta": eta} if kind == "degraded" else {}))
        return CommandResult.ACCEPTED, ""


class ParamProtocol:
    """PARAM_REQUEST_LIST / _READ / PARAM_SET over the FlightSoftware's parameter registry:
    every ground-settable parameter, by its MAVLink id (matched case-insensitively) or its
    index in sorted-name order, as MAV_PARAM_TYPE_REAL32."""

    def __init__(self, fsw) -> None:
        self.fsw = fsw
        self.names: list[str] = fsw.registry.settable()                # index order
        self.id_of: dict[str, str] = fsw.registry.ids
        self._name_of_id = {pid.upper(): n for n, pid in self.id_of.items()}
        self._index = {n: i for i, n in enumerate(self.names)}

    def value_msg(self, name: str):
        return mav.MAVLink_param_value_message(self.id_of[name].encode("ascii"), float(self.fsw.params[name]),
                                               mav.MAV_PARAM_TYPE_REAL32, len(self.names), self._index[name])

    @staticmethod
    def id_text(raw) -> str:
        """A parameter id as received, for lookup and for the events that name it
        (control characters escaped: the event goes to the ground's terminals)."""
        return printable_text(raw.rstrip(b"\x00")[:PARAM_ID_LEN] if isinstance(raw, bytes)
                              else str(raw).rstrip("\x00")[:PARAM_ID_LEN])

    def lookup(self, raw_id) -> str | None:
        return self._name_of_id.get(self.id_text(raw_id).upper())

    def read(self, msg) -> tuple[str | None, str]:
        """(name, "") of a PARAM_REQUEST_READ, or (None, why) if unknown."""
        if msg.param_index >= 0:
            if msg.param_index >= len(self.names):
                return None, f"PARAM INDEX {msg.param_index} UNKNOWN"
            return self.names[msg.param_index], ""
        name = self.lookup(msg.param_id)
        return (name, "") if name is not None else (None, f"PARAM {self.id_text(msg.param_id)} UNKNOWN")

    def set(self, msg) -> tuple[str | None, str]:
        """Apply a PARAM_SET: (name, "") if set, (name, why) if refused (value unchanged),
        (None, why) if the id is unknown. Never raises."""
        name = self.lookup(msg.param_id)
        if name is None:
            return None, f"PARAM {self.id_text(msg.param_id)} UNKNOWN"
        try:
            self.fsw.set_param(name, float(msg.param_value))
        except ValueError as e:
            return name, f"{self.id_of[name]} REFUSED: {str(e).split(': ', 1)[-1]}"
        except Exception as e:                   # an owner's hook failed: say so, keep flying
            log.exception("setting %s failed", name)
            return name, f"{self.id_of[name]} FAILED: {type(e).__name__}"
        return name, ""
