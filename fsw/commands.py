"""The flight software's command API: what the ground may ask of it, judged here.

The ground link (fsw/groundlink/commands.py) translates MAVLink to these calls and checks only
what is MAVLink's; every request is judged here. Each returns (CommandResult, reason): the
reason says why a request was refused, for the operator; nothing here raises on a bad
request. A command acts between control cycles (the executive runs the ground link in the
same thread as the loop), so it holds from the next cycle.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from common.events import EventLog
from interfaces.vocabulary import MARK_KINDS, N_JETS, CommandResult
from interfaces.event_catalogue import EV

from .modes import Mode

if TYPE_CHECKING:
    from .fdir import Fdir
    from .jetdriver import JetDriver
    from .modes import ModeManager
    from .params import ParamRegistry

Reply = tuple[CommandResult, str]
_MODE_CHOICES = ",".join(f"{int(m)} {m.name}" for m in Mode)


class GroundCommands:
    """The ``cmd_*`` methods and ``set_param`` of FlightSoftware (mixed into it). They act on
    its mode manager, jet driver, FDIR and parameter registry at its mission time ``t_s``; a
    change of jet health ends in its ``health_changed``."""

    modes: ModeManager
    driver: JetDriver
    fdir: Fdir
    registry: ParamRegistry
    events: EventLog
    t_s: float

    def health_changed(self) -> None:
        """FlightSoftware's: the allocator and the authority supervisor take the new health."""
        raise NotImplementedError

    def cmd_mode(self, mode) -> Reply:
        """Request a mode (Mode, its number or name); entering ENTRY arms the jets when
        driver.arm_on_entry is set."""
        try:
            target = Mode[mode.upper()] if isinstance(mode, str) else Mode(int(mode))
        except (KeyError, ValueError, TypeError, AttributeError):
            return CommandResult.DENIED, f"MODE {mode!s:.12} DENIED ({_MODE_CHOICES})"
        before = self.modes.mode
        if not self.modes.request(self.t_s, target, "ground"):
            return CommandResult.DENIED, ""              # ModeManager already said why
        if target == Mode.ENTRY and before != Mode.ENTRY:
            self.driver.entering_entry(self.t_s)
        return CommandResult.ACCEPTED, ""

    def cmd_arm(self, on: bool) -> Reply:
        self.driver.arm(self.t_s, bool(on))
        return CommandResult.ACCEPTED, ""

    def cmd_fault_tolerance(self, on: bool) -> Reply:
        self.set_param("allocator.fault_tolerance", float(bool(on)))
        self.events.emit(self.t_s, EV.FAULT_TOLERANCE, state=int(bool(on)))
        return CommandResult.ACCEPTED, ""

    def cmd_mark(self, jet: int, kind: str, eta: float = 1.0) -> Reply:
        """Operator override of one jet's health (a MARK_KINDS word); "inhibited" sets the
        inhibit mask instead. The allocator adopts it now."""
        if not _jet_in(jet, 1):
            return CommandResult.DENIED, f"MARK JET {jet} DENIED (1..{N_JETS})"
        if kind not in MARK_KINDS:
            return CommandResult.DENIED, f"MARK KIND {kind!s:.12} DENIED"
        jet = int(jet)
        if kind == "inhibited":
            return self.cmd_inhibit(jet, True)
        if kind == "degraded" and not (isinstance(eta, (int, float)) and math.isfinite(eta) and 0.0 < eta < 1.0):
            return CommandResult.DENIED, f"MARK ETA {eta:g} DENIED (0<ETA<1)"
        try:
            self.fdir.override(self.t_s, jet, kind, float(eta) if kind == "degraded" else 1.0)
        except ValueError as e:
            return CommandResult.DENIED, f"MARK DENIED: {e}"
        self.health_changed()
        return CommandResult.ACCEPTED, ""

    def cmd_inhibit(self, jet: int, on: bool) -> Reply:
        """The ground inhibit mask (jet 0 = all): the driver never fires the jet and the
        allocator no longer plans with it."""
        if not _jet_in(jet, 0):
            return CommandResult.DENIED, f"INHIBIT JET {jet} DENIED (0..{N_JETS})"
        self.driver.set_inhibit(self.t_s, int(jet), bool(on))
        self.fdir.set_inhibit(self.t_s, int(jet), bool(on))
        self.health_changed()
        return CommandResult.ACCEPTED, ""

    def cmd_clear(self, jet: int) -> Reply:
        """FDIR latch, pending reconfiguration, override and inhibit of ``jet`` (0 = all) cleared."""
        if not _jet_in(jet, 0):
            return CommandResult.DENIED, f"CLEAR JET {jet} DENIED (0..{N_JETS})"
        self.fdir.clear(self.t_s, int(jet))
        return self.cmd_inhibit(jet, False)

    def cmd_delay(self, delay_s: float) -> Reply:
        """FDIR isolation-to-reconfiguration delay for detections from now on."""
        try:
            v = self.set_param("fdir.delay_s", delay_s)
        except ValueError as e:
            return CommandResult.DENIED, f"DELAY DENIED: {str(e).split(': ', 1)[-1]}"
        self.events.emit(self.t_s, EV.FDIR_DELAY, delay_s=v)
        return CommandResult.ACCEPTED, ""

    def set_param(self, name: str, value: float) -> float:
        """Validated parameter set, applied by its owner; ValueError (nothing changed) when
        refused (fsw/params.py ParamRegistry)."""
        return self.registry.set(name, value)


def _jet_in(jet, lo: int) -> bool:
    """A jet number lo..N_JETS given as an integer or an integral float (a MAVLink param)."""
    try:
        return float(jet).is_integer() and lo <= jet <= N_JETS and not isinstance(jet, bool)
    except (TypeError, ValueError, OverflowError):
        return False
