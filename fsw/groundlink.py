"""The FSW's MAVLink 2 ground link (spec 40-interfaces.md, "MAVLink 2"): telemetry to the
ground station, signed commands and the parameter protocol from it.

Runs in the FSW process, OFF the control rate group: the executive calls ``tick()`` from
RG2 (or RG3), in the same thread as ``FlightSoftware.control_step`` and between cycles
(commands change FSW state, so they must not run concurrently with a control cycle).
``tick`` polls a non-blocking UDP socket (at most ``max_rx_per_tick`` datagrams), answers
what arrived, then sends the telemetry that is due; it never blocks and never raises on
anything that arrives from the network.

Addresses: telemetry goes to ``gcs`` (default udp:127.0.0.1:14550, the usual ground port)
and to every peer that sent an accepted *signed* frame within ``peer_timeout_s`` (so a
script such as ``ellipsled gse inject`` can command the vehicle while the console holds
14550, as MAVLink vehicles answer the sender). The link binds ``bind`` (default
udp:127.0.0.1:14555, "port 0" = ephemeral) on loopback.

Identity: system 1, component 1 (MAV_COMP_ID_AUTOPILOT1), MAV_TYPE_GENERIC (there is no
entry-capsule type), MAV_AUTOPILOT_GENERIC. HEARTBEAT.custom_mode = fsw Mode (0 STANDBY,
1 ENTRY, 2 SAFE), base_mode has CUSTOM_MODE_ENABLED and SAFETY_ARMED when the jets are
armed. system_status, first match wins:
  | condition                                      | MAV_STATE     |
  |------------------------------------------------|---------------|
  | mode SAFE                                      | EMERGENCY     |
  | a jet not NOMINAL in FDIR's active health, or the allocator degraded | CRITICAL |
  | mode STANDBY                                   | STANDBY       |
  | otherwise                                      | ACTIVE        |

Attitude telemetry is relative to the local NED frame at the vehicle (north, east, down
on the sphere, N and the planet frame coincide at t = 0): ATTITUDE (3-2-1 Euler) and
ATTITUDE_QUATERNION of C_BL, ATTITUDE_TARGET of the guidance reference C_RL with
omega_RN_R as body rates. Body rates are omega_BN_B. NAMED_VALUE_FLOAT: bank_deg,
bref_deg (reference), berr_deg (bank - reference, wrapped), mach, qbar_pa, alt_km.
ACTUATOR_OUTPUT_STATUS: actuator[i] = command of jet i+1 (0/1), slots 18..31 zero,
active = bits 0..17. STATUSTEXT: every event of ``fsw.events.history`` (read by index, so
another consumer may ``drain()`` the queue), severity 1:1, text <= 50 ASCII characters.

Commands (COMMAND_LONG, signed; answered by COMMAND_ACK to the sender):
  | command                        | params                                   | result |
  |--------------------------------|------------------------------------------|--------|
  | MAV_CMD_INJECT_FAILURE (420)   | p1 unit 101 (RCS jet), p2 type 0 OK=clear, 1 OFF, 2 STUCK, 4 WRONG (p4 = eta in (0,1)), p3 jet 0..18 (0 = all) | see below |
  | ELLIPSLED_CMD_SET_MODE         | p1 0 STANDBY / 1 ENTRY / 2 SAFE          | ACCEPTED, DENIED (transition not allowed) |
  | ELLIPSLED_CMD_ARM_JETS, MAV_CMD_COMPONENT_ARM_DISARM (400) | p1 1 arm / 0 disarm | ACCEPTED |
  | ELLIPSLED_CMD_FAULT_TOLERANCE  | p1 1 on / 0 off                          | ACCEPTED |
  | ELLIPSLED_CMD_FDIR_MARK_JET    | p1 jet 1..18, p2 ELLIPSLED_JET_HEALTH 0 healthy, 1 failed off, 2 stuck on, 3 degraded (p3 eta in (0,1)), 4 inhibited | ACCEPTED |
  | ELLIPSLED_CMD_FDIR_CLEAR       | p1 jet 0..18 (0 = all): latch, override and inhibit cleared | ACCEPTED |
  | ELLIPSLED_CMD_FDIR_SET_DELAY   | p1 delay [s] within fdir.delay_s bounds  | ACCEPTED |
  | anything else                  |                                          | UNSUPPORTED |
A parameter that is not a finite number of the allowed set/range is DENIED; an injection
with a failure unit other than 101 or a failure type other than 0/1/2/4 is UNSUPPORTED.
Injection is forwarded through ``inject(jet, kind, eta) -> bool`` (kind: 'clear' | 'off' |
'stuck' | 'degraded', the plant's words, sim/plant.py Plant.set_fault) and ACCEPTED only
if it returns True (the plant is reachable and took it). It returning False means "the
plant cannot take it now" (not connected): TEMPORARILY_REJECTED, the ground may retry;
raising ValueError means the plant refused the values: DENIED; any other exception:
FAILED. With no ``inject`` callback the vehicle has no plant to forward to: UNSUPPORTED.
Every refusal is also a STATUSTEXT (event source "link", WARNING) saying why.

Parameters: PARAM_REQUEST_LIST / PARAM_REQUEST_READ / PARAM_SET -> PARAM_VALUE for every
ground-settable parameter of ``fsw.param_table``, all as MAV_PARAM_TYPE_REAL32 (integer
parameters are checked to be integral by the FSW). Ids (<= 16 characters) are derived
deterministically by ``param_id``: a section prefix + the key in upper case, cut to 16
characters; in the unlikely case of a collision, later names (sorted) get "~1", "~2".. at
the end. The mapping for today's parameters (a test keeps this table current):

PARAM_ID_TABLE_BEGIN
  | FSW parameter              | MAVLink param_id   |
  |----------------------------|--------------------|
  | allocator.fault_tolerance  | A_FAULT_TOLERANC   |
  | allocator.penalty_per_N    | A_PENALTY_PER_N    |
  | allocator.w_pitch          | A_W_PITCH          |
  | allocator.w_roll           | A_W_ROLL           |
  | allocator.w_yaw            | A_W_YAW            |
  | control.d_max              | C_D_MAX            |
  | control.d_min              | C_D_MIN            |
  | control.deadzone           | C_DEADZONE         |
  | control.gamma_d            | C_GAMMA_D          |
  | control.gamma_h            | C_GAMMA_H          |
  | control.h_bound_frac       | C_H_BOUND_FRAC     |
  | control.h_prod_scale       | C_H_PROD_SCALE     |
  | control.int_limit          | C_INT_LIMIT        |
  | control.lambda_radps       | C_LAMBDA_RADPS     |
  | control.q_weight           | C_Q_WEIGHT         |
  | control.safe_rate_gain     | C_SAFE_RATE_GAIN   |
  | control.shortfall_frac     | C_SHORTFALL_FRAC   |
  | control.sigma_switch       | C_SIGMA_SWITCH     |
  | driver.arm_on_entry        | D_ARM_ON_ENTRY     |
  | fdir.accel_max_mps2        | F_ACCEL_MAX_MPS2   |
  | fdir.alt_max_m             | F_ALT_MAX_M        |
  | fdir.chamber_hi            | F_CHAMBER_HI       |
  | fdir.chamber_lo            | F_CHAMBER_LO       |
  | fdir.degraded_hi           | F_DEGRADED_HI      |
  | fdir.degraded_lo           | F_DEGRADED_LO      |
  | fdir.delay_s               | F_DELAY_S          |
  | fdir.off_threshold         | F_OFF_THRESHOLD    |
  | fdir.omega_max_radps       | F_OMEGA_MAX_RADP   |
  | fdir.on_threshold          | F_ON_THRESHOLD     |
  | fdir.persist_n             | F_PERSIST_N        |
  | fdir.r_below_m             | F_R_BELOW_M        |
  | fdir.res_persist_s         | F_RES_PERSIST_S    |
  | fdir.res_rel               | F_RES_REL          |
  | fdir.res_tau_s             | F_RES_TAU_S        |
  | fdir.res_thr_Nm            | F_RES_THR_NM       |
  | fdir.safe_track_deg        | F_SAFE_TRACK_DEG   |
  | fdir.safe_track_s          | F_SAFE_TRACK_S     |
  | fdir.sigma_tol             | F_SIGMA_TOL        |
  | fdir.stale_n               | F_STALE_N          |
  | fdir.v_max_mps             | F_V_MAX_MPS        |
  | guidance.authority_use     | G_AUTHORITY_USE    |
  | guidance.trim_max_deg      | G_TRIM_MAX_DEG     |
PARAM_ID_TABLE_END

A refused PARAM_SET is answered with the unchanged value and a STATUSTEXT (WARNING)
"<ID> REFUSED: <reason>". Param ids are matched case-insensitively.

Security (interfaces/mavlink/signing.py, verify-first): every frame sent is signed; every
frame received is verified before decoding. Accepted unsigned: HEARTBEAT (the ground
station's presence, authorises nothing) and the parameter *reads* PARAM_REQUEST_LIST /
PARAM_REQUEST_READ (they change nothing, so a stock ground station without the key can
list parameters); commands and PARAM_SET must be signed. Rejections are counted
(``rejections``, per reason) and reported as FSW events (source "link", WARNING,
rate-limited per code).
"""
from __future__ import annotations

