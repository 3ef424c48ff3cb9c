"""The ground link's signing policy by message class: the one table of what a ground station
may send without the signing key (interfaces/mavlink/README.md, "Signing policy").

READ   changes nothing on the vehicle: accepted unsigned, answered to the requester only,
       within the requester's read budget; never makes a telemetry peer.
WRITE  changes the vehicle's state (or another client's): accepted signed only; unsigned it
       is refused, counted and told in the link's one throttled refusal event.

A message's class is its entry in MESSAGES; for the messages that carry a command or an FTP
opcode it is the command's (COMMANDS: WRITE for any command not listed) or the opcode's
(FTP_OPCODES: READ for any opcode not listed, which the server refuses). The intake lets through unsigned only the message ids that
can be READ (``may_be_unsigned``); the link judges the rest by ``access`` after decoding.
"""
from __future__ import annotations

from interfaces.mavlink import dialect as mav

from . import ftp

READ, WRITE = "read", "write"
BY_COMMAND, BY_OPCODE = "by command", "by opcode"

MESSAGES: dict[int, str] = {
    mav.MAVLINK_MSG_ID_HEARTBEAT: READ,                  # presence; authorises nothing
    mav.MAVLINK_MSG_ID_PING: READ,
    mav.MAVLINK_MSG_ID_TIMESYNC: READ,
    mav.MAVLINK_MSG_ID_PARAM_REQUEST_LIST: READ,
    mav.MAVLINK_MSG_ID_PARAM_REQUEST_READ: READ,
    mav.MAVLINK_MSG_ID_MISSION_REQUEST_LIST: READ,
    mav.MAVLINK_MSG_ID_MISSION_ACK: READ,                # a client closing its mission download
    mav.MAVLINK_MSG_ID_REQUEST_EVENT: READ,              # events sent again (events.py), to the requester
    mav.MAVLINK_MSG_ID_PARAM_SET: WRITE,
    mav.MAVLINK_MSG_ID_COMMAND_LONG: BY_COMMAND,
    mav.MAVLINK_MSG_ID_COMMAND_INT: BY_COMMAND,
    mav.MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL: BY_OPCODE,
}

# Read-only commands; every other command (mode, arming, fault injection, FDIR overrides,
# SET_MESSAGE_INTERVAL, ...) is WRITE.
COMMANDS: dict[int, str] = {
    mav.MAV_CMD_REQUEST_MESSAGE: READ,                   # identity, metadata, a telemetry message
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: READ,
    mav.MAV_CMD_REQUEST_PROTOCOL_VERSION: READ,
    mav.MAV_CMD_GET_MESSAGE_INTERVAL: READ,
    mav.MAV_CMD_RUN_PREARM_CHECKS: READ,                 # a report asked for (MAVSDK's events plugin): UNSUPPORTED
}

# MAVLink FTP opcodes that change something: ResetSessions (everyone's sessions) and every
# write opcode. Every other opcode is READ: the read-only ones (a client's own session:
# ftp.FtpServer keeps sessions per client) and those the server does not know, which it
# answers NAK UnknownCommand (a client falls back on it, e.g. from ListDirectoryWithTime).
FTP_OPCODES: dict[int, str] = {op: WRITE for op in (ftp.RESET, *ftp.WRITE_OPS)}


def may_be_unsigned(msgid: int) -> bool:
    """Whether a frame of ``msgid`` can be READ (the intake's unsigned allow-list)."""
    return MESSAGES.get(msgid, WRITE) != WRITE


def access(msg) -> str:
    """READ or WRITE: the class of one decoded message."""
    cls = MESSAGES.get(msg.get_msgId(), WRITE)
    if cls == BY_COMMAND:
        return COMMANDS.get(msg.command, WRITE)
    if cls == BY_OPCODE:
        payload = bytes(msg.payload)
        return FTP_OPCODES.get(payload[3], READ) if len(payload) > 3 else WRITE
    return cls


# What may arrive unsigned at all, and what must be signed in some form (only those make a
# telemetry peer, and only signed).
UNSIGNED_MSGIDS = frozenset(m for m in MESSAGES if may_be_unsigned(m))
COMMAND_CLASS = frozenset(m for m, c in MESSAGES.items() if c != READ)
