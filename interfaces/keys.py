"""Zenoh key expressions: every topic of a run lives under one prefix, ``ellipsled/<vehicle>``.

The suffixes below are the one definition of each topic (docs/interfaces/index.md, Zenoh
table); the codec registry (interfaces/codec.py) names its topic by these constants.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

ROOT = "ellipsled"

SENSORS = "sim/sensors"     # sim -> fsw
JETS = "fsw/jets"           # fsw -> sim
FAULTS = "sim/faults"       # fsw or test harness -> sim
FAULT_LOG = "sim/fault_log" # sim -> fsw in oracle identification (a test mode): every fault the plant applied
TRUTH = "sim/truth"         # sim -> viewers
STATE = "fsw/state"         # fsw -> viewers
EVENTS = "fsw/events"       # fsw -> viewers, ground
ALIVE = "alive"             # liveliness tokens: alive/<role>

ROLES = ("sim", "fsw", "bridge", "console")

# The prefix every process uses when not told otherwise (sim, fsw, the launcher, the viewer):
# processes started by hand with their defaults find each other
DEFAULT_PREFIX = f"{ROOT}/ellipsled"

# A vehicle / run name is one key chunk: no '/', no wildcard or special characters.
_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")


@dataclass(frozen=True)
class Keys:
    prefix: str          # e.g. "ellipsled/ellipsled-1"
    sensors: str
    jets: str
    faults: str
    fault_log: str
    truth: str
    state: str
    events: str
    alive_sim: str
    alive_fsw: str
    alive_bridge: str
    alive_console: str
    alive_any: str       # wildcard over every liveliness token of this prefix
    ready_fsw: str       # the FSW's second token: warmed up, its real-time loop about to lock on

    def alive(self, role: str) -> str:
        if role not in ROLES:
            raise ValueError(f"liveliness role: {role!r} not one of {ROLES}")
        return f"{self.prefix}/{ALIVE}/{role}"

    def topic(self, suffix: str) -> str:
        """The full key of a topic suffix (e.g. keys.SENSORS)."""
        return f"{self.prefix}/{suffix}"


def keys(prefix_or_vehicle: str) -> Keys:
    """Keys for a vehicle name ("ellipsled-1" -> "ellipsled/ellipsled-1/...") or for an
    explicit prefix that already starts with "ellipsled/" (e.g. "ellipsled/run42")."""
    if not isinstance(prefix_or_vehicle, str) or not prefix_or_vehicle:
        raise ValueError(f"key prefix: must be a non-empty string, got {prefix_or_vehicle!r}")
    p = prefix_or_vehicle.strip("/")
    chunks = p.split("/")
    if chunks[0] != ROOT or len(chunks) == 1:
        chunks = [ROOT] + chunks
    for c in chunks:
        if not _CHUNK.match(c):
            raise ValueError(f"key prefix: chunk {c!r} of {prefix_or_vehicle!r} must match "
                             f"[A-Za-z0-9_.-]+ (no wildcards, no empty chunks)")
    prefix = "/".join(chunks)
    return Keys(
        prefix=prefix,
        sensors=f"{prefix}/{SENSORS}",
        jets=f"{prefix}/{JETS}",
        faults=f"{prefix}/{FAULTS}",
        fault_log=f"{prefix}/{FAULT_LOG}",
        truth=f"{prefix}/{TRUTH}",
        state=f"{prefix}/{STATE}",
        events=f"{prefix}/{EVENTS}",
        alive_sim=f"{prefix}/{ALIVE}/sim",
        alive_fsw=f"{prefix}/{ALIVE}/fsw",
        alive_bridge=f"{prefix}/{ALIVE}/bridge",
        alive_console=f"{prefix}/{ALIVE}/console",
        alive_any=f"{prefix}/{ALIVE}/*",
        ready_fsw=f"{prefix}/{ALIVE}/fsw/ready",
    )