import logging
import math
import socket
import time
from collections import deque
from collections.abc import Callable, Mapping

import numpy as np

from common import frames, mrp
from common.frames import local_axes
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing import SignedLink, SigningKey, Rejection

from common.events import Severity
from interfaces.records import FAULT_NAMES
from interfaces.vocabulary import (DEFAULT_GCS, DEFAULT_VEHICLE, INHIBITED, MARK_KINDS, N_JETS, NOMINAL, Mode,
                                   parse_udp)

log = logging.getLogger(__name__)

SYSTEM_ID = 1
COMPONENT_ID = mav.MAV_COMP_ID_AUTOPILOT1        # 1
PARAM_ID_LEN = 16
STATUSTEXT_LEN = 50
NAMED_VALUE_LEN = 10

DEFAULT_BIND = DEFAULT_VEHICLE

PARAM_PREFIX = {"control": "C_", "allocator": "A_", "fdir": "F_", "driver": "D_", "executive": "X_",
                "guidance": "G_"}

# Telemetry streams and their default rates [Hz]; 0 disables a stream. The achieved rate
# is at most the rate at which tick() is called.
DEFAULT_RATES_HZ: dict[str, float] = {
    "HEARTBEAT": 1.0,
    "SYS_STATUS": 1.0,
    "ATTITUDE": 10.0,
    "ATTITUDE_QUATERNION": 10.0,
    "ATTITUDE_TARGET": 10.0,
    "ACTUATOR_OUTPUT_STATUS": 10.0,
    "NAMED_VALUE_FLOAT": 5.0,
    "ELLIPSLED_ENTRY_STATE": 5.0,
    "ELLIPSLED_JET_STATUS": 5.0,
    "ELLIPSLED_CONTROL_STATUS": 5.0,
    "ELLIPSLED_LOOP_TIMING": 1.0,
}
MAX_RATE_HZ = 100.0
DUE_SLACK = 0.05         # a stream may go out up to 5 % of its period early

