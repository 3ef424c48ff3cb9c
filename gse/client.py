"""Ground-station client (system 255) for the ellipsled vehicle, shared by the console and
the command-line tools: a UDP socket, the verify-first signed link, a state model of what
the vehicle reports, commands and parameters with retries, and the .tlog. What an operator
types is turned into requests by gse/commands.py.

Addressing: the client listens on ``listen`` (default udp:127.0.0.1:14550, where the
vehicle sends its telemetry; "port 0" = ephemeral) and sends to ``vehicle`` if given,
else to the source address of the vehicle's first verified frame. The vehicle sends its
telemetry to the sender of every accepted signed command, and answers requests to their
sender, so a client on an ephemeral port with ``vehicle="udp:127.0.0.1:14555"`` works
while another client (the console) holds 14550.

Whom it believes, with a key: only frames of the vehicle (system 1) whose signature
verified — an unsigned HEARTBEAT cannot set the mode, ARMED or the link age shown — and
only from the address of the first one verified (``vehicle_source``: the vehicle is
pinned; frames of system 1 from elsewhere are dropped and counted, ``rx_foreign``).

Signing: every frame sent is signed with the key (commands and parameter writes must be);
each client should use its own ``link_id`` when several share one key and system/component
id (the console uses 0, the CLI a per-process one), so their timestamp streams stay apart.

Watching without the key (``key=None``: the view-only console, a recorded log): frames
whose CRC is right are decoded without checking their signature, and nothing is sent; what
is shown is then unverified, and it authorises nothing.

Text fields from the link (STATUSTEXT, parameter and value names) are kept with their
control characters escaped (``framing.printable_text``): what is printed cannot act on the
operator's terminal. ``listen=None`` opens no socket:
frames come from ``feed`` (gse/replay.py drives it from a .tlog).

Nothing here blocks except the explicit waiting calls (``wait_*``, ``command``,
``param_*``), which poll with ``select`` up to their timeout.
"""
from __future__ import annotations

import os
import select
import socket
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

from interfaces.mavlink import dialect as mav
from interfaces.mavlink.framing import FrameSplitter, parse_header, printable_text
from interfaces.mavlink.intake import kernel_drops
from interfaces.mavlink.signing.keys import SigningKey
from interfaces.mavlink.signing.link import SignedLink
from interfaces.mavlink.signing.verify import Rejection
from interfaces.vocabulary import DEFAULT_GCS, DEFAULT_VEHICLE, parse_udp

from .commands import Request
from .tlog import TlogWriter

GCS_SYSTEM_ID = 255
GCS_COMPONENT_ID = mav.MAV_COMP_ID_MISSIONPLANNER        # 190
VEHICLE_SYSTEM_ID = 1
VEHICLE_COMPONENT_ID = 1
DEFAULT_LISTEN = DEFAULT_GCS                 # where the vehicle sends its telemetry
# The ground end asks for a deep receive buffer: telemetry is fire-and-forget UDP, and a
# console starved of CPU for a second or two (a busy laptop, a loaded 2-core SIL host)
# would otherwise lose what the kernel cannot queue — events (STATUSTEXT) included. The
# system default (~208 kB) holds ~150 small datagrams, about 1.5 s of the default streams;
# 4 MiB (the kernel caps it at net.core.rmem_max) holds minutes. What is lost anyway is
# counted from the kernel's own drop counter (stats["rx_kernel_drops"]) and shown.
RX_BUFFER_BYTES = 4 << 20


def _deep_receive_buffer(sock: socket.socket, size: int) -> None:
    """Ask for ``size`` bytes of receive buffer: beyond net.core.rmem_max where the process
    may (SO_RCVBUFFORCE, CAP_NET_ADMIN), else up to that cap (SO_RCVBUF); what was granted
    is the socket's SO_RCVBUF (GroundClient.rx_buffer_bytes)."""
    force = getattr(socket, "SO_RCVBUFFORCE", None)
    if force is not None:
        try:
            sock.setsockopt(socket.SOL_SOCKET, force, size)
            return
        except OSError:
            pass
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, size)


