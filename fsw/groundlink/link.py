"""The ground link's protocol side: a non-blocking UDP socket, verify-first signing, the
ground peers, receive and dispatch, telemetry scheduling and sending. What it sends and
accepts is documented in interfaces/mavlink/README.md.

Runs in the FSW process, in the same thread as ``FlightSoftware.control_step`` and between
cycles (commands change FSW state, so they must not run concurrently with a control cycle):
the executive calls ``tick()`` from RG2 and ``listen()`` (receive and answer only) on the
other cycles, after the cycle's command is out, so the socket is read every control period
within the same per-cycle budget. ``tick`` reads
the socket within a budget (interfaces/mavlink/intake.py: at most ``max_rx_per_tick``
datagrams and ``rx_budget_us`` a tick; what cannot be a command refused before any CRC or
signature work; the receive buffer sized to one tick's budget, the kernel dropping the
excess), answers what arrived, then sends the telemetry that is due, all within its time
budget per tick (schedule.py: a share of the control period; what does not fit waits for a
later tick, counted); it never blocks and never raises on anything from the network. What the link refused and dropped is in
``stats``, in SYS_STATUS (errors_comm: rejections; errors_count1: datagrams dropped on the
full queue; errors_count2: datagrams refused before verification; errors_count3: unsigned
state-changing frames refused; errors_count4: reads over budget), per sender in
``refused_by_sender``, and in the one throttled refusal event below.

Who the link listens to:
- the vehicle's own system id is refused from the link (a frame the vehicle signed and
  someone sent back verifies: same key, fresh timestamp);
- what may come unsigned is decided by one table, policy.py (signing policy by message
  class): read-only requests (identity, a telemetry message, modes, metadata over FTP's
  read-only opcodes, parameter reads, the mission list, PING, TIMESYNC) are answered to the
  requester only and within the tick's reply budget; an unsigned sender gets at most
  ``READ_RATE_HZ`` requests and answer frames a second (after a burst of ``READ_BURST``: a
  parameter list or an FTP burst goes out at that pace), so no unsigned request is an
  amplifier; state-changing frames are acted on only signed (unsigned: refused, counted,
  a command answered DENIED);
- a telemetry peer (an address that gets the telemetry besides ``gcs``) is made only by a
  signed *command-class* frame (COMMAND_LONG, COMMAND_INT, PARAM_SET, FTP) from a ground
  system addressed to this vehicle; a signed heartbeat or read makes none;
- every refusal (the intake's, an unsigned state-changing frame, a read over budget, an
  unknown parameter id read unsigned) is counted and told in one event code,
  ``REFUSAL_EVENT``: at once, then at most once per ``REFUSAL_EVENT_INTERVAL_S`` (a summary).

Downlink per tick, beyond the telemetry streams: at most ``max_tx_per_tick`` frames of
events and answers; answers take at most ``max_tx_per_tick - EVENT_SHARE`` of them, so
events always keep ``EVENT_SHARE`` frames a tick. Why in the control thread and not a
receive thread: docs/decisions.md. Beside this module: senders.py (peers, read budgets),
streams.py (what each stream says), schedule.py (the tick's budget, when streams are due).
"""
from __future__ import annotations

import logging
import socket
import time
from collections import OrderedDict, deque
from collections.abc import Callable, Mapping

from fsw.executive import divisors
from interfaces.event_catalogue import EV
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.intake import DatagramIntake
from interfaces.mavlink.signing.keys import SigningKey, stream_state_path
from interfaces.mavlink.signing.link import SignedLink
from interfaces.mavlink.signing.verify import Reject, Rejection
from interfaces.vocabulary import DEFAULT_GCS, DEFAULT_VEHICLE, CommandResult, Severity, parse_udp

from . import ftp, metadata, policy
from . import telemetry as tm
from .commands import CommandTranslator, InjectFn, ParamProtocol
from .ftp import FtpServer
from .senders import Peers, ReadBudgets
from .services import COMMANDS as LINK_COMMANDS, LinkServices
from .schedule import TICK_BUDGET_FRAC, RecentCost, StreamSchedule, TickBudget
from .streams import MAX_RATE_HZ, TelemetryStreams, check_rates

log = logging.getLogger(__name__)

SYSTEM_ID = 1
COMPONENT_ID = mav.MAV_COMP_ID_AUTOPILOT1        # 1
DEFAULT_BIND = DEFAULT_VEHICLE

