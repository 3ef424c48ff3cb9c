"""The words every process shares: jet count, jet health states, fault kinds, modes,
event severities and the default ground-link endpoints. The one definition; fsw/, sim/
and gse/ import them from here (tests/test_vocabulary.py fails on a second copy).

The jet count, the health states and the modes are read from the MAVLink dialect
(interfaces/mavlink/ellipsled.xml), the wire's own definition, so Python and the ground
station cannot disagree; numbers that MAVLink's common.xml fixes (MAV_SEVERITY,
FAILURE_TYPE) are written here and checked against the generated bindings by the test.
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from enum import IntEnum
from pathlib import Path

DIALECT_XML = Path(__file__).with_name("mavlink") / "ellipsled.xml"
_DIALECT = ET.parse(DIALECT_XML).getroot()


def _enum(name: str) -> dict[str, int]:
    """{short name: value} of a dialect enum, its "<NAME>_" prefix removed."""
    for e in _DIALECT.iter("enum"):
        if e.get("name") == name:
            return {x.get("name").removeprefix(name + "_"): int(x.get("value")) for x in e.iter("entry")}
    raise LookupError(f"{DIALECT_XML}: no enum {name}")


def _array_len(message: str, field: str) -> int:
    for m in _DIALECT.iter("message"):
        if m.get("name") == message:
            for f in m.iter("field"):
                if f.get("name") == field:
                    return int(re.fullmatch(r"\w+\[(\d+)\]", f.get("type")).group(1))
    raise LookupError(f"{DIALECT_XML}: no field {message}.{field}")


# ---- jets: numbered 1..N_JETS in text and commands, 0..N_JETS-1 in arrays
N_JETS: int = _array_len("ELLIPSLED_JET_STATUS", "health")

# ---- jet health (ELLIPSLED_JET_HEALTH): the FSW's belief, the plant's fault state and the
# wire share these codes. INHIBITED is the ground's inhibit mask, shown on the wire only.
# A state has one word everywhere (code, scenario files, commands, telemetry labels, docs):
# its dialect name in lower case, e.g. "failed_off"; tests/test_jet_state_words.py keeps it so.
JetState = IntEnum("JetState", _enum("ELLIPSLED_JET_HEALTH"), module=__name__)
NOMINAL: int = int(JetState.NOMINAL)
FAILED_OFF: int = int(JetState.FAILED_OFF)
STUCK_ON: int = int(JetState.STUCK_ON)
DEGRADED: int = int(JetState.DEGRADED)
INHIBITED: int = int(JetState.INHIBITED)
HEALTH_NAMES: dict[int, str] = {int(s): s.name.lower() for s in JetState}     # 1 -> "failed_off"

# What an operator may mark a jet as (ELLIPSLED_CMD_FDIR_MARK_JET): a health state by its
# word; marking a jet "nominal" makes FDIR's allocator view use it as nominal.
MARK_KINDS: dict[str, int] = {n: c for c, n in HEALTH_NAMES.items()}           # "failed_off" -> 1

# ---- fault injection into the plant (MAV_CMD_INJECT_FAILURE): the health state a fault puts
# the jet in -> MAVLink FAILURE_TYPE (OK, OFF, STUCK, WRONG); "nominal" removes a fault.
_FAILURE_TYPE: dict[int, int] = {NOMINAL: 0, FAILED_OFF: 1, STUCK_ON: 2, DEGRADED: 4}
FAULT_KINDS: dict[str, int] = {HEALTH_NAMES[h]: ft for h, ft in _FAILURE_TYPE.items()}    # kind -> FAILURE_TYPE
FAULT_HEALTH: dict[str, int] = {HEALTH_NAMES[h]: h for h in _FAILURE_TYPE}               # kind -> health code

# Jet-state words retired for the one word above: refused on input, naming the new word.
RETIRED_STATE_WORDS: dict[str, str] = {"off": HEALTH_NAMES[FAILED_OFF], "stuck": HEALTH_NAMES[STUCK_ON],
                                       "clear": HEALTH_NAMES[NOMINAL], "healthy": HEALTH_NAMES[NOMINAL]}


def renamed(word, valid) -> str:
    """" (renamed 'failed_off')" when ``word`` is a retired jet-state word whose replacement is
    one of ``valid``; "" otherwise."""
    new = RETIRED_STATE_WORDS.get(str(word).lower())
    return f" (renamed {new!r})" if new in valid else ""


def refuse_state_word(word, valid) -> str:
    """Why ``word`` is refused where one of the jet-state words ``valid`` was expected: the
    valid words, and for a retired word the one that replaced it."""
    valid = list(valid)
    return f"must be one of {', '.join(valid)}; got {word!r}{renamed(word, valid)}"


# ---- flight-software modes (ELLIPSLED_MODE; HEARTBEAT.custom_mode)
Mode = IntEnum("Mode", _enum("ELLIPSLED_MODE"), module=__name__)
Mode.__doc__ = "Flight-software mode (docs/fsw/index.md Modes): STANDBY, ENTRY, SAFE."


# ---- event severities: MAVLink MAV_SEVERITY numbering, so STATUSTEXT carries them 1:1
class Severity(IntEnum):
    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6
    DEBUG = 7


# ---- command results: MAVLink MAV_RESULT numbering, so COMMAND_ACK carries them 1:1
class CommandResult(IntEnum):
    ACCEPTED = 0                # done
    TEMPORARILY_REJECTED = 1    # valid, but cannot be done now; the ground may retry
    DENIED = 2                  # a parameter is invalid, or the request is not allowed now
    UNSUPPORTED = 3             # this vehicle does not do that
    FAILED = 4                  # valid and allowed, but executing it failed


# ---- ground link endpoints: the vehicle listens on VEHICLE, sends telemetry to GCS
DEFAULT_GCS = "udp:127.0.0.1:14550"
DEFAULT_VEHICLE = "udp:127.0.0.1:14555"


def parse_udp(spec: str, what: str) -> tuple[str, int]:
    """"udp:HOST:PORT" (or "HOST:PORT") -> (host, port); ValueError naming ``what``."""
    if not isinstance(spec, str):
        raise ValueError(f"{what}: expected 'udp:HOST:PORT', got {spec!r}")
    s = spec[4:] if spec.startswith("udp:") else spec
    host, sep, port = s.rpartition(":")
    if not sep or not host:
        raise ValueError(f"{what}: expected 'udp:HOST:PORT', got {spec!r}")
    try:
        p = int(port)
    except ValueError:
        raise ValueError(f"{what}: port must be an integer, got {port!r}") from None
    if not 0 <= p <= 65535:
        raise ValueError(f"{what}: port must be in 0..65535, got {p}")
    return host, p


__all__ = ["N_JETS", "JetState", "NOMINAL", "FAILED_OFF", "STUCK_ON", "DEGRADED", "INHIBITED", "HEALTH_NAMES",
           "MARK_KINDS", "FAULT_KINDS", "FAULT_HEALTH", "RETIRED_STATE_WORDS", "renamed", "refuse_state_word", "Mode", "Severity",
           "CommandResult", "DEFAULT_GCS", "DEFAULT_VEHICLE", "parse_udp"]
