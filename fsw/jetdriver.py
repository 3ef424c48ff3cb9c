"""Jet driver (docs/fsw/index.md "Jet driver"): arming, the ground inhibit mask and the mode
gate; the command holds for exactly one control period; pulse, on-time and propellant
bookkeeping; remembers what it sent for FDIR.

Bookkeeping counts what was *commanded*: a jet stuck on in the plant burns propellant the
driver does not see (FDIR's health says so instead).

Events (source "driver", NOTICE): "JETS ARMED" / "JETS DISARMED" on a change of arming,
"JET 5 INHIBITED" / "JET 5 INHIBIT CLEARED" (jet 0 = "ALL JETS") on a change of the mask.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from common.events import EventLog
from interfaces.event_catalogue import EV
from .params import Param


@njit(cache=True)
def drive_jets(u_on, gate, inhibit, last, pulses, on_time_s, mdot_kgps, dt_s):
    """Write the command into ``last`` (uint8), count 0->1 transitions against the previous
    content of ``last``, add on-time; returns the propellant used over this period [kg]."""
    used = 0.0
    for k in range(last.shape[0]):
        on = gate and u_on[k] != 0 and not inhibit[k]
        if on:
            if last[k] == 0:
                pulses[k] += 1
            on_time_s[k] += dt_s
            used += mdot_kgps[k]
            last[k] = 1
        else:
            last[k] = 0
    return used * dt_s


@njit(cache=True)
def ring_views(jb, jc):
    """The ring of answers in ``JetDriver.packed``'s buffers: (the answers, their frame indices)."""
    return jb[2:], jc[jb.shape[1]:]


@njit(cache=True)
def packed_views(jb, jc, jr):
    """``JetDriver.packed``'s buffers as the arrays they hold: (inhibit, the command in force,
    pulses, on-time [s], propellant flow [kg/s], dt [s], the ring's answers, their frame indices)."""
    n = jb.shape[1]
    sent, sent_k = ring_views(jb, jc)
    return jb[0], jb[1], jc[:n], jr[:n], jr[n:2 * n], jr[2 * n], sent, sent_k


class JetDriver:
    PARAMS = [
        Param("driver.arm_on_entry", 0, 1, "-", "1 = a ground request that enters ENTRY also arms the jets",
              integer=True),
    ]

    def __init__(self, thrust_N: np.ndarray, isp_s: float, g0_mps2: float, dt_s: float, events: EventLog,
                 ring: int = 0) -> None:
        """``ring``: rows of the ring of answers its owner notes by frame index (``sent``, ``sent_k``;
        fsw/flightsoftware.py ``note_sent``), kept in this driver's buffers."""
        thrust_N = np.asarray(thrust_N, dtype=float)
        if thrust_N.ndim != 1 or thrust_N.size == 0 or not np.all(np.isfinite(thrust_N)) or np.any(thrust_N < 0):
            raise ValueError("thrust_N: must be a 1-D array of finite values >= 0")
        for name, v in (("isp_s", isp_s), ("g0_mps2", g0_mps2), ("dt_s", dt_s)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be finite and > 0, got {v!r}")
        n = thrust_N.size
        self.n = n
        self.dt_s = float(dt_s)
        self.events = events
        self.thrust_N = thrust_N.copy()
        self.armed = False
        self.arm_on_entry = True
        self._params = {p.name: p for p in self.PARAMS}
        # the arrays a cycle's tail reads and writes, in three buffers by type (a compiled caller
        # takes three arguments, not nine: ``packed``); the names are views into them
        ring = int(ring)
        self._bytes = np.zeros((2 + ring, n), dtype=np.uint8)
        self.inhibit = self._bytes[0].view(np.bool_)
        self.last_command = self._bytes[1]                    # the command in force (sent last)
        self.sent = self._bytes[2:]
        self._counts = np.zeros(n + ring, dtype=np.int64)
        self.pulses = self._counts[:n]
        self.sent_k = self._counts[n:]
        self.sent_k[:] = -2                                   # no frame answered
        self._reals = np.zeros(2 * n + 1)
        self.on_time_s = self._reals[:n]
        self._reals[n:2 * n] = thrust_N / (isp_s * g0_mps2)   # per jet, while on
        self._mdot_kgps = self._reals[n:2 * n]
        self._reals[2 * n] = self.dt_s
        self.propellant_kg = 0.0
        self.seq = 0                                          # commands issued
        self._u8 = np.zeros(n, dtype=np.uint8)

    def _check_jet(self, jet) -> int:
        if isinstance(jet, bool) or not isinstance(jet, (int, np.integer)) or not 0 <= int(jet) <= self.n:
            raise ValueError(f"jet: must be an integer in 0..{self.n} (0 = all), got {jet!r}")
        return int(jet)

    def arm(self, t_s: float, on: bool) -> None:
        on = bool(on)
        if on != self.armed:
            self.armed = on
            self.events.emit(t_s, EV.JETS_ARMED if on else EV.JETS_DISARMED)

    def set_param(self, name: str, value: float) -> float:
        """Owner's hook (driver.arm_on_entry)."""
        if name != "driver.arm_on_entry":
            raise ValueError(f"{name}: not a jet-driver parameter")
        v = self._params[name].check(value)
        self.arm_on_entry = bool(v)
        return v

    def entering_entry(self, t_s: float) -> None:
        """The mode has just become ENTRY by request: arm if ``arm_on_entry``."""
        if self.arm_on_entry:
            self.arm(t_s, True)

    def set_inhibit(self, t_s: float, jet: int, on: bool) -> None:
        """Ground inhibit mask; jet is 1-based, 0 = all jets."""
        jet = self._check_jet(jet)
        on = bool(on)
        sel = slice(None) if jet == 0 else slice(jet - 1, jet)
        if np.all(self.inhibit[sel] == on):
            return
        self.inhibit[sel] = on
        self.events.emit(t_s, EV.JET_INHIBIT, jets=jet, inhibit=on)

    def packed(self) -> tuple:
        """The driver's state in three buffers, made once and only ever written in place, for a
        compiled caller that drives the jets inside its own kernel (fsw/flightsoftware.py
        ``finish_cycle``, through ``packed_views``): uint8 rows (inhibit, the command in force,
        the ring's answers), int64 (pulses, the ring's frame indices), float64 (on-time,
        propellant flow per jet, dt). The caller adds what ``drive_jets`` returns to
        ``propellant_kg`` and counts ``seq`` as ``command`` does."""
        return self._bytes, self._counts, self._reals

    def command(self, u_alloc: np.ndarray, jets_enabled: bool) -> np.ndarray:
        """The command actually sent for the next period: u_alloc (> 0.5 = on; NaN = off)
        unless disarmed or not enabled by the mode, inhibited jets off. Returns
        ``last_command`` (uint8, preallocated and overwritten by the next call)."""
        u = np.asarray(u_alloc)
        if u.shape != (self.n,):
            raise ValueError(f"u_alloc: must have shape ({self.n},), got {u.shape}")
        if u.dtype != np.uint8:
            np.greater(u, 0.5, out=self._u8, casting="unsafe")      # NaN -> off
            u = self._u8
        self.count(drive_jets(u, self.armed and bool(jets_enabled), self.inhibit, self.last_command,
                          self.pulses, self.on_time_s, self._mdot_kgps, self.dt_s))
        return self.last_command

    def count(self, used_kg: float) -> None:
        """One command issued, using ``used_kg`` of propellant (what ``drive_jets`` returned)."""
        self.propellant_kg += used_kg
        self.seq += 1
