"""The ground link's own MAVLink services — what a ground station asks of any vehicle at
connect, answered by the link without touching the flight software's state:

- message intervals: MAV_CMD_SET_MESSAGE_INTERVAL / MAV_CMD_GET_MESSAGE_INTERVAL on the
  link's telemetry streams (a new rate takes effect at the next tick; no faster than the
  link ticks);
- one-shot requests: MAV_CMD_REQUEST_MESSAGE for every message the vehicle produces,
  MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, MAV_CMD_REQUEST_PROTOCOL_VERSION;
- identity: AUTOPILOT_VERSION (capability bits only for what the link does, the version,
  vendor and product ids), PROTOCOL_VERSION;
- the modes by name: AVAILABLE_MODES (MAV_CMD_REQUEST_MESSAGE param2: 0 all, else the index);
- the mission list of a vehicle without missions: MISSION_COUNT 0.

Each command is judged here and answered as (MAV_RESULT, reason, replies, broadcast); the
link sends the COMMAND_ACK, then the replies. Nothing here raises on a field's value: a
non-finite, non-integral or out-of-range field is DENIED with the reason.
"""
from __future__ import annotations

import hashlib
import math
from pathlib import Path

from interfaces.mavlink import dialect as mav
from interfaces.vocabulary import CommandResult

from . import telemetry as tm
from .metadata import firmware_version

# AUTOPILOT_VERSION.vendor_id / product_id: the project's own (MAVLink keeps no registry of
# them; they are not USB ids): "EL" and 1, the flight software of this vehicle.
VENDOR_ID = 0x454C
PRODUCT_ID = 0x0001
MAVLINK_VERSION = 200                    # MAVLink 2 only: the intake refuses MAVLink 1 frames
MSG_ID_MAX = 0xFFFFFF                    # message ids are 24 bits

# What the link implements, and nothing else (MAV_PROTOCOL_CAPABILITY). PARAM_FLOAT and
# PARAM_ENCODE_C_CAST: every parameter is MAV_PARAM_TYPE_REAL32 and its value is sent as
# that float (integers cast); COMMAND_INT: handled as COMMAND_LONG is; FTP: the read-only
# subset that serves the component metadata (ftp.py); MISSION_INT: the mission protocol's
# list, in its MISSION_ITEM_INT form, of zero items (the vehicle flies no missions; a ground
# station refuses to download from a vehicle without it). MAVLink signing has
# no capability bit; the link requires it for commands and writes.
CAPABILITIES = (mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2 | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
                | mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
                | mav.MAV_PROTOCOL_CAPABILITY_FTP | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT)

COMMANDS = frozenset({mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_SET_MESSAGE_INTERVAL,
                      mav.MAV_CMD_GET_MESSAGE_INTERVAL, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
                      mav.MAV_CMD_REQUEST_PROTOCOL_VERSION})

# MAV_CMD_REQUEST_MESSAGE param7, response target
TARGET_DEFAULT, TARGET_REQUESTER, TARGET_BROADCAST = 0, 1, 2

Answer = tuple[int, str, list, bool]       # (MAV_RESULT, reason, replies, broadcast)


def _int_in(x: float, lo: int, hi: int) -> bool:
    return math.isfinite(x) and float(x).is_integer() and lo <= x <= hi


def flight_sw_version() -> int:
    """AUTOPILOT_VERSION.flight_sw_version: major << 24 | minor << 16 | patch << 8 | type,
    of the version the metadata gives (metadata.firmware_version)."""
    major, minor, patch = (int(x) & 0xFF for x in firmware_version().split("."))
    return major << 24 | minor << 16 | patch << 8 | mav.FIRMWARE_VERSION_TYPE_DEV


def source_digest() -> bytes:
    """8 bytes identifying the flight software build: SHA-256 over the sources of fsw/ and
    interfaces/ (the code that flies and the words it speaks), in path order."""
    root = Path(__file__).resolve().parents[2]
    h = hashlib.sha256()
    for sub in ("fsw", "interfaces"):
        for p in sorted((root / sub).rglob("*")):
            if p.suffix in (".py", ".xml") and "__pycache__" not in p.parts:
                h.update(p.relative_to(root).as_posix().encode())
                h.update(p.read_bytes())
    return h.digest()[:8]