# What a ground station may send unsigned, and what must be signed: the one table is
# policy.py (read-only messages, commands and FTP opcodes; everything else signed only).
ALLOW_UNSIGNED = policy.UNSIGNED_MSGIDS
# What the link acts on besides HEARTBEAT (messages with a target system and component, and
# TIMESYNC, which has none in pymavlink 2.4.50's common.xml).
_ADDRESSED = frozenset(policy.MESSAGES) - {mav.MAVLINK_MSG_ID_HEARTBEAT}
_UNTARGETED = frozenset({mav.MAVLINK_MSG_ID_TIMESYNC})
# Frames that must be signed in some form, and only they (signed) make a telemetry peer.
COMMAND_CLASS = policy.COMMAND_CLASS
REFUSAL_EVENT = EV.LINK_REFUSED.name   # the one event code of every refusal on the link ...
REFUSAL_EVENT_INTERVAL_S = 60.0  # ... told at once, then at most once in this interval (a summary)
FTP_REPLIES_PER_TICK = 32        # what MAVLink FTP may add to one tick's sends
EVENT_SHARE = 16                 # frames a tick no answer to a request can take from the events
MAX_PARAM_LISTS = 4              # parameter lists queued at once (one per requester)
STAT_NAMES = ("rx_datagrams", "rx_bytes", "rx_messages", "tx_frames", "tx_bytes", "tx_errors", "refused_early",
              "kernel_drops", "rx_budget_hits", "rx_poll_max_us", "rx_deferred", "ftp_deferred", "tx_deferred",
              "reads_limited", "reads_unknown", "peers_added", "refused_senders", "commands_accepted", "params_set",
              "unsigned_writes", "unsigned_reads", "events_deferred", "events_missed", "params_deferred")
# the kinds of work a tick begins item by item against their own recent cost (schedule.RecentCost):
# an event (its frames), a parameter-list entry, an FTP reply
ITEM_KINDS = ("event", "param", "ftp")