def result_name(result: int | None) -> str:
    """'ACCEPTED', 'DENIED', ... for a MAV_RESULT; 'TIMEOUT' for None."""
    if result is None:
        return "TIMEOUT"
    entry = mav.enums["MAV_RESULT"].get(result)
    return entry.name.removeprefix("MAV_RESULT_") if entry is not None else f"RESULT_{result}"


@dataclass
class StatusText:
    t_unix_s: float
    severity: int
    text: str

    @property
    def severity_name(self) -> str:
        e = mav.enums["MAV_SEVERITY"].get(self.severity)
        return e.name.removeprefix("MAV_SEVERITY_") if e is not None else str(self.severity)


@dataclass
class Ack:
    t_unix_s: float
    command: int
    result: int

    @property
    def name(self) -> str:
        return result_name(self.result)


@dataclass
class PendingCommand:
    """A COMMAND_LONG waiting for its COMMAND_ACK (``result`` None until it arrives;
    ``done`` also when every retry timed out)."""
    command: int
    params: tuple[float, ...]
    timeout_s: float
    retries: int
    sent: int = 0
    deadline: float = 0.0
    result: int | None = None
    done: bool = False

    @property
    def result_name(self) -> str:
        return result_name(self.result)


@dataclass
class VehicleState:
    """What the vehicle last reported: latest message of each type, named values,
    events, acknowledgements, parameters."""
    latest: dict[str, object] = field(default_factory=dict)
    named: dict[str, float] = field(default_factory=dict)
    events: deque = field(default_factory=lambda: deque(maxlen=500))
    acks: deque = field(default_factory=lambda: deque(maxlen=100))
    params: dict[str, float] = field(default_factory=dict)
    param_count: int | None = None
    rx_counts: dict[str, int] = field(default_factory=dict)
    last_heartbeat_t: float | None = None
    events_total: int = 0


class WatchLink:
    """Receive side for watching without the key: splits datagrams into frames (CRC checked
    by the splitter) and decodes them; signatures are NOT checked (a signed frame is marked
    signed because it carries one). Sends nothing."""

    def __init__(self):
        self.splitter = FrameSplitter()
        self._decoder = mav.MAVLink(None)
        self._decoder.robust_parsing = True

    def receive(self, datagram) -> list:
        out = []
        for frame in self.splitter.split_datagram(datagram):
            try:
                msg = self._decoder.decode(bytearray(frame))
            except Exception:               # pymavlink raises MAVError and others
                continue
            if isinstance(msg, (mav.MAVLink_bad_data, mav.MAVLink_unknown)):
                continue
            hdr = parse_header(frame)
            msg._signed = bool(hdr is not None and hdr.signed)
            out.append(msg)
        return out


