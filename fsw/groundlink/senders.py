"""What the ground link keeps per address: the telemetry peers (made by signed commands,
forgotten after a timeout) and the read budgets of senders without the key (a token bucket
each). Plain bookkeeping over a clock the caller reads; no socket here."""
from __future__ import annotations

from collections import OrderedDict

Address = tuple[str, int]

READ_RATE_HZ = 50.0              # read-only requests and answer frames per second and unsigned sender ...
READ_BURST = 300.0               # ... after a burst of this many (a ground station connecting)
MAX_READ_SENDERS = 64            # unsigned senders whose read budget is remembered


class Peers:
    """Addresses that get the telemetry besides the ground station's: each one that sent an
    accepted signed command within ``timeout_s``, at most ``max_peers`` (the oldest go)."""

    def __init__(self, timeout_s: float, max_peers: int) -> None:
        self.timeout_s = float(timeout_s)
        self.max_peers = int(max_peers)
        self._last_t: dict[Address, float] = {}          # addr -> clock() of its last signed command

    def __contains__(self, addr) -> bool:
        return addr in self._last_t

    def __len__(self) -> int:
        return len(self._last_t)

    def add(self, addr: Address, now: float) -> bool:
        """``addr`` sent a signed command at ``now``; True if it was not a peer yet."""
        new = addr not in self._last_t
        self._last_t[addr] = now
        for a, t in list(self._last_t.items()):
            if now - t > self.timeout_s:
                del self._last_t[a]
        while len(self._last_t) > self.max_peers:
            oldest = min(self._last_t, key=self._last_t.get)
            del self._last_t[oldest]
        return new

    def destinations(self, gcs: Address, now: float, extra: Address | None = None) -> list[Address]:
        """Where a telemetry frame goes at ``now``: ``gcs``, every live peer, and ``extra``."""
        dest = [gcs]
        for a, t in self._last_t.items():
            if now - t <= self.timeout_s and a not in dest:
                dest.append(a)
        if extra is not None and extra not in dest:
            dest.append(extra)
        return dest


class ReadBudgets:
    """The read budget of each sender without the key: a token bucket of READ_RATE_HZ units a
    second, burst READ_BURST; the last MAX_READ_SENDERS senders remembered."""

    def __init__(self) -> None:
        self._buckets: OrderedDict[Address, list[float]] = OrderedDict()   # sender -> [tokens, t]

    def take(self, addr: Address, now: float) -> bool:
        """One unit of ``addr``'s budget at ``now``, if it has one."""
        b = self._buckets.get(addr)
        if b is None:
            if len(self._buckets) >= MAX_READ_SENDERS:
                self._buckets.popitem(last=False)
            b = self._buckets[addr] = [READ_BURST, now]
        else:
            self._buckets.move_to_end(addr)
            b[0] = min(READ_BURST, b[0] + (now - b[1]) * READ_RATE_HZ)
            b[1] = now
        if b[0] >= 1.0:
            b[0] -= 1.0
            return True
        return False

    def give_back(self, addr: Address, units: float) -> None:
        """Return ``units`` taken but not used (``addr`` has taken some before)."""
        self._buckets[addr][0] += units