class GroundLink:
    """MAVLink 2 ground link of one FlightSoftware.

    fsw      fsw.flightsoftware.FlightSoftware (read for telemetry, commanded).
    key      SigningKey shared with the ground station.
    gcs      "udp:HOST:PORT" the telemetry goes to (and to every peer that sent an accepted
             signed frame within ``peer_timeout_s``, as MAVLink vehicles answer the sender).
    bind     "udp:HOST:PORT" the link listens on (port 0 = ephemeral; see ``address``).
    inject   callback forwarding a fault injection to the plant (may be None).
    rates    {stream: Hz} overriding DEFAULT_RATES_HZ.
    clock    monotonic time [s] for telemetry scheduling and read budgets (tests pass a fake one).
    wall_clock  Unix time [s] for SYSTEM_TIME.
    stream_state  where the signing streams' last timestamps are kept across restarts:
             "beside-key" (the key file's name + ".streams"; none for a key not read from a
             file), a path, or None (only the start-time rule refuses older frames).
    tick_budget_frac  the share of the control period one tick may take (schedule.py).
    tick_clock_ns  the clock that budget is kept on (tests pass a fake one).
    """

    SEND_MARGIN_NS = 1_000_000       # kept free before the deadline beyond the send side's peak

    def __init__(self, fsw, key: SigningKey, *, gcs: str = DEFAULT_GCS, bind: str = DEFAULT_BIND,
                 inject: InjectFn | None = None, rates: Mapping[str, float] | None = None,
                 clock: Callable[[], float] = time.monotonic, wall_clock: Callable[[], float] = time.time,
                 max_rx_per_tick: int = 256,
                 rx_budget_us: float = 2000.0, max_tx_per_tick: int = 64, peer_timeout_s: float = 10.0, max_peers: int = 4,
                 stream_state: str | None = "beside-key", refusal_event_interval_s: float = REFUSAL_EVENT_INTERVAL_S,
                 tick_budget_frac: float = TICK_BUDGET_FRAC, tick_clock_ns: Callable[[], int] = time.perf_counter_ns):
        if not isinstance(key, SigningKey):
            raise TypeError("key must be a SigningKey (interfaces.mavlink.signing)")
        if not int(max_tx_per_tick) > EVENT_SHARE:
            raise ValueError(f"max_tx_per_tick must be > {EVENT_SHARE} (the events' share), got {max_tx_per_tick}")
        self.fsw, self.clock, self.wall_clock = fsw, clock, wall_clock
        self.max_rx_per_tick = int(max_rx_per_tick)
        self.max_tx_per_tick = int(max_tx_per_tick)
        self.refusal_event_interval_s = refusal_event_interval_s
        self.rates_hz = check_rates(rates)
        if not 0.0 < tick_budget_frac <= 1.0:
            raise ValueError(f"tick_budget_frac must be in (0, 1], got {tick_budget_frac}")
        self.budget = TickBudget(round(tick_budget_frac * fsw.dt_s * 1e9), tick_clock_ns)
        self.in_tick = False
        # no stream can go out more often than the link ticks (RG2): the fastest rate a
        # ground station may ask for
        self.max_rate_hz = min(MAX_RATE_HZ, 1.0 / (fsw.dt_s * divisors(fsw.params, fsw.dt_s)[1]))
        self.gcs = parse_udp(gcs, "gcs")
        bind_addr = parse_udp(bind, "bind")
        self.commands_in = CommandTranslator(fsw, inject)
        self.params_in = ParamProtocol(fsw)

        self.link = SignedLink(key, system_id=SYSTEM_ID, component_id=COMPONENT_ID,
                               allow_unsigned=ALLOW_UNSIGNED, on_reject=self._on_reject,
                               state_path=stream_state_path(key) if stream_state == "beside-key" else stream_state,
                               persist_msgids=COMMAND_CLASS)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind(bind_addr)
        except OSError as e:
            self.sock.close()
            raise OSError(f"ground link cannot bind {bind}: {e.strerror or e}") from None
        self.sock.setblocking(False)
        self.intake = DatagramIntake(self.sock, self.link, accept=_ADDRESSED | {mav.MAVLINK_MSG_ID_HEARTBEAT},
                                     max_datagrams=self.max_rx_per_tick, budget_us=rx_budget_us,
                                     own_sysid=SYSTEM_ID)
        self._drops_reported = 0

        self.peers = Peers(peer_timeout_s, max_peers)
        self._param_lists: OrderedDict[tuple[str, int], tuple[deque[str], bool]] = OrderedDict()  # requester -> (names left, signed)
        self.reads = ReadBudgets()                                        # unsigned senders' read budgets
        self._reply_budget = self.max_tx_per_tick - EVENT_SHARE          # this tick's answers left
        self.schedule = StreamSchedule(self.rates_hz)
        self.streams = TelemetryStreams(self)
        self.files = metadata.build(fsw.registry, fsw.scenario.vehicle.name)
        self.ftp = FtpServer(self.files)
        self._ftp_budget = FTP_REPLIES_PER_TICK
        self.services = LinkServices(self, {mav.MAVLINK_MSG_ID_COMPONENT_METADATA: lambda p: [self.component_metadata()],
                                            mav.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: self.streams.origin_message})
        self._event_index = 0                          # the start-up events go out too
        self._pack_only = False                        # warm_up packs without sending
        self.ground_heartbeat_t: float | None = None                     # clock() of last GCS heartbeat
        self.commands: dict[int, int] = {}                               # MAV_RESULT -> count
        self.stats = dict.fromkeys(STAT_NAMES, 0)
        self.stats["rx_poll_max_us"] = 0.0
        self.send_ns_peak = self.send_overhead_ns = 0
        self.rx_tail = RecentCost()                    # what receiving takes past the intake's budget [ns]
        self.item_cost = {kind: RecentCost() for kind in ITEM_KINDS}   # what one item of each kind costs [ns]
        self._rx_skipped = False                       # the last tick had no time to receive

    # -------------------------------------------------------------- configuration
    @property
    def inject(self) -> InjectFn | None:
        return self.commands_in.inject

    @inject.setter
    def inject(self, fn: InjectFn | None) -> None:
        self.commands_in.inject = fn

    @property
    def param_names(self) -> list[str]:
        return self.params_in.names

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) the link is bound to."""
        return self.sock.getsockname()

    def close(self) -> None:
        self.sock.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # -------------------------------------------------------------- the tick
    def tick(self, sensors=None, deadline_ns: int | None = None) -> None:
        """Call from RG2: receive and answer, then send what is due, within the tick's budget
        (schedule.py); when the intake stopped on its budget, receive more in what sending
        left. ``sensors``: the latest SENSORS record (for "firing" from the chamber pressures).
        ``deadline_ns`` (time.monotonic_ns): the cycle's deadline; the budget then also ends
        SEND_MARGIN_NS before it: whatever ran late before the link in this cycle, the ground's
        datagrams wait in the socket rather than push the cycle past its deadline. A tick left
        no time to receive reads nothing (counted: rx_deferred); the next one left none takes
        up one datagram and its first frame (the intake's least) if the deadline leaves the
        link any time: a command waits at most one tick past the one it arrived before."""
        b = self._start(deadline_ns)
        try:
            overdue = self.streams.overdue_ns(self.clock())      # the streams owed, with what sending costs besides
            rx_ns = b.receive_ns(self.send_ns_peak, overdue + self.send_overhead_ns if overdue else 0)
            hits = self.intake.stats["budget_hits"]
            self._rx_skipped = not (rx_ns > 0 or self._rx_skipped and b.limit_ns > 0)
            if self._rx_skipped:
                self.stats["rx_deferred"] += 1
            else:                                # a second tick running with no time: one frame (intake.py)
                self._receive(self._share(rx_ns) if rx_ns > 0 else 1)
            t_send = b.elapsed_ns()
            self.streams.sample_allocator()
            self.send_due(sensors)
            t_more = b.elapsed_ns()
            left = b.left_ns() - self.rx_tail.ns
            if self.intake.stats["budget_hits"] != hits and left > self.intake.frame_estimate_ns(left * 4):
                self._receive(left, False)   # the intake stopped on its budget: more, in what sending left
            # what receiving leaves the send side: what it wanted (sent, and what the budget
            # deferred), and its cost besides the streams, peaks decaying x0.9 a tick (one
            # outlier is forgotten within seconds)
            send_ns = t_more - t_send
            self.send_ns_peak = max(send_ns + self.streams.deferred_ns, int(self.send_ns_peak * 0.9))
            self.send_overhead_ns = max(send_ns - self.streams.sent_ns, int(self.send_overhead_ns * 0.9))
        except Exception:                       # the link must never take the FSW down
            log.exception("ground link tick failed")
        finally:
            self.in_tick = False
        b.finish()

    def listen(self, deadline_ns: int | None = None) -> None:
        """Call on the cycles between ticks (RG1, when RG2 does not run): receive and answer
        within the tick's budget, sending nothing scheduled (answers draw on the reply and
        FTP budgets the next tick renews, so what the link sends a second is unchanged).
        The socket is thus read every control period, not every RG2 period: a flood fills
        the receive queue for one period at most, so the kernel does not drop a genuine
        command at a queue filled between ticks, and what the link may spend receiving a
        second grows with the control rate. ``deadline_ns``: as ``tick``'s. Counted apart
        from the ticks (``TickBudget.finish``); a cycle with nothing waiting (``intake.waiting``,
        one poll(2)) costs no more than that check and is not counted."""
        if not self.intake.waiting():
            return
        b = self._start(deadline_ns)
        try:
            rx_ns = b.receive_ns(0)
            if rx_ns > 0:
                self._receive(self._share(rx_ns))
            else:
                self.stats["rx_deferred"] += 1
        except Exception:                       # the link must never take the FSW down
            log.exception("ground link listen failed")
        finally:
            self.in_tick = False
        b.finish(listen=True)

    def _start(self, deadline_ns: int | None) -> TickBudget:
        """A tick or a listen begins: its budget started, ending SEND_MARGIN_NS before the
        cycle's deadline when there is one; inside it until ``in_tick`` is cleared."""
        b = self.budget
        b.start(None if deadline_ns is None else deadline_ns - time.monotonic_ns() - self.SEND_MARGIN_NS)
        self.in_tick = True
        return b

    def _share(self, rx_ns: int) -> int:
        """Receiving's share ``rx_ns`` (> 0) less what receiving recently took past the
        intake's budget (``rx_tail``), at most half of it."""
        return rx_ns - min(self.rx_tail.ns, rx_ns // 2)

    def _receive(self, given_ns: int, least: bool = True) -> None:
        """Poll within ``given_ns``. The intake's budget ends at its last frame's start; what
        follows (that frame past its estimate, the refusal reports, the link's counters) is
        measured (``rx_tail``) and taken from the next shares (at most half of one)."""
        t = self.budget.elapsed_ns()
        self.poll(given_ns, least)
        self.rx_tail.add(max(0, self.budget.elapsed_ns() - t - given_ns))

    def warm_up(self, spare_fsw, sensors=None) -> None:
        """Encode (pack) every telemetry message once from ``spare_fsw`` — a throwaway
        FlightSoftware that has flown a cycle — and send nothing: the first encode of each
        message type costs milliseconds, which would otherwise land in the first real-time
        cycles. Schedules, counters and the link's sequence numbers are left as they were."""
        saved = (self.fsw, dict(self.schedule.next_due), self._event_index, self.link.signer.seq, self.streams.origin,
                 self.streams.mode_sent)
        self.fsw = spare_fsw
        self._pack_only = True
        try:
            self.send_due(sensors)
            self._send(self.params_in.value_msg(self.params_in.names[0]))
            self._send(tm.statustext(Severity.INFO, "warm-up"))
            for msg in (mav.MAVLink_command_ack_message(0, 0, 0, 0, 0, 0), self.services.autopilot_version(),
                        self.services.protocol_version(), mav.MAVLink_message_interval_message(0, 0),
                        self.component_metadata(), mav.MAVLink_file_transfer_protocol_message(0, 0, 0, [0] * 251),
                        *tm.available_modes(), mav.MAVLink_ping_message(0, 0, 0, 0), mav.MAVLink_timesync_message(0, 0),
                        mav.MAVLink_mission_count_message(0, 0, 0, 0)):
                self._send(msg)
        except Exception:                       # a warm-up failure must not stop the FSW
            log.exception("ground link warm-up failed")
        finally:
            (self.fsw, self.schedule.next_due, self._event_index, self.link.signer.seq, self.streams.origin,
             self.streams.mode_sent) = saved
            self._pack_only = False

    def poll(self, budget_ns: int | None = None, least: bool = True) -> int:
        """Receive within the tick's budget (or ``budget_ns``, if less) without blocking;
        returns the datagrams read. ``least``: as DatagramIntake.poll's."""
        n = self.intake.poll(self._handle_one, budget_ns, least)
        st, ist = self.stats, self.intake.stats
        st["rx_datagrams"], st["rx_bytes"] = ist["datagrams"], ist["bytes"]
        st["refused_early"], st["kernel_drops"] = ist["refused_early"], ist["kernel_drops"]
        st["rx_budget_hits"] = ist["budget_hits"]
        st["refused_senders"] = len(self.intake.refused_by_sender)
        st["rx_poll_max_us"] = max(st["rx_poll_max_us"], self.intake.last_poll_ns * 1e-3)
        dropped = ist["kernel_drops"] - self._drops_reported
        if dropped > 0:
            self._drops_reported = ist["kernel_drops"]
            self.fsw.events.emit(self.fsw.t_s, EV.LINK_FLOOD, dropped=dropped)
        return n

    def _handle_one(self, msg, addr) -> None:
        self.stats["rx_messages"] += 1
        try:
            self.handle(msg, addr)
        except Exception:
            log.exception("ground link: handling %s failed", msg.get_type())

    @property
    def refused_by_sender(self) -> dict[tuple[str, int], int]:
        """Refusals per sender address (the last senders refused; see DatagramIntake)."""
        return dict(self.intake.refused_by_sender)

    @property
    def refusal_event_interval_s(self) -> float:
        """How often the one refusal event is told at most (the rest summarised) [s]."""
        return self._refusal_event_interval_s

    @refusal_event_interval_s.setter
    def refusal_event_interval_s(self, s: float) -> None:
        self._refusal_event_interval_s = float(s)
        self.fsw.events.set_throttle(EV.LINK_REFUSED, self._refusal_event_interval_s)

    @property
    def rejections(self) -> int:
        """Frames and datagrams refused so far, all reasons (SigningVerifier counts)."""
        return self.link.verifier.rejected

    # -------------------------------------------------------------- receive side
    def _on_reject(self, rej: Rejection) -> None:
        self._tell_refusal(rej.text())

    def _tell_refusal(self, text: str) -> None:
        """The link's one refusal event: the first told at once, the others held and told
        as one summary (the last one's text, + how many) once REFUSAL_EVENT_INTERVAL_S is over."""
        self.fsw.events.emit(self.fsw.t_s, EV.LINK_REFUSED, detail=text)

    def handle(self, msg, addr: tuple[str, int]) -> None:
        """Act on one verified, decoded message that arrived from ``addr``, by its class
        (policy.py): READ answered to the requester (unsigned: within its read budget),
        WRITE only when signed; only a signed frame of a command-class message from a ground
        system makes ``addr`` a telemetry peer."""
        signed = bool(msg.get_signed())
        mid = msg.get_msgId()
        if mid == mav.MAVLINK_MSG_ID_HEARTBEAT:
            if msg.type == mav.MAV_TYPE_GCS:
                self.ground_heartbeat_t = self.clock()
            return
        if mid not in _ADDRESSED or not self._for_me(msg):
            return
        if signed and mid in COMMAND_CLASS and msg.get_srcSystem() != SYSTEM_ID:
            self._add_peer(addr)
        elif not signed:
            if policy.access(msg) != policy.READ:
                self._refuse_unsigned(msg, addr)
                return
            if not self._may_read(addr):
                return
            self.stats["unsigned_reads"] += 1
        if mid in (mav.MAVLINK_MSG_ID_COMMAND_LONG, mav.MAVLINK_MSG_ID_COMMAND_INT):
            # no command of this vehicle takes a position: COMMAND_INT's x, y are passed on as numbers
            p5, p6 = (msg.param5, msg.param6) if mid == mav.MAVLINK_MSG_ID_COMMAND_LONG else (float(msg.x), float(msg.y))
            self._command(msg, addr, [msg.param1, msg.param2, msg.param3, msg.param4, p5, p6,
                                      msg.param7 if mid == mav.MAVLINK_MSG_ID_COMMAND_LONG else msg.z], signed)
        elif mid == mav.MAVLINK_MSG_ID_MISSION_REQUEST_LIST:
            self._reply(self.services.mission_count(msg), addr)
        elif mid == mav.MAVLINK_MSG_ID_PING:
            if msg.target_system == 0 and msg.target_component == 0:       # a request, not an answer
                self._reply(mav.MAVLink_ping_message(msg.time_usec, msg.seq, msg.get_srcSystem(),
                                                     msg.get_srcComponent()), addr)
        elif mid == mav.MAVLINK_MSG_ID_TIMESYNC:
            if msg.tc1 == 0:                                                # a request, not an answer
                self._reply(mav.MAVLink_timesync_message(time.monotonic_ns(), msg.ts1), addr)
        elif mid == mav.MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL:
            self._ftp(msg, addr, signed)
        elif mid == mav.MAVLINK_MSG_ID_PARAM_REQUEST_LIST:
            self._queue_param_list(addr, signed)
        elif mid == mav.MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            name, why = self.params_in.read(msg)
            if name is not None:
                self._reply(self.params_in.value_msg(name), addr)
            elif signed:
                self._refuse(EV.PARAM_UNKNOWN, why)
            else:                                # counted, told in the one throttled event
                self.stats["reads_unknown"] += 1
                self.intake.count_sender(addr)
                self._tell_refusal(why)
        elif mid == mav.MAVLINK_MSG_ID_PARAM_SET and signed:
            name, why = self.params_in.set(msg)
            if why:
                self._refuse(EV.PARAM_UNKNOWN if name is None else EV.PARAM_REFUSED, why)
            elif name is not None:
                self.stats["params_set"] += 1
            if name is not None:
                self._send(self.params_in.value_msg(name), extra=addr)     # new value, or unchanged

    def _refuse_unsigned(self, msg, addr) -> None:
        """An unsigned frame of the WRITE class: refused with no effect, counted (as the
        intake counts the unsigned frames it refuses: Reject.UNSIGNED, per sender) and told
        in the one throttled event; a command is answered DENIED, within the sender's read
        budget, so its client stops retrying."""
        self.stats["unsigned_writes"] += 1
        mid = msg.get_msgId()
        cmd = getattr(msg, "command", None)
        self.intake.count_sender(addr)
        self.link.verifier.reject(Rejection(Reject.UNSIGNED, msg.get_srcSystem(), msg.get_srcComponent(), mid,
                                            detail="" if cmd is None else f"command {cmd}"))
        if cmd is not None and self._take_read(addr):
            self._reply(mav.MAVLink_command_ack_message(cmd, CommandResult.DENIED, 0, 0, msg.get_srcSystem(),
                                                        msg.get_srcComponent()), addr)

    @staticmethod
    def _for_me(msg) -> bool:
        if msg.get_msgId() in _UNTARGETED:
            return True
        return msg.target_system in (0, SYSTEM_ID) and msg.target_component in (0, COMPONENT_ID)

    def _take_read(self, addr) -> bool:
        """One unit of ``addr``'s unsigned read budget (senders.ReadBudgets), if it has one."""
        return self.reads.take(addr, self.clock())

    def _may_read(self, addr) -> bool:
        """One unsigned read-only request from ``addr`` within its budget; counted and told
        (one throttled event) when not."""
        if self._take_read(addr):
            return True
        self.stats["reads_limited"] += 1
        self.intake.count_sender(addr)
        self._tell_refusal(f"link reads limited: {addr[0]}:{addr[1]}")
        return False

    def _reply(self, msg, addr) -> None:
        """An answer to a read-only request, to the requester, within the tick's reply budget
        (what is over it is dropped and counted: the requester asks again)."""
        if self._reply_budget <= 0:
            self.stats["reads_limited"] += 1
            return
        self._reply_budget -= 1
        self._send(msg, only=addr)

    def _queue_param_list(self, addr, signed: bool) -> None:
        """A parameter list for ``addr``, sent from the reply budget (and, unsigned, at the
        requester's read pace); one list per requester at a time, at most MAX_PARAM_LISTS."""
        if addr in self._param_lists:              # a signed request lifts the pace of an unsigned one
            names, was_signed = self._param_lists[addr]
            self._param_lists[addr] = (names, was_signed or signed)
            return
        if len(self._param_lists) >= MAX_PARAM_LISTS:
            self.stats["reads_limited"] += 1
            return
        self._param_lists[addr] = (deque(self.params_in.names), signed)

    def _send_param_lists(self) -> None:
        """The queued parameter lists' next entries, each begun only when its recent cost
        fits the tick's time; a list the time cut waits for the next tick (counted once a
        tick: ``params_deferred``)."""
        est = self.item_cost["param"]
        for addr in list(self._param_lists):
            names, signed = self._param_lists[addr]
            while names and self._reply_budget > 0:
                if not self._fits(est):
                    self.stats["params_deferred"] += 1
                    return
                if not (signed or self._take_read(addr)):
                    break
                t = self.budget.elapsed_ns()
                self._reply(self.params_in.value_msg(names.popleft()), addr)
                self._cost(est, t)
            if not names:
                del self._param_lists[addr]
            if self._reply_budget <= 0:
                return

    def _add_peer(self, addr) -> None:
        if self.peers.add(addr, self.clock()):
            self.stats["peers_added"] += 1

    def _refuse(self, event, text: str) -> None:
        self.fsw.events.emit(self.fsw.t_s, event, detail=text)

    def _take_reads(self, addr, n: int) -> int:
        """Up to ``n`` units of ``addr``'s read budget: how many it had."""
        got = 0
        while got < n and self._take_read(addr):
            got += 1
        return got

    def _ftp(self, msg, addr, signed: bool = True) -> None:
        """One MAVLink FTP request; what this tick can no longer send is dropped unanswered
        (counted: ``ftp_deferred``; the client retries). A burst is cut to the replies whose
        recent cost the tick's time still covers (at least one: the request was begun) and,
        unsigned, to the sender's read budget (its request took one unit: the first reply)."""
        if self._ftp_budget <= 0:
            self.stats["ftp_deferred"] += 1
            return
        est = self.item_cost["ftp"]
        budget = self._ftp_budget
        if self.in_tick and est.ns > 0:
            budget = max(1, min(budget, self.budget.left_ns() // est.ns))
        if not signed:                      # a burst's replies beyond the first, from the read budget
            payload = bytes(msg.payload)
            want = self.ftp.burst_packets if len(payload) > 3 and payload[3] == ftp.BURST else 1
            budget = 1 + self._take_reads(addr, min(want, self._ftp_budget, self._reply_budget) - 1)
        replies = self.ftp.handle(msg.payload, budget, client=addr)
        if not signed and len(replies) < budget:     # what a short burst did not use goes back
            self.reads.give_back(addr, budget - max(1, len(replies)))
        self._ftp_budget -= len(replies)
        for payload in replies:
            t = self.budget.elapsed_ns()
            reply = mav.MAVLink_file_transfer_protocol_message(0, msg.get_srcSystem(), msg.get_srcComponent(),
                                                               list(payload))
            if signed:
                self._send(reply, only=addr)
            else:
                self._reply(reply, addr)
            self._cost(est, t)

    def component_metadata(self):
        """COMPONENT_METADATA: where the general metadata file is, and its CRC."""
        general = self.files[metadata.GENERAL_PATH]
        return mav.MAVLink_component_metadata_message(int(max(0.0, self.fsw.t_s) * 1000.0) & 0xFFFFFFFF,
                                                      metadata.crc32(general),
                                                      metadata.mftp_uri(metadata.GENERAL_PATH).encode("ascii"))

    def _command(self, msg, addr, p: list[float], signed: bool = True) -> None:
        """A command: its COMMAND_ACK, then what was asked for, to the requester (a signed
        request for a broadcast answer excepted). Unsigned (a READ command): from the reply
        budget, each frame after the ACK and the first answer taking a unit of the
        requester's read budget."""
        replies, broadcast = [], False
        if msg.command in LINK_COMMANDS:
            result, why, replies, broadcast = self.services.execute(msg.command, p)
        else:
            result, why = self.commands_in.execute(msg.command, p)
        if result != CommandResult.ACCEPTED and why and signed:
            self._refuse(EV.CMD_REFUSED, why)
        self.commands[result] = self.commands.get(result, 0) + 1
        if result == CommandResult.ACCEPTED and signed:
            self.stats["commands_accepted"] += 1
        ack = mav.MAVLink_command_ack_message(msg.command, result, 0, 0, msg.get_srcSystem(),
                                              msg.get_srcComponent())
        if not signed:
            replies = replies[:1 + self._take_reads(addr, len(replies) - 1)] if len(replies) > 1 else replies
            for m in [ack, *replies]:
                self._reply(m, addr)
            return
        # to the requester only: another ground station waiting on the same command id
        # must not take this answer for its own; what was asked for follows the ACK
        self._send(ack, only=addr)
        for reply in replies:
            self._send(reply, only=None if broadcast else addr)

    # -------------------------------------------------------------- send side
    def _send(self, msg, extra=None, only=None) -> None:
        frame = self.link.pack(msg)
        if self._pack_only:                     # warm_up: encode, send nothing
            return
        for addr in ((only,) if only is not None else self.peers.destinations(self.gcs, self.clock(), extra)):
            try:
                self.sock.sendto(frame, addr)
                self.stats["tx_frames"] += 1
                self.stats["tx_bytes"] += len(frame)
            except OSError:
                self.stats["tx_errors"] += 1

    def schedule_now(self, name: str) -> None:
        """Stream ``name`` is due at the next tick (its rate was just changed)."""
        self.schedule.now(name)

    def _fits(self, est: RecentCost) -> bool:
        """Inside a tick: an item of the kind ``est`` estimates may be begun (it ends short
        of the budget's end reserve, schedule.py); outside one (a warm-up, a flush): always."""
        return not self.in_tick or self.budget.fits(est.ns)

    def _cost(self, est: RecentCost, t0_ns: int) -> None:
        """An item begun at ``t0_ns`` (budget.elapsed_ns) is done: its cost, to ``est``
        (inside a tick only: a warm-up's first encodings would inflate it)."""
        if self.in_tick:
            est.add(self.budget.elapsed_ns() - t0_ns)

    def system_status(self) -> int:
        return tm.system_status(self.fsw)

    def stream_messages(self, name: str) -> list:
        """The messages of stream ``name`` now, outside its schedule (a one-shot request)."""
        return self.streams.messages(name)

    def send_due(self, sensors=None) -> None:
        """Events (their share), the telemetry streams that are due (the longest-waiting
        first, while the tick's budget lasts: the rest stay due, counted), queued parameters
        and further events from what answers left (schedule.py)."""
        now = self.clock()
        fsw = self.fsw
        self.streams.sensors = sensors
        self._ftp_budget = FTP_REPLIES_PER_TICK
        ms = int(max(0.0, fsw.t_s) * 1000.0) & 0xFFFFFFFF
        self.fsw.events.release_held(fsw.t_s)
        self._send_events(EVENT_SHARE, forced=1)
        if fsw.modes.mode != self.streams.mode_sent and self.rates_hz["CURRENT_MODE"] > 0.0:
            self.schedule_now("CURRENT_MODE")                 # a mode change is told at once
        self.streams.send_due(now, ms)
        self._send_param_lists()
        self._send_events(self._reply_budget)                 # what answers left
        # the events left for a later tick, each counted once a tick it waits
        if not self._pack_only:
            self.stats["events_deferred"] += max(0, fsw.events.total - self._event_index)
        self._reply_budget = self.max_tx_per_tick - EVENT_SHARE

    def flush_events(self, max_frames: int = 256) -> None:
        """Send the events not sent yet (at most ``max_frames``): at shutdown, so what the
        FSW reported after its last tick reaches the ground too."""
        try:
            self._send_events(max_frames)
        except Exception:                       # shutting down: never raise from here
            log.exception("ground link: flushing events failed")

    def _send_events(self, budget: int, forced: int = 0) -> None:
        """The events of the FSW's event history not sent yet, in order, at most ``budget``
        frames (read by sequence number, so another consumer may ``drain()`` the queue;
        events the history's ring dropped before they went out are skipped, counted:
        ``events_missed``). Inside a tick each event is begun only when its recent cost fits
        the tick's time, the first ``forced`` whatever is left (the events never wait for
        good, however a flood or the streams use the budget); the rest wait for the next
        tick (``send_due`` counts them)."""
        events = self.fsw.events
        if self._event_index > events.total:      # a new event log
            self._event_index = 0
        first, new = events.since(self._event_index)
        self.stats["events_missed"] += first - self._event_index if new else 0
        est, frames = self.item_cost["event"], 0
        for k, ev in enumerate(new):
            n = self._event_frames(ev)
            if frames + n > budget:
                break
            if k >= forced and not self._fits(est):
                break
            t = self.budget.elapsed_ns()
            self._send_event(ev)
            self._cost(est, t)
            frames += n
            first += 1
        self._event_index = first

    def _event_frames(self, ev) -> int:
        """The frames event ``ev`` goes down as."""
        return 1

    def _send_event(self, ev) -> None:
        """Event ``ev`` to the ground: a STATUSTEXT."""
        self._send(tm.statustext(ev.severity, ev.text))
