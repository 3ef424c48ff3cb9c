"""Jet health as the FSW believes it (from FDIR and ground overrides); the allocator's input."""
from __future__ import annotations

import numpy as np

from interfaces.vocabulary import DEGRADED, FAILED_OFF, N_JETS, NOMINAL, STUCK_ON


class JetHealth:
    """Per-jet state (NOMINAL / FAILED_OFF / STUCK_ON / DEGRADED), thrust factor eta, and
    the ground inhibit mask (states: interfaces/vocabulary.py). Arrays are indexed by jet - 1."""

    __slots__ = ("state", "eta", "inhibited")

    def __init__(self, n: int = N_JETS):
        self.state = np.zeros(n, dtype=np.int8)
        self.eta = np.ones(n)
        self.inhibited = np.zeros(n, dtype=bool)

    @classmethod
    def of(cls, failed_off=(), stuck_on=(), degraded=(), inhibited=()) -> "JetHealth":
        """A configuration from 1-based jet lists; ``degraded`` holds (jet, eta) pairs."""
        h = cls()
        for j in failed_off:
            h.set(j, FAILED_OFF)
        for j in stuck_on:
            h.set(j, STUCK_ON)
        for j, eta in degraded:
            h.set(j, DEGRADED, eta)
        for j in inhibited:
            h.inhibited[j - 1] = True
        return h

    def copy(self) -> "JetHealth":
        h = JetHealth(len(self.state))
        h.state[:] = self.state
        h.eta[:] = self.eta
        h.inhibited[:] = self.inhibited
        return h

    def key(self) -> tuple:
        """Hashable identity of this configuration (for caching allocator tables)."""
        return (self.state.tobytes(), np.round(self.eta, 12).tobytes(), self.inhibited.tobytes())

    def __eq__(self, other) -> bool:
        return isinstance(other, JetHealth) and self.key() == other.key()

    def usable(self) -> np.ndarray:
        """Jets the allocator may switch: nominal or degraded, not inhibited."""
        return ((self.state == NOMINAL) | (self.state == DEGRADED)) & ~self.inhibited

    def effective_eta(self) -> np.ndarray:
        """Thrust factor per jet as the allocator models it (0 for failed_off, 1 for stuck_on)."""
        e = np.where(self.state == DEGRADED, self.eta, 1.0)
        return np.where(self.state == FAILED_OFF, 0.0, e)

    def set(self, jet: int, state: int, eta: float = 1.0) -> None:
        """jet is 1-based."""
        self.state[jet - 1] = state
        self.eta[jet - 1] = eta if state == DEGRADED else 1.0