class LinkServices:
    """The services above, over one GroundLink's stream schedule (``link.rates_hz``,
    ``link.schedule_now``, ``link.stream_messages``)."""

    def __init__(self, link, extra: dict | None = None) -> None:
        self.link = link
        self.default_rates = dict(link.rates_hz)
        self.stream_of_id = {getattr(mav, "MAVLINK_MSG_ID_" + name): name for name in link.rates_hz}
        # one-shot messages that are not streams: id -> (params) -> messages (empty: none yet),
        # or a reason to deny the request
        self.oneshot = {mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION: lambda p: [self.autopilot_version()],
                        mav.MAVLINK_MSG_ID_PROTOCOL_VERSION: lambda p: [self.protocol_version()],
                        mav.MAVLINK_MSG_ID_AVAILABLE_MODES: self._available_modes}
        self.oneshot.update(extra or {})
        self._version = flight_sw_version()
        self._custom = list(source_digest())

    # ------------------------------------------------------------------ identity
    def autopilot_version(self):
        z8 = [0] * 8
        return mav.MAVLink_autopilot_version_message(CAPABILITIES, self._version, 0, 0, 0, self._custom, z8, z8,
                                                     VENDOR_ID, PRODUCT_ID, 0, [0] * 18)

    @staticmethod
    def _available_modes(p) -> list | str:
        n = len(tm.available_modes())
        if not _int_in(p[1], 0, n):
            return f"REQUEST MODES {p[1]:g} DENIED (0 ALL, 1..{n})"
        return tm.available_modes(int(p[1]))

    @staticmethod
    def protocol_version():
        z8 = [0] * 8
        return mav.MAVLink_protocol_version_message(MAVLINK_VERSION, MAVLINK_VERSION, MAVLINK_VERSION, z8, z8)

    @staticmethod
    def mission_count(msg):
        """A mission list request (any mission type): this vehicle has no items."""
        return mav.MAVLink_mission_count_message(msg.get_srcSystem(), msg.get_srcComponent(), 0, msg.mission_type)

    # ------------------------------------------------------------------ commands
    def execute(self, command: int, p: list[float]) -> Answer:
        try:
            if command == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
                return self._set_interval(p)
            if command == mav.MAV_CMD_GET_MESSAGE_INTERVAL:
                return self._get_interval(p)
            if command == mav.MAV_CMD_REQUEST_MESSAGE:
                return self._request_message(p)
            if command == mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
                return self._flag_request(p, "CAPABILITIES", self.autopilot_version)
            if command == mav.MAV_CMD_REQUEST_PROTOCOL_VERSION:
                return self._flag_request(p, "PROTOCOL VERSION", self.protocol_version)
        except Exception as e:                 # a bug must reach the ground as FAILED, not silence
            return CommandResult.FAILED, f"CMD {command} FAILED: {type(e).__name__}", [], False
        return CommandResult.UNSUPPORTED, f"CMD {command} UNSUPPORTED", [], False

    def _msg_id(self, x: float, what: str) -> int | str:
        if not _int_in(x, 0, MSG_ID_MAX):
            return f"{what} MSG ID {x:g} DENIED"
        return int(x)

    def _set_interval(self, p) -> Answer:
        mid = self._msg_id(p[0], "INTERVAL")
        if isinstance(mid, str):
            return CommandResult.DENIED, mid, [], False
        name = self.stream_of_id.get(mid)
        if name is None:
            return CommandResult.DENIED, f"INTERVAL MSG {mid} DENIED: NOT STREAMED", [], False
        us, fastest = p[1], self.link.max_rate_hz
        if not math.isfinite(us) or (us < 0 and us != -1):
            return CommandResult.DENIED, f"INTERVAL {us:g} US DENIED (-1 OFF, 0 DEFAULT, >0)", [], False
        if us == -1:
            hz = 0.0
        elif us == 0:
            hz = self.default_rates[name]
        else:
            hz = 1e6 / us
            if hz > fastest * (1.0 + 1e-9):
                return CommandResult.DENIED, f"INTERVAL {us:g} US DENIED (MIN {1e6 / fastest:.0f})", [], False
        self.link.rates_hz[name] = hz
        self.link.schedule_now(name)
        return CommandResult.ACCEPTED, "", [], False

    def interval_us(self, mid: int) -> int:
        """MESSAGE_INTERVAL.interval_us: -1 disabled, 0 not available, else the period."""
        name = self.stream_of_id.get(mid)
        if name is None:
            return 0
        hz = self.link.rates_hz[name]
        return -1 if hz <= 0.0 else int(round(1e6 / hz))

    def _get_interval(self, p) -> Answer:
        mid = self._msg_id(p[0], "GET INTERVAL")
        if isinstance(mid, str):
            return CommandResult.DENIED, mid, [], False
        return CommandResult.ACCEPTED, "", [mav.MAVLink_message_interval_message(mid, self.interval_us(mid))], False

    def _request_message(self, p) -> Answer:
        mid = self._msg_id(p[0], "REQUEST")
        if isinstance(mid, str):
            return CommandResult.DENIED, mid, [], False
        if math.isnan(p[6]) or math.isnan(p[1]):       # a param left unused (NaN, as MAVSDK sends it): 0
            p = list(p)
            p[1], p[6] = (0.0 if math.isnan(x) else x for x in (p[1], p[6]))
        if not _int_in(p[6], 0, 2):
            return CommandResult.DENIED, f"REQUEST TARGET {p[6]:g} DENIED (0, 1, 2)", [], False
        broadcast = int(p[6]) == TARGET_BROADCAST
        if mid in self.oneshot:
            msgs = self.oneshot[mid](p)
            if isinstance(msgs, str):
                return CommandResult.DENIED, msgs, [], False
            if not msgs:
                return CommandResult.TEMPORARILY_REJECTED, f"REQUEST MSG {mid} REJECTED: NO DATA YET", [], False
            return CommandResult.ACCEPTED, "", msgs, broadcast
        name = self.stream_of_id.get(mid)
        if name is None:
            return CommandResult.DENIED, f"REQUEST MSG {mid} DENIED: NOT PRODUCED", [], False
        msgs = self.link.stream_messages(name)
        if not msgs:
            return CommandResult.TEMPORARILY_REJECTED, f"REQUEST MSG {mid} REJECTED: NO DATA YET", [], False
        return CommandResult.ACCEPTED, "", msgs, broadcast

    @staticmethod
    def _flag_request(p, what: str, make) -> Answer:
        if not _int_in(p[0], 0, 1):
            return CommandResult.DENIED, f"{what} {p[0]:g} DENIED (1 REQUEST, 0 NONE)", [], False
        return CommandResult.ACCEPTED, "", [make()] if p[0] == 1 else [], False