# Messages a ground station may send unsigned (see the module docstring).
ALLOW_UNSIGNED = frozenset({mav.MAVLINK_MSG_ID_HEARTBEAT, mav.MAVLINK_MSG_ID_PARAM_REQUEST_LIST,
                            mav.MAVLINK_MSG_ID_PARAM_REQUEST_READ})

MARK_NAMES = {code: kind for kind, code in MARK_KINDS.items()}   # ELLIPSLED_CMD_FDIR_MARK_JET p2 -> kind

InjectFn = Callable[[int, str, float], bool]


# ------------------------------------------------------------------ helpers

def param_id(name: str) -> str:
    """MAVLink param_id (<= 16 chars) of an FSW parameter "section.key" (collisions aside)."""
    section, key = name.split(".", 1)
    prefix = PARAM_PREFIX.get(section, section[:1].upper() + "_")
    return (prefix + key.upper())[:PARAM_ID_LEN]


def param_ids(names) -> dict[str, str]:
    """{fsw name: param_id} for a set of names, unique: sorted order, later colliding
    names get "~1", "~2", ... in their last characters."""
    out: dict[str, str] = {}
    used: set[str] = set()
    for name in sorted(names):
        pid = param_id(name)
        n = 0
        while pid in used:
            n += 1
            suffix = f"~{n}"
            pid = param_id(name)[:PARAM_ID_LEN - len(suffix)] + suffix
        used.add(pid)
        out[name] = pid
    return out


def _ascii(text: str, n: int) -> bytes:
    return str(text).encode("ascii", "replace")[:n]


def _local_ned_dcm(r_N: np.ndarray) -> np.ndarray:
    """C_LN: rows north, east, down at r_N (spherical planet, N3 = spin axis)."""
    north, east, up = local_axes(r_N)
    return np.vstack((north, east, -up))