class GroundClient:
    """One ground station end of the link (see the module docstring)."""

    def __init__(self, key: SigningKey | None, *, listen: str | None = DEFAULT_LISTEN, vehicle: str | None = None,
                 system_id: int = GCS_SYSTEM_ID, component_id: int = GCS_COMPONENT_ID, link_id: int = 0,
                 tlog: str | os.PathLike[str] | None = None, clock=time.time):
        if key is not None and not isinstance(key, SigningKey):
            raise TypeError("key must be a SigningKey (interfaces.mavlink.signing) or None (watch only)")
        self.clock = clock
        self.link = WatchLink() if key is None else SignedLink(
            key, system_id=system_id, component_id=component_id, link_id=link_id, on_reject=self._on_reject)
        self.view_only = key is None
        self.vehicle_addr: tuple[str, int] | None = parse_udp(vehicle, "vehicle") if vehicle else None
        self._vehicle_fixed = self.vehicle_addr is not None
        self.vehicle_source: tuple[str, int] | None = None        # pinned: first verified vehicle frame's address
        self.sock = None
        if listen is not None:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                self.sock.bind(parse_udp(listen, "listen"))
            except OSError as e:
                self.sock.close()
                raise OSError(f"ground client cannot listen on {listen}: {e.strerror or e}") from None
            self.sock.setblocking(False)
            _deep_receive_buffer(self.sock, RX_BUFFER_BYTES)
        self.tlog = TlogWriter(tlog) if tlog is not None else None
        self._splitter = FrameSplitter()
        self.state = VehicleState()
        self.rejections: deque[Rejection] = deque(maxlen=100)
        self.rejected = 0
        self.pending: list[PendingCommand] = []
        self._rx_times: deque[float] = deque(maxlen=4096)
        self._tx_times: deque[float] = deque(maxlen=4096)
        self.stats = {"rx_datagrams": 0, "rx_frames": 0, "rx_messages": 0, "tx_frames": 0, "tx_errors": 0,
                      "rx_kernel_drops": 0, "rx_unsigned": 0, "rx_foreign": 0}
        self.rx_buffer_bytes = (self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
                                if self.sock is not None else 0)
        self._buf = bytearray(65536)

    # ---------------------------------------------------------------- basics
    @property
    def address(self) -> tuple[str, int]:
        return self.sock.getsockname()

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
        if self.tlog is not None:
            self.tlog.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def set_vehicle(self, addr: tuple[str, int]) -> None:
        """Send to ``addr`` from now on (and stop learning it from telemetry)."""
        self.vehicle_addr = (str(addr[0]), int(addr[1]))
        self._vehicle_fixed = True

    def _on_reject(self, rej: Rejection) -> None:
        self.rejected += 1
        self.rejections.append(rej)

    def send(self, msg) -> bool:
        """Sign and send one message to the vehicle; False if its address is not known yet
        (or when watching without the key: nothing is ever sent)."""
        if self.vehicle_addr is None or self.view_only or self.sock is None:
            return False
        frame = self.link.pack(msg)
        try:
            self.sock.sendto(frame, self.vehicle_addr)
        except OSError:
            self.stats["tx_errors"] += 1
            return False
        self.stats["tx_frames"] += 1
        self._tx_times.append(self.clock())
        if self.tlog is not None:
            self.tlog.write(frame)
        return True

    def send_heartbeat(self) -> bool:
        return self.send(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0,
                                                       mav.MAV_STATE_ACTIVE, 3))

    def poll(self, timeout_s: float = 0.0) -> int:
        """Receive every waiting datagram (waiting up to ``timeout_s`` for the first);
        returns the number of messages accepted. Also services pending commands."""
        n = 0
        if self.sock is None:
            self.service()
            return 0
        if timeout_s > 0:
            try:
                select.select([self.sock], [], [], timeout_s)
            except (OSError, ValueError):
                return 0
        while True:
            try:
                size, addr = self.sock.recvfrom_into(self._buf)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                continue
            n += self.feed(bytes(self._buf[:size]), addr, self.clock())
        drops = kernel_drops(self.sock)
        if drops is not None:
            self.stats["rx_kernel_drops"] = drops
        self.service()
        return n

    def feed(self, data: bytes, addr: tuple[str, int] | None, now: float) -> int:
        """One datagram from ``addr`` received at ``now`` (Unix s): recorded, verified (with
        a key), folded into ``state``; returns the number of vehicle messages taken."""
        n = 0
        self.stats["rx_datagrams"] += 1
        if self.tlog is not None:
            for frame in self._splitter.split_datagram(data):
                self.tlog.write(frame, now)
                self.stats["rx_frames"] += 1
        for msg in self.link.receive(data):
            if msg.get_srcSystem() != VEHICLE_SYSTEM_ID:
                continue
            if not self.view_only:
                if not msg.get_signed():    # authorises nothing, shows nothing
                    self.stats["rx_unsigned"] += 1
                    continue
                if self.vehicle_source is None:
                    self.vehicle_source = addr
                    if not self._vehicle_fixed and addr is not None:
                        self.vehicle_addr = addr
                elif addr != self.vehicle_source:
                    self.stats["rx_foreign"] += 1
                    continue
            self._rx_times.append(now)
            self.stats["rx_messages"] += 1
            self._update(msg, now)
            n += 1
        return n

    def _update(self, msg, now: float) -> None:
        st = self.state
        t = msg.get_type()
        st.latest[t] = msg
        st.rx_counts[t] = st.rx_counts.get(t, 0) + 1
        if t == "HEARTBEAT":
            st.last_heartbeat_t = now
        elif t == "STATUSTEXT":
            st.events.append(StatusText(now, msg.severity, printable_text(msg.text)))
            st.events_total += 1
        elif t == "NAMED_VALUE_FLOAT":
            st.named[printable_text(msg.name)] = msg.value
        elif t == "COMMAND_ACK":
            st.acks.append(Ack(now, msg.command, msg.result))
            for p in self.pending:
                if not p.done and p.command == msg.command:
                    p.result, p.done = msg.result, True
                    break
        elif t == "PARAM_VALUE":
            st.params[printable_text(msg.param_id)] = msg.param_value
            st.param_count = msg.param_count

    # ---------------------------------------------------------------- rates
    def rate_hz(self, which: str = "rx", window_s: float = 2.0) -> float:
        times = self._rx_times if which == "rx" else self._tx_times
        now = self.clock()
        return sum(1 for t in times if now - t <= window_s) / window_s

    def link_age_s(self) -> float | None:
        """Seconds since the vehicle's last heartbeat (None if never seen)."""
        t = self.state.last_heartbeat_t
        return None if t is None else self.clock() - t

    # ---------------------------------------------------------------- waiting
    def wait_for(self, predicate, timeout_s: float) -> bool:
        """Poll until ``predicate()`` is true or ``timeout_s`` elapses."""
        end = time.monotonic() + timeout_s
        while True:
            if predicate():
                return True
            left = end - time.monotonic()
            if left <= 0:
                return False
            self.poll(min(left, 0.05))

    def wait_vehicle(self, timeout_s: float = 3.0) -> bool:
        """Until the vehicle's address is known (given, or learned from its telemetry)."""
        return self.wait_for(lambda: self.vehicle_addr is not None, timeout_s)

    # ---------------------------------------------------------------- commands
    def start_command(self, command: int, *params: float, timeout_s: float = 1.0,
                      retries: int = 3) -> PendingCommand:
        """Send a COMMAND_LONG now; ``poll``/``service`` resend it on timeout (confirmation
        counting up) until its COMMAND_ACK arrives or the retries are spent."""
        p = tuple(float(x) for x in params) + (0.0,) * (7 - len(params))
        if len(p) != 7:
            raise ValueError(f"COMMAND_LONG takes at most 7 parameters, got {len(params)}")
        pc = PendingCommand(int(command), p, float(timeout_s), int(retries))
        self.pending.append(pc)
        self._send_pending(pc)
        return pc

    def _send_pending(self, pc: PendingCommand) -> None:
        msg = mav.MAVLink_command_long_message(VEHICLE_SYSTEM_ID, VEHICLE_COMPONENT_ID, pc.command,
                                               min(pc.sent, 255), *pc.params)
        self.send(msg)
        pc.sent += 1
        pc.deadline = time.monotonic() + pc.timeout_s

    def service(self) -> None:
        """Resend pending commands whose ACK is late; give up after the retries."""
        now = time.monotonic()
        for pc in self.pending:
            if not pc.done and now >= pc.deadline:
                if pc.sent > pc.retries:
                    pc.done = True
                else:
                    self._send_pending(pc)
        self.pending = [p for p in self.pending if not p.done]

    def command(self, command: int, *params: float, timeout_s: float = 1.0, retries: int = 3) -> int | None:
        """Send and wait: the MAV_RESULT, or None if no ACK came (all retries timed out)."""
        pc = self.start_command(command, *params, timeout_s=timeout_s, retries=retries)
        self.wait_for(lambda: pc.done, timeout_s * (retries + 1) + 0.1)
        return pc.result

    def start(self, req: Request, timeout_s: float = 1.0, retries: int = 3) -> PendingCommand | None:
        """Non-blocking (console): send a Request; a command returns its PendingCommand,
        a parameter action returns None (its PARAM_VALUE lands in ``state.params``)."""
        if req.command:
            return self.start_command(req.command, *req.params, timeout_s=timeout_s, retries=retries)
        if req.param == "list":
            self.param_request_list()
        elif req.param == "get":
            self.send(mav.MAVLink_param_request_read_message(VEHICLE_SYSTEM_ID, VEHICLE_COMPONENT_ID,
                                                             req.param_id.encode("ascii"), -1))
        elif req.param == "set":
            self.state.params.pop(req.param_id, None)
            self.send(mav.MAVLink_param_set_message(VEHICLE_SYSTEM_ID, VEHICLE_COMPONENT_ID,
                                                    req.param_id.encode("ascii"), req.value,
                                                    mav.MAV_PARAM_TYPE_REAL32))
        return None

    # ---------------------------------------------------------------- parameters
    def param_request_list(self) -> None:
        self.send(mav.MAVLink_param_request_list_message(VEHICLE_SYSTEM_ID, VEHICLE_COMPONENT_ID))

    def param_list(self, timeout_s: float = 3.0) -> dict[str, float]:
        """Every parameter (id -> value) the vehicle sends within ``timeout_s``."""
        self.param_request_list()
        self.wait_for(lambda: self.state.param_count is not None
                      and len(self.state.params) >= self.state.param_count, timeout_s)
        return dict(self.state.params)

    def param_get(self, param_id: str, timeout_s: float = 1.0, retries: int = 3) -> float | None:
        pid = param_id.upper()
        for _ in range(retries + 1):
            self.state.params.pop(pid, None)
            self.send(mav.MAVLink_param_request_read_message(VEHICLE_SYSTEM_ID, VEHICLE_COMPONENT_ID,
                                                             pid.encode("ascii"), -1))
            if self.wait_for(lambda: pid in self.state.params, timeout_s):
                return self.state.params[pid]
        return None

    def param_set(self, param_id: str, value: float, timeout_s: float = 1.0,
                  retries: int = 3) -> float | None:
        """Send PARAM_SET and wait for the PARAM_VALUE echo: the vehicle's value after the
        set (equal to ``value`` in float32 if accepted, the unchanged one if refused), or
        None if no answer came."""
        pid = param_id.upper()
        for _ in range(retries + 1):
            self.state.params.pop(pid, None)
            self.send(mav.MAVLink_param_set_message(VEHICLE_SYSTEM_ID, VEHICLE_COMPONENT_ID, pid.encode("ascii"),
                                                    float(value), mav.MAV_PARAM_TYPE_REAL32))
            if self.wait_for(lambda: pid in self.state.params, timeout_s):
                return self.state.params[pid]
        return None


def float32_equal(a: float, b: float) -> bool:
    """True if a and b are the same float32 (what PARAM_VALUE carries)."""
    import struct
    try:
        return struct.pack("<f", a) == struct.pack("<f", b)
    except (OverflowError, struct.error):
        return False


def load_key(path: str | os.PathLike[str] | None) -> SigningKey:
    """The signing key from ``path`` or $ELLIPSLED_SIGNING_KEY_FILE (SigningKeyError if neither)."""
    return SigningKey.from_file(Path(path) if path else None)


__all__ = ["GroundClient", "VehicleState", "PendingCommand", "StatusText", "Ack", "result_name",
           "float32_equal", "load_key", "DEFAULT_LISTEN", "DEFAULT_VEHICLE", "GCS_SYSTEM_ID"]