def euler321(C: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) [rad] of C = R1(roll) R2(pitch) R3(yaw)."""
    pitch = -math.asin(max(-1.0, min(1.0, float(C[0, 2]))))
    return math.atan2(C[1, 2], C[2, 2]), pitch, math.atan2(C[0, 1], C[0, 0])


def _is_int_in(x: float, lo: int, hi: int) -> bool:
    return math.isfinite(x) and float(x).is_integer() and lo <= x <= hi


# ------------------------------------------------------------------ the link

class GroundLink:
    """MAVLink 2 ground link of one FlightSoftware (see the module docstring).

    fsw      fsw.flightsoftware.FlightSoftware (read for telemetry, commanded).
    key      SigningKey shared with the ground station.
    gcs      "udp:HOST:PORT" the telemetry goes to.
    bind     "udp:HOST:PORT" the link listens on (port 0 = ephemeral; see ``address``).
    inject   callback forwarding a fault injection to the plant (may be None).
    rates    {stream: Hz} overriding DEFAULT_RATES_HZ.
    clock    monotonic time [s] for telemetry scheduling (tests pass a fake one).
    """

    def __init__(self, fsw, key: SigningKey, *, gcs: str = DEFAULT_GCS, bind: str = DEFAULT_BIND,
                 inject: InjectFn | None = None, rates: Mapping[str, float] | None = None,
                 clock: Callable[[], float] = time.monotonic, max_rx_per_tick: int = 64,
                 max_tx_per_tick: int = 64, peer_timeout_s: float = 10.0, max_peers: int = 4):
        if not isinstance(key, SigningKey):
            raise TypeError("key must be a SigningKey (interfaces.mavlink.signing)")
        self.fsw = fsw
        self.inject = inject
        self.clock = clock
        self.max_rx_per_tick = int(max_rx_per_tick)
        self.max_tx_per_tick = int(max_tx_per_tick)
        self.peer_timeout_s = float(peer_timeout_s)
        self.max_peers = int(max_peers)
        self.rates_hz = self._check_rates(rates)
        self.gcs = parse_udp(gcs, "gcs")
        bind_addr = parse_udp(bind, "bind")

        self.link = SignedLink(key, system_id=SYSTEM_ID, component_id=COMPONENT_ID,
                               allow_unsigned=ALLOW_UNSIGNED, on_reject=self._on_reject)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind(bind_addr)
        except OSError as e:
            self.sock.close()
            raise OSError(f"ground link cannot bind {bind}: {e.strerror or e}") from None
        self.sock.setblocking(False)
        self._rxbuf = bytearray(65536)

        # parameters
        settable = [n for n, p in fsw.param_table.items() if p.ground_settable]
        self.param_of_name = param_ids(settable)
        self.param_names = sorted(settable)                               # index order
        self._name_of_id = {pid.upper(): n for n, pid in self.param_of_name.items()}
        self._param_queue: deque[str] = deque()

        # state
        self.peers: dict[tuple[str, int], float] = {}                     # addr -> last signed rx
        self._next_due = {name: 0.0 for name in self.rates_hz}
        self._event_index = 0                          # the start-up events go out too
        self._pack_only = False                        # warm_up packs without sending
        self._loop_timing: dict[int, tuple] = {}
        self._alloc_ns: deque[int] = deque(maxlen=512)
        self._alloc_degraded = 0
        self.rejections = 0
        self.ground_heartbeat_t: float | None = None                     # clock() of last GCS heartbeat
        self.commands: dict[int, int] = {}                               # MAV_RESULT -> count
        self.stats = {"rx_datagrams": 0, "rx_bytes": 0, "rx_messages": 0, "tx_frames": 0,
                      "tx_bytes": 0, "tx_errors": 0}
        self.tick_ns_max = 0
        self._handlers = {
            mav.MAV_CMD_INJECT_FAILURE: self._cmd_inject,
            mav.ELLIPSLED_CMD_SET_MODE: self._cmd_mode,
            mav.ELLIPSLED_CMD_ARM_JETS: self._cmd_arm,
            mav.MAV_CMD_COMPONENT_ARM_DISARM: self._cmd_arm,
            mav.ELLIPSLED_CMD_FAULT_TOLERANCE: self._cmd_ft,
            mav.ELLIPSLED_CMD_FDIR_MARK_JET: self._cmd_mark,
            mav.ELLIPSLED_CMD_FDIR_CLEAR: self._cmd_clear,
            mav.ELLIPSLED_CMD_FDIR_SET_DELAY: self._cmd_delay,
        }

    # -------------------------------------------------------------- configuration
    @staticmethod
    def _check_rates(rates: Mapping[str, float] | None) -> dict[str, float]:
        out = dict(DEFAULT_RATES_HZ)
        for name, hz in (rates or {}).items():
            if name not in DEFAULT_RATES_HZ:
                raise ValueError(f"rates: unknown stream {name!r} (known: {', '.join(DEFAULT_RATES_HZ)})")
            if isinstance(hz, bool) or not isinstance(hz, (int, float)) or not math.isfinite(hz) \
                    or not 0.0 <= hz <= MAX_RATE_HZ:
                raise ValueError(f"rates.{name}: must be a number in [0, {MAX_RATE_HZ:g}] Hz, got {hz!r}")
            out[name] = float(hz)
        return out

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

    def set_loop_timing(self, rate_group: int, *, jitter_p50_us: float, jitter_p99_us: float,
                        jitter_max_us: float, compute_p50_us: float, compute_p99_us: float,
                        compute_max_us: float, cycle_slips: int) -> None:
        """Latest timing statistics of one rate group (from the executive), sent as
        ELLIPSLED_LOOP_TIMING (one message per rate group at that stream's rate)."""
        self._loop_timing[int(rate_group)] = (jitter_p50_us, jitter_p99_us, jitter_max_us, compute_p50_us,
                                              compute_p99_us, compute_max_us, int(cycle_slips))

    # -------------------------------------------------------------- the tick
    def tick(self, sensors=None) -> None:
        """Call from RG2/RG3: receive and answer (bounded), then send what is due.
        ``sensors``: the latest SENSORS record (for "firing" from the chamber pressures)."""
        t0 = time.perf_counter_ns()
        try:
            self.poll()
            self._sample_allocator()
            self.send_due(sensors)
        except Exception:                       # the link must never take the FSW down
            log.exception("ground link tick failed")
        self.tick_ns_max = max(self.tick_ns_max, time.perf_counter_ns() - t0)

    def warm_up(self, spare_fsw, sensors=None) -> None:
        """Encode (pack) every telemetry message once from ``spare_fsw`` — a throwaway
        FlightSoftware that has flown a cycle — and send nothing: the first encode of each
        message type costs milliseconds, which would otherwise land in the first real-time
        cycles. Schedules, counters and the link's sequence numbers are left as they were."""
        saved = (self.fsw, dict(self._next_due), self._event_index, self.link.signer.seq)
        self.fsw = spare_fsw
        self._pack_only = True
        try:
            self.send_due(sensors)
            self._send(self._param_value_msg(next(iter(self.param_of_name))))
            self._send(mav.MAVLink_statustext_message(int(Severity.INFO), b"warm-up"))
        except Exception:                       # a warm-up failure must not stop the FSW
            log.exception("ground link warm-up failed")
        finally:
            self.fsw, self._next_due, self._event_index, self.link.signer.seq = saved
            self._pack_only = False

    def poll(self) -> int:
        """Receive at most ``max_rx_per_tick`` datagrams without blocking; returns how many."""
        n = 0
        view = memoryview(self._rxbuf)
        while n < self.max_rx_per_tick:
            try:
                size, addr = self.sock.recvfrom_into(self._rxbuf)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:                     # e.g. ICMP errors reported on a later recv
                self.stats["tx_errors"] += 1
                continue
            n += 1
            self.stats["rx_datagrams"] += 1
            self.stats["rx_bytes"] += size
            for msg in self.link.receive(view[:size]):
                self.stats["rx_messages"] += 1
                try:
                    self.handle(msg, addr)
                except Exception:
                    log.exception("ground link: handling %s failed", msg.get_type())
        return n

    # -------------------------------------------------------------- receive side
    def _on_reject(self, rej: Rejection) -> None:
        self.rejections += 1
        self.fsw.events.emit(self.fsw.t_s, Severity.WARNING, "link", "link_reject", rej.text(),
                             rate_limited=True)

    def handle(self, msg, addr: tuple[str, int]) -> None:
        """Act on one verified, decoded message that arrived from ``addr``."""
        signed = bool(msg.get_signed())
        mid = msg.get_msgId()
        if signed:
            self._add_peer(addr)
        if mid == mav.MAVLINK_MSG_ID_HEARTBEAT:
            if msg.type == mav.MAV_TYPE_GCS:
                self.ground_heartbeat_t = self.clock()
            return
        if mid == mav.MAVLINK_MSG_ID_COMMAND_LONG:
            if signed and self._for_me(msg):
                self._command(msg, addr)
            return
        if mid == mav.MAVLINK_MSG_ID_PARAM_REQUEST_LIST:
            if self._for_me(msg):
                self._param_queue.extend(n for n in self.param_names if n not in self._param_queue)
            return
        if mid == mav.MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            if self._for_me(msg):
                self._param_read(msg, addr)
            return
        if mid == mav.MAVLINK_MSG_ID_PARAM_SET:
            if signed and self._for_me(msg):
                self._param_set(msg, addr)
            return

    @staticmethod
    def _for_me(msg) -> bool:
        return msg.target_system in (0, SYSTEM_ID) and msg.target_component in (0, COMPONENT_ID)

    def _add_peer(self, addr) -> None:
        now = self.clock()
        self.peers[addr] = now
        for a, t in list(self.peers.items()):
            if now - t > self.peer_timeout_s:
                del self.peers[a]
        while len(self.peers) > self.max_peers:
            oldest = min(self.peers, key=self.peers.get)
            del self.peers[oldest]

    # -------------------------------------------------------------- commands
    def _refuse(self, code: str, text: str) -> None:
        self.fsw.events.emit(self.fsw.t_s, Severity.WARNING, "link", code, text[:STATUSTEXT_LEN])

    def _command(self, msg, addr) -> None:
        handler = self._handlers.get(msg.command)
        if handler is None:
            result, why = mav.MAV_RESULT_UNSUPPORTED, f"CMD {msg.command} UNSUPPORTED"
        else:
            p = [msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6, msg.param7]
            result, why = handler(p)
        if result != mav.MAV_RESULT_ACCEPTED and why:
            self._refuse("cmd_refused", why)
        self.commands[result] = self.commands.get(result, 0) + 1
        ack = mav.MAVLink_command_ack_message(msg.command, result, 0, 0, msg.get_srcSystem(),
                                              msg.get_srcComponent())
        # to the requester only: another ground station waiting on the same command id
        # must not take this answer for its own
        self._send(ack, only=addr)

    def _reconfigure(self) -> None:
        """FDIR's active health changed by a ground command: the allocator adopts it now."""
        self.fsw.health_changed()

    def _cmd_inject(self, p) -> tuple[int, str]:
        unit, ftype, jet, eta = p[0], p[1], p[2], p[3]
        if not _is_int_in(unit, 0, 1000) or int(unit) != mav.FAILURE_UNIT_SYSTEM_MOTOR:
            return mav.MAV_RESULT_UNSUPPORTED, f"INJECT UNIT {unit:g} UNSUPPORTED (101=JET)"
        if not _is_int_in(ftype, 0, 1000) or int(ftype) not in FAULT_NAMES:
            return mav.MAV_RESULT_UNSUPPORTED, f"INJECT TYPE {ftype:g} UNSUPPORTED"
        if not _is_int_in(jet, 0, N_JETS):
            return mav.MAV_RESULT_DENIED, f"INJECT JET {jet:g} DENIED (1..{N_JETS}, 0=ALL)"
        kind = FAULT_NAMES[int(ftype)]
        if kind == "degraded":
            if not (math.isfinite(eta) and 0.0 < eta < 1.0):
                return mav.MAV_RESULT_DENIED, f"INJECT ETA {eta:g} DENIED (0<ETA<1)"
            eta = float(eta)
        else:
            eta = 1.0
        if self.inject is None:
            return mav.MAV_RESULT_UNSUPPORTED, "INJECT UNSUPPORTED: NO PLANT LINK"
        jet = int(jet)
        try:
            ok = self.inject(jet, kind, eta)
        except ValueError as e:
            return mav.MAV_RESULT_DENIED, f"INJECT DENIED BY PLANT: {e}"
        except Exception as e:
            log.exception("inject callback failed")
            return mav.MAV_RESULT_FAILED, f"INJECT FAILED: {type(e).__name__}"
        if ok is not True:
            return mav.MAV_RESULT_TEMPORARILY_REJECTED, "INJECT REJECTED: PLANT UNAVAILABLE"
        who = "ALL JETS" if jet == 0 else f"JET {jet}"
        self.fsw.events.emit(self.fsw.t_s, Severity.NOTICE, "link", "inject",
                             f"GND INJECT {who} {kind.upper()}" + (f" ETA {eta:.2f}" if kind == "degraded" else ""))
        return mav.MAV_RESULT_ACCEPTED, ""

    def _cmd_mode(self, p) -> tuple[int, str]:
        if not _is_int_in(p[0], 0, 2):
            return mav.MAV_RESULT_DENIED, f"MODE {p[0]:g} DENIED (0 STBY,1 ENTRY,2 SAFE)"
        target = Mode(int(p[0]))
        if self.fsw.modes.request(self.fsw.t_s, target, "ground"):
            return mav.MAV_RESULT_ACCEPTED, ""
        return mav.MAV_RESULT_DENIED, ""          # ModeManager already said why

    def _cmd_arm(self, p) -> tuple[int, str]:
        if not _is_int_in(p[0], 0, 1):
            return mav.MAV_RESULT_DENIED, f"ARM {p[0]:g} DENIED (1 ARM, 0 DISARM)"
        self.fsw.driver.arm(self.fsw.t_s, bool(p[0]))
        return mav.MAV_RESULT_ACCEPTED, ""

    def _cmd_ft(self, p) -> tuple[int, str]:
        if not _is_int_in(p[0], 0, 1):
            return mav.MAV_RESULT_DENIED, f"FAULT TOLERANCE {p[0]:g} DENIED (1 ON, 0 OFF)"
        on = bool(p[0])
        self.fsw.set_param("allocator.fault_tolerance", float(on))
        self.fsw.events.emit(self.fsw.t_s, Severity.NOTICE, "link", "fault_tolerance",
                             f"GND FAULT TOLERANCE {'ON' if on else 'OFF'}")
        return mav.MAV_RESULT_ACCEPTED, ""

    def _cmd_mark(self, p) -> tuple[int, str]:
        jet, kind_code, eta = p[0], p[1], p[2]
        if not _is_int_in(jet, 1, N_JETS):
            return mav.MAV_RESULT_DENIED, f"MARK JET {jet:g} DENIED (1..{N_JETS})"
        if not _is_int_in(kind_code, 0, 255) or int(kind_code) not in MARK_NAMES:
            return mav.MAV_RESULT_DENIED, f"MARK KIND {kind_code:g} DENIED (0..4)"
        kind = MARK_NAMES[int(kind_code)]
        jet = int(jet)
        t = self.fsw.t_s
        if kind == "inhibited":
            self.fsw.driver.set_inhibit(t, jet, True)
            self.fsw.fdir.set_inhibit(t, jet, True)
        else:
            if kind == "degraded" and not (math.isfinite(eta) and 0.0 < eta < 1.0):
                return mav.MAV_RESULT_DENIED, f"MARK ETA {eta:g} DENIED (0<ETA<1)"
            try:
                self.fsw.fdir.override(t, jet, kind, float(eta) if kind == "degraded" else 1.0)
            except ValueError as e:
                return mav.MAV_RESULT_DENIED, f"MARK DENIED: {e}"
        self._reconfigure()
        return mav.MAV_RESULT_ACCEPTED, ""

    def _cmd_clear(self, p) -> tuple[int, str]:
        if not _is_int_in(p[0], 0, N_JETS):
            return mav.MAV_RESULT_DENIED, f"CLEAR JET {p[0]:g} DENIED (0..{N_JETS})"
        jet, t = int(p[0]), self.fsw.t_s
        self.fsw.fdir.clear(t, jet)
        self.fsw.driver.set_inhibit(t, jet, False)
        self.fsw.fdir.set_inhibit(t, jet, False)
        self._reconfigure()
        return mav.MAV_RESULT_ACCEPTED, ""

    def _cmd_delay(self, p) -> tuple[int, str]:
        try:
            v = self.fsw.set_param("fdir.delay_s", p[0])
        except ValueError as e:
            return mav.MAV_RESULT_DENIED, f"DELAY DENIED: {str(e).split(': ', 1)[-1]}"
        self.fsw.fdir.set_delay(v, self.fsw.t_s)        # the event "FDIR DELAY x S"
        return mav.MAV_RESULT_ACCEPTED, ""

    # -------------------------------------------------------------- parameters
    def _lookup(self, raw_id) -> str | None:
        pid = raw_id.decode("ascii", "replace") if isinstance(raw_id, bytes) else str(raw_id)
        return self._name_of_id.get(pid.rstrip("\x00").upper())

    def _param_value_msg(self, name: str):
        return mav.MAVLink_param_value_message(
            self.param_of_name[name].encode("ascii"), float(self.fsw.params[name]),
            mav.MAV_PARAM_TYPE_REAL32, len(self.param_names), self.param_names.index(name))

    def _param_read(self, msg, addr) -> None:
        if msg.param_index >= 0:
            if msg.param_index >= len(self.param_names):
                self._refuse("param_unknown", f"PARAM INDEX {msg.param_index} UNKNOWN")
                return
            name = self.param_names[msg.param_index]
        else:
            name = self._lookup(msg.param_id)
            if name is None:
                self._refuse("param_unknown", f"PARAM {self._id_text(msg.param_id)} UNKNOWN")
                return
        self._send(self._param_value_msg(name), extra=addr)

    @staticmethod
    def _id_text(raw) -> str:
        s = raw.decode("ascii", "replace") if isinstance(raw, bytes) else str(raw)
        return s.rstrip("\x00")[:PARAM_ID_LEN]

    def _param_set(self, msg, addr) -> None:
        name = self._lookup(msg.param_id)
        if name is None:
            self._refuse("param_unknown", f"PARAM {self._id_text(msg.param_id)} UNKNOWN")
            return
        try:
            self.fsw.set_param(name, float(msg.param_value))
        except ValueError as e:
            reason = str(e).split(": ", 1)[-1]
            self._refuse("param_refused", f"{self.param_of_name[name]} REFUSED: {reason}")
        self._send(self._param_value_msg(name), extra=addr)     # new value, or unchanged

    # -------------------------------------------------------------- send side
    def _destinations(self, extra=None) -> list[tuple[str, int]]:
        now = self.clock()
        dest = [self.gcs]
        for a, t in self.peers.items():
            if now - t <= self.peer_timeout_s and a not in dest:
                dest.append(a)
        if extra is not None and extra not in dest:
            dest.append(extra)
        return dest

    def _send(self, msg, extra=None, only=None) -> None:
        frame = self.link.pack(msg)
        if self._pack_only:                     # warm_up: encode, send nothing
            return
        for addr in ((only,) if only is not None else self._destinations(extra)):
            try:
                self.sock.sendto(frame, addr)
                self.stats["tx_frames"] += 1
                self.stats["tx_bytes"] += len(frame)
            except OSError:
                self.stats["tx_errors"] += 1

    def _sample_allocator(self) -> None:
        self._alloc_ns.append(int(getattr(self.fsw, "alloc_ns", 0)))
        if self.fsw.allocator.degraded:
            self._alloc_degraded += 1

    def _due(self, name: str, now: float) -> bool:
        hz = self.rates_hz[name]
        if hz <= 0.0:
            return False
        period = 1.0 / hz
        if now < self._next_due[name] - DUE_SLACK * period:     # slack: tick jitter must not skip a period
            return False
        nxt = self._next_due[name] + period
        self._next_due[name] = nxt if nxt > now else now + period
        return True

    def system_status(self) -> int:
        fsw = self.fsw
        mode = fsw.modes.mode
        if mode == Mode.SAFE:
            return mav.MAV_STATE_EMERGENCY
        if np.any(fsw.fdir.health_active.state != NOMINAL) or fsw.allocator.degraded:
            return mav.MAV_STATE_CRITICAL
        if mode == Mode.STANDBY:
            return mav.MAV_STATE_STANDBY
        return mav.MAV_STATE_ACTIVE

    def send_due(self, sensors=None) -> None:
        """Send every telemetry stream that is due, queued parameters and new events."""
        now = self.clock()
        fsw = self.fsw
        ms = int(max(0.0, fsw.t_s) * 1000.0) & 0xFFFFFFFF
        sent = 0
        if self._due("HEARTBEAT", now):
            base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mav.MAV_MODE_FLAG_SAFETY_ARMED if fsw.driver.armed else 0)
            self._send(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GENERIC, mav.MAV_AUTOPILOT_GENERIC, base,
                                                     int(fsw.modes.mode), self.system_status(), 3))
        if self._due("SYS_STATUS", now):
            self._send(self._sys_status())
        nav_ok = fsw.k >= 0 and float(np.dot(fsw.nav.state.r_N, fsw.nav.state.r_N)) > 1.0
        if nav_ok:
            sent += self._send_attitude(now, ms)
        if self._due("ACTUATOR_OUTPUT_STATUS", now):
            act = [0.0] * 32
            act[:N_JETS] = [float(x) for x in fsw.driver.last_command]
            self._send(mav.MAVLink_actuator_output_status_message(int(fsw.t_s * 1e6), (1 << N_JETS) - 1, act))
        if self._due("ELLIPSLED_JET_STATUS", now):
            self._send(self._jet_status(ms, sensors))
        if self._due("ELLIPSLED_CONTROL_STATUS", now):
            self._send(self._control_status(ms))
        if self._due("ELLIPSLED_LOOP_TIMING", now):
            for rg, v in sorted(self._loop_timing.items()):
                self._send(mav.MAVLink_ellipsled_loop_timing_message(ms, *v[:6], v[6] & 0xFFFFFFFF, rg & 0xFF))
        budget = self.max_tx_per_tick
        while self._param_queue and budget > 0:
            self._send(self._param_value_msg(self._param_queue.popleft()))
            budget -= 1
        self._send_events(budget)

    def _send_events(self, budget: int) -> None:
        hist = self.fsw.events.history
        if self._event_index > len(hist):         # history was reset by its owner
            self._event_index = 0
        while self._event_index < len(hist) and budget > 0:
            ev = hist[self._event_index]
            self._event_index += 1
            budget -= 1
            self._send(mav.MAVLink_statustext_message(int(ev.severity), _ascii(ev.text, STATUSTEXT_LEN)))

    def _sys_status(self):
        S = mav
        present = (S.MAV_SYS_STATUS_SENSOR_3D_GYRO | S.MAV_SYS_STATUS_SENSOR_3D_ACCEL
                   | S.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION | S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
        enabled = present if self.fsw.driver.armed else present & ~S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        health = present
        if np.any(self.fsw.fdir.health_active.state != NOMINAL):
            health &= ~S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        if getattr(self.fsw.monitor, "stale", False):
            health &= ~(S.MAV_SYS_STATUS_SENSOR_3D_GYRO | S.MAV_SYS_STATUS_SENSOR_3D_ACCEL)
        load = 0
        if 1 in self._loop_timing or 0 in self._loop_timing:
            rg = self._loop_timing.get(0) or self._loop_timing.get(1)
            load = int(round(min(1000.0, max(0.0, rg[3] * 1e-6 / self.fsw.dt_s * 1000.0))))
        return mav.MAVLink_sys_status_message(present, enabled, health, load, 0xFFFF, -1, -1, 0,
                                              min(self.rejections, 0xFFFF), 0, 0, 0, 0)

    def _send_attitude(self, now: float, ms: int) -> int:
        fsw = self.fsw
        nav, g = fsw.nav.state, fsw.guidance
        want = [self._due(n, now) for n in ("ATTITUDE", "ATTITUDE_QUATERNION", "ATTITUDE_TARGET",
                                            "NAMED_VALUE_FLOAT", "ELLIPSLED_ENTRY_STATE")]
        if not any(want):
            return 0
        C_LN = _local_ned_dcm(nav.r_N)
        w = nav.omega_BN_B
        if want[0] or want[1]:
            C_BL = nav.C_BN @ C_LN.T
            if want[0]:
                roll, pitch, yaw = euler321(C_BL)
                self._send(mav.MAVLink_attitude_message(ms, roll, pitch, yaw, w[0], w[1], w[2]))
            if want[1]:
                q = mrp.dcm_to_quat(C_BL)
                self._send(mav.MAVLink_attitude_quaternion_message(ms, q[0], q[1], q[2], q[3], w[0], w[1], w[2]))
        if want[2]:
            q = mrp.dcm_to_quat(mrp.to_dcm(g.sigma_RN) @ C_LN.T)
            wr = g.omega_RN_R
            self._send(mav.MAVLink_attitude_target_message(
                ms, mav.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE, [float(x) for x in q], wr[0], wr[1], wr[2], 0.0))
        if want[3]:
            bank_err = frames.wrap_pi(nav.bank_rad - g.phi_r)
            for name, value in (("bank_deg", math.degrees(nav.bank_rad)), ("bref_deg", math.degrees(g.phi_r)),
                                ("berr_deg", math.degrees(bank_err)), ("mach", nav.mach),
                                ("qbar_pa", nav.qbar_pa), ("alt_km", nav.h_m * 1e-3)):
                self._send(mav.MAVLink_named_value_float_message(ms, name.encode(), float(value)))
        if want[4]:
            self._send(self._entry_state(ms, C_LN))
        return 1

    def _entry_state(self, ms: int, C_LN: np.ndarray):
        fsw = self.fsw
        nav = fsw.nav.state
        north, east, down = C_LN
        V = max(nav.V_rel_mps, 1e-9)
        gamma = math.asin(max(-1.0, min(1.0, -float(nav.vrel_N @ down) / V)))
        psi = math.atan2(float(nav.vrel_N @ east), float(nav.vrel_N @ north))
        r = float(np.linalg.norm(nav.r_N))
        lat = math.asin(max(-1.0, min(1.0, nav.r_N[2] / r)))
        lon = frames.wrap_pi(math.atan2(nav.r_N[1], nav.r_N[0]) - fsw.scenario.planet.omega_radps * fsw.t_s)
        return mav.MAVLink_ellipsled_entry_state_message(
            ms, nav.h_m, nav.V_rel_mps, gamma, psi, lat, lon, nav.mach, nav.qbar_pa, nav.alpha_rad,
            nav.beta_rad, nav.bank_rad, fsw.guidance.phi_r)

    def _jet_status(self, ms: int, sensors):
        fsw = self.fsw
        h = fsw.fdir.health_active
        health = [int(s) for s in h.state]
        for i in range(N_JETS):
            if h.inhibited[i] and health[i] == NOMINAL:
                health[i] = INHIBITED
        cmd = int(np.dot(fsw.driver.last_command.astype(np.int64) != 0, 1 << np.arange(N_JETS, dtype=np.int64)))
        firing = 0
        if sensors is not None:
            on = np.asarray(sensors["chamber"]) > fsw.params["fdir.on_threshold"]
            firing = int(np.dot(on.astype(np.int64), 1 << np.arange(N_JETS, dtype=np.int64)))
        return mav.MAVLink_ellipsled_jet_status_message(
            ms, cmd, firing, health, [float(x) for x in h.effective_eta()],
            [int(min(x, 0xFFFFFFFF)) for x in fsw.driver.pulses], [float(x) for x in fsw.driver.on_time_s])

    def _control_status(self, ms: int):
        fsw = self.fsw
        a = np.fromiter(self._alloc_ns, dtype=np.int64)
        p99 = float(np.percentile(a, 99)) * 1e-3 if a.size else 0.0
        return mav.MAVLink_ellipsled_control_status_message(
            ms, [float(x) for x in fsw.u_cal_B], [float(x) for x in fsw.tau_alloc_B],
            [float(x) for x in fsw.control.theta_hat], int(fsw.cycles) & 0xFFFFFFFF, p99,
            self._alloc_degraded & 0xFFFFFFFF)


__all__ = ["GroundLink", "param_id", "param_ids", "parse_udp", "DEFAULT_RATES_HZ", "DEFAULT_GCS",
           "DEFAULT_BIND", "euler321"]
