"""A hostile ground: floods the vehicle's MAVLink port with what a radio can bring.

``python -m ellipsled.bench.flood --target udp:127.0.0.1:14555 --rate 2500 --seconds 12``
sends, at ``rate`` datagrams per second (paced every millisecond), a seeded mix of:

| kind        | what                                                                      |
|-------------|---------------------------------------------------------------------------|
| random      | 1..300 random bytes                                                       |
| malformed   | a signed COMMAND_LONG frame truncated, or with its length byte or CRC wrong |
| unsigned    | a well-formed unsigned COMMAND_LONG (disarm) and PARAM_SET                |
| badsig      | COMMAND_LONG / PARAM_SET signed with another key (current and future time) |
| replay      | genuine signed frames captured earlier (``--replay FILE``, .tlog records)  |
| oversized   | a 60,000-byte datagram of back-to-back bad frames and noise               |
| reads       | unsigned read-only requests: PARAM_REQUEST_READ (known and unknown ids),  |
|             | PARAM_REQUEST_LIST, MISSION_REQUEST_LIST (their answers come back here)  |
| reflected   | frames the vehicle signed itself, sent back to it: its answers to the     |
|             | reads above, and its HEARTBEATs sniffed off the link (``--reflect FILE``) |
| multiframe  | 2-4 frames in one datagram: an unsigned command, a read, a forged signed  |
|             | command, a MAVLink 1 frame, a reflected frame                             |
| mavlink1    | MAVLink 1 frames (cannot be signed): HEARTBEAT, COMMAND_LONG, PARAM_SET   |

Loopback only (the target must be 127.0.0.1). Prints one JSON line at the end: the count
sent per kind, the achieved rate, and how many vehicle-signed frames came back to reflect.
Nothing here knows the vehicle's key.
"""
from __future__ import annotations

import argparse
import json
import random
import socket
import struct
import sys
import threading
import time
from collections import deque

from pymavlink.dialects.v10 import common as v10

from common import argtypes
from ellipsled.node_reports import read_fsw
from ellipsled.procs import ELLIPSLED, stop_process
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.framing import parse_header
from interfaces.mavlink.signing.keys import SigningKey
from interfaces.mavlink.signing.sign import Signer

from .rows import NO_TARGET, Row, fmt, g, ratio, row, speed

TARGETS = {"slips": 0, "groundlink_max_us_max": 20_000.0,    # a ground-link tick within one period
           "state_changes": 0, "peers_added": 0, "fdir_event_latency_s_max": 1.0}

# share of each kind in the mix (oversized datagrams are few: each is 60 kB)
MIX = {"random": 12, "malformed": 12, "unsigned": 10, "badsig": 14, "replay": 10, "oversized": 2,
       "reads": 10, "reflected": 10, "multiframe": 12, "mavlink1": 8}
REFLECT_POOL = 64                # vehicle-signed frames kept to send back
OVERSIZED_BYTES = 60_000
DISARM = mav.MAVLink_command_long_message(1, 1, mav.ELLIPSLED_CMD_ARM_JETS, 0, 0, 0, 0, 0, 0, 0, 0)
SAFE = mav.MAVLink_command_long_message(1, 1, mav.ELLIPSLED_CMD_SET_MODE, 0, 2, 0, 0, 0, 0, 0, 0)
PARAM = mav.MAVLink_param_set_message(1, 1, b"C_LAMBDA_RADPS", 50.0, mav.MAV_PARAM_TYPE_REAL32)
READS = (mav.MAVLink_param_request_read_message(1, 1, b"C_LAMBDA_RADPS", -1),
         mav.MAVLink_param_request_read_message(1, 1, b"NO_SUCH_PARAM", -1),
         mav.MAVLink_param_request_read_message(1, 1, b"", 3),
         mav.MAVLink_param_request_list_message(1, 1),
         mav.MAVLink_mission_request_list_message(1, 1, 0))
V1 = (v10.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3),
      v10.MAVLink_command_long_message(1, 1, mav.ELLIPSLED_CMD_ARM_JETS, 0, 0, 0, 0, 0, 0, 0, 0),
      v10.MAVLink_param_set_message(1, 1, b"C_LAMBDA_RADPS", 50.0, mav.MAV_PARAM_TYPE_REAL32))


def vehicle_signed(frame: bytes) -> bool:
    """A signed MAVLink 2 frame of the vehicle (system 1): worth reflecting."""
    hdr = parse_header(frame)
    return hdr is not None and hdr.version == 2 and hdr.signed and hdr.sysid == 1


class Flood:
    """Datagram maker; ``next()`` returns (kind, datagram)."""

    def __init__(self, seed: int = 1, replay: list[bytes] | None = None, reflect: list[bytes] | None = None):
        self.rng = random.Random(seed)
        self.replay = replay or []
        self.reflect: deque[bytes] = deque((f for f in reflect or () if vehicle_signed(f)), maxlen=REFLECT_POOL)
        self.forger = Signer(SigningKey.generate(), system_id=255, component_id=190, link_id=0)
        # a forged frame a day ahead: a verify-after-store link would lock the ground out
        self.future = Signer(SigningKey.generate(), system_id=255, component_id=190, link_id=0,
                             clock=lambda: time.time() + 86_400.0)
        self.unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        self.v1 = v10.MAVLink(None, srcSystem=255, srcComponent=190)
        kinds = [k for k in MIX if k != "replay" or self.replay]
        self.kinds, self.weights = kinds, [MIX[k] for k in kinds]
        self._oversized = self._make_oversized()

    def _make_oversized(self) -> bytes:
        parts, n = [], 0
        while n < OVERSIZED_BYTES:
            p = self._malformed() if self.rng.random() < 0.5 else self.rng.randbytes(200)
            parts.append(p)
            n += len(p)
        return b"".join(parts)[:OVERSIZED_BYTES]

    def _malformed(self) -> bytes:
        f = bytearray(self.forger.pack(self.rng.choice((DISARM, SAFE))))
        how = self.rng.randrange(3)
        if how == 0:
            return bytes(f[:self.rng.randrange(1, len(f))])          # truncated
        if how == 1:
            f[1] = self.rng.randrange(256)                            # length corrupted
        else:
            f[-15] ^= 0xFF                                            # CRC wrong
        return bytes(f)

    def take(self, data: bytes) -> None:
        """A datagram that came back from the vehicle: its signed frames go to the pool."""
        i = 0
        while i < len(data):
            hdr = parse_header(data, i)
            if hdr is None or hdr.frame_len > len(data) - i:
                return
            frame = data[i:i + hdr.frame_len]
            if vehicle_signed(frame):
                self.reflect.append(frame)
            i += hdr.frame_len

    def _read(self) -> bytes:
        return self.rng.choice(READS).pack(self.unsigned)

    def _mavlink1(self) -> bytes:
        return self.rng.choice(V1).pack(self.v1)

    def _multiframe(self) -> bytes:
        parts = [DISARM.pack(self.unsigned), self._read(), self.forger.pack(SAFE)]
        if self.reflect:
            parts.append(self.rng.choice(self.reflect))
        self.rng.shuffle(parts)
        parts = parts[:self.rng.randrange(2, len(parts) + 1)]
        if self.rng.random() < 0.3:
            parts.append(self._mavlink1())
        return b"".join(parts)

    def next(self) -> tuple[str, bytes]:
        kind = self.rng.choices(self.kinds, self.weights)[0]
        if kind == "reflected" and not self.reflect:
            kind = "reads"                     # nothing to reflect yet: ask for something to
        if kind == "reads":
            return kind, self._read()
        if kind == "reflected":
            return kind, self.rng.choice(self.reflect)
        if kind == "multiframe":
            return kind, self._multiframe()
        if kind == "mavlink1":
            return kind, self._mavlink1()
        if kind == "random":
            return kind, self.rng.randbytes(self.rng.randrange(1, 301))
        if kind == "malformed":
            return kind, self._malformed()
        if kind == "unsigned":
            return kind, self.rng.choice((DISARM, PARAM)).pack(self.unsigned)
        if kind == "badsig":
            signer = self.future if self.rng.random() < 0.2 else self.forger
            return kind, signer.pack(self.rng.choice((DISARM, SAFE, PARAM)))
        if kind == "replay":
            return kind, self.rng.choice(self.replay)
        return kind, self._oversized


def send(target: tuple[str, int], rate: float, seconds: float, seed: int = 1,
         replay: list[bytes] | None = None, reflect: list[bytes] | None = None, flood: Flood | None = None) -> dict:
    """Flood ``target`` for ``seconds`` at ``rate`` datagrams/s; what was sent, by kind.
    What the vehicle sends back (answers to the reads) is kept to reflect. ``flood``: a
    Flood to use (another thread may add to its reflect pool)."""
    if target[0] != "127.0.0.1":
        raise ValueError("the flood stays on loopback: target must be 127.0.0.1")
    fl = flood or Flood(seed, replay, reflect)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4 << 20)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    counts = {k: 0 for k in MIX}
    errors = back = 0
    t0 = time.monotonic()
    sent = 0
    while True:
        now = time.monotonic()
        if now - t0 >= seconds:
            break
        while True:                          # the vehicle's answers: frames it signed
            try:
                fl.take(sock.recv(65536))
                back += 1
            except (BlockingIOError, InterruptedError):
                break
            except OSError:                  # an ICMP error reported here: go on
                errors += 1
                break
        due = int((now - t0) * rate) + 1
        while sent < due:
            kind, data = fl.next()
            try:
                sock.sendto(data, target)
            except OSError:                  # e.g. ECONNREFUSED from an earlier ICMP: go on
                errors += 1
            counts[kind] += 1
            sent += 1
        time.sleep(0.001)
    elapsed = time.monotonic() - t0
    sock.close()
    return {"sent": sent, "seconds": elapsed, "rate_per_s": sent / elapsed, "by_kind": counts,
            "send_errors": errors, "answers_received": back, "reflect_pool": len(fl.reflect)}


# ------------------------------------------------------------------ benchmark
RG2_HZ = 10.0
CYCLES_PER_TICK = 5              # control periods in an RG2 period at 50 Hz: the link reads every one


def _pct(ns) -> dict:
    import numpy as np
    a = np.asarray(ns, dtype=np.float64) * 1e-3
    return {"p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
            "max_us": float(a.max()), "n": int(a.size)}


def receive_cost(quick: bool, rate: float = 2500.0) -> dict:
    """The vehicle's receive work per RG2 tick (10 Hz), in this process: quiet, and under
    a flood of ``rate`` datagrams/s (the mix above, one genuine signed command among each
    tick's datagrams), through the bounded intake and through the previous receive path
    (every datagram split, CRC-checked and verified, up to 64 a tick); and through the
    intake read every control period at 50 Hz (``flood_every_cycle``: the tick's datagrams
    in CYCLES_PER_TICK parts, a call after each; its cost per call), as the vehicle reads
    (fsw/groundlink/link.py ``listen``). Same run, same datagrams."""
    from interfaces.mavlink.intake import DatagramIntake
    from interfaces.mavlink.signing.link import SignedLink
    ticks = 100 if quick else 400
    per_tick = int(rate / RG2_HZ)
    key = SigningKey.generate()
    ground = Signer(key, system_id=255, component_id=190, link_id=1)
    accept = {mav.MAVLINK_MSG_ID_HEARTBEAT, mav.MAVLINK_MSG_ID_COMMAND_LONG, mav.MAVLINK_MSG_ID_PARAM_SET,
              mav.MAVLINK_MSG_ID_PARAM_REQUEST_LIST, mav.MAVLINK_MSG_ID_PARAM_REQUEST_READ}
    replay = [ground.pack(DISARM) for _ in range(8)]
    out = {"rate_per_s": rate, "ticks": ticks, "datagrams_per_tick": per_tick}
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 8 << 20)
    for name in ("quiet", "flood_intake", "flood_previous", "flood_every_cycle"):
        rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        rx.bind(("127.0.0.1", 0))
        rx.setblocking(False)
        link = SignedLink(key, system_id=1, component_id=1)
        for f in replay:                      # seen once: from now on they are replays
            link.receive(f)
        got = []

        def handle(msg, addr):
            if msg.get_type() == "COMMAND_LONG":
                got.append(msg)
        intake = DatagramIntake(rx, link, accept=accept) if name != "flood_previous" else None
        if intake is None:
            rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 212992)      # the system default
        buf = bytearray(65536)
        view = memoryview(buf)
        fl = Flood(1, replay)
        cost, sent_genuine = [], 0
        parts = CYCLES_PER_TICK if name == "flood_every_cycle" else 1
        for _ in range(ticks):
            at = fl.rng.randrange(per_tick) if name != "quiet" else -1
            for part in range(parts):         # a part of the tick's datagrams, then a call
                if name != "quiet":
                    for i in range(part * per_tick // parts, (part + 1) * per_tick // parts):
                        tx.sendto(fl.next()[1] if i != at else ground.pack(ARM), rx.getsockname())
                time.sleep(0.002)             # loopback delivery
                t0 = time.perf_counter_ns()
                if intake is not None:
                    intake.poll(handle)
                else:                         # the previous GroundLink.poll: 64 datagrams, each split and verified
                    for _ in range(64):
                        try:
                            size, addr = rx.recvfrom_into(buf)
                        except BlockingIOError:
                            break
                        for msg in link.receive(view[:size]):
                            handle(msg, addr)
                cost.append(time.perf_counter_ns() - t0)
            sent_genuine += name != "quiet"
        out[name] = {**_pct(cost), "genuine_sent": sent_genuine, "genuine_handled": len(got),
                     **({"kernel_drops": intake.stats["kernel_drops"], "refused_early": intake.stats["refused_early"],
                         "rcvbuf_bytes": intake.rcvbuf_bytes} if intake is not None else {})}
        rx.close()
    tx.close()
    return out


ARM = mav.MAVLink_command_long_message(1, 1, mav.ELLIPSLED_CMD_ARM_JETS, 0, 1, 0, 0, 0, 0, 0, 0)


def _free_udp() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# a command is answered in time when its COMMAND_ACK is back within two RG2 periods (0.1 s
# each; the link reads and answers every control period, GroundLink.listen: a generous bound)
ANSWER_IN_TIME_S = 0.2
ANSWER_WAIT_S = 1.0              # commands sent this close to the run's end are not judged
SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35)     # Linux: the kernel's arrival time of a datagram
_TIMESPEC = struct.Struct("=qq")
PROBE = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 0, 1, 0, 0, 0, 0, 0, 0)


class GroundWatch:
    """The ground station of a benchmark run, in a thread: listens where the vehicle sends
    its telemetry, with the key (GroundClient: only verified vehicle frames), and notes when
    each STATUSTEXT arrived and the vehicle's SYSTEM_TIME (Unix time against mission time);
    it also gives the vehicle's HEARTBEATs, as sniffed off the link, to the flood's reflect
    pool. With ``pace_hz`` and once ``pace()`` is called, it also sends a signed read-only
    command (PROBE: the protocol version, answered ACK + PROTOCOL_VERSION, changing nothing)
    to ``vehicle`` at that pace from the same port, one at a time: the next waits for the
    last one's COMMAND_ACK, or ANSWER_WAIT_S without one (then it is missing), so each ACK
    is known to be its command's even when one is lost; it notes when each was sent and
    when its ACK came back. After a stall of this thread the pace resumes a period later,
    never with two commands at once."""

    def __init__(self, key: SigningKey, port: int, flood: Flood | None, pace_hz: float = 0.0,
                 vehicle: tuple[str, int] | None = None):
        from gse.client import GroundClient
        self.client = GroundClient(key, listen=None)
        self.flood = flood
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.settimeout(0.005 if pace_hz else 0.05)
        self.arrivals: list[tuple[float, str]] = []          # (Unix s, text) of each STATUSTEXT
        self.offsets_s: list[float] = []                      # Unix time - mission time, per SYSTEM_TIME
        self.pace_hz, self.vehicle = float(pace_hz), vehicle
        self.signer = Signer(key, system_id=255, component_id=190, link_id=2) if pace_hz else None
        # Unix time [s] of each PROBE sent, of its COMMAND_ACK as the kernel stamped its
        # arrival (SO_TIMESTAMPNS: not when this thread, on a busy host, got to it; None
        # while unanswered), and of the vehicle's last frame; ACKs of no command waiting
        self.sent_t: list[float] = []
        self.ack_t: list[float | None] = []
        self.last_rx_t = 0.0
        self.stale_acks = 0
        self.clock = time.time                                # Unix time (tests set their own)
        self._next_t = 0.0
        if pace_hz:
            self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        self._pacing = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="ground-watch", daemon=True)

    def pace(self) -> None:
        """Start sending the paced commands (after the run's warm-up)."""
        self._pacing.set()

    def _send_due(self) -> None:
        """Send the next PROBE if its time has come and no command is waiting for its ACK
        (one that waited ANSWER_WAIT_S is given up: missing)."""
        now = self.clock()
        if not self._pacing.is_set() or now < self._next_t:
            return
        if self.ack_t and self.ack_t[-1] is None and now - self.sent_t[-1] < ANSWER_WAIT_S:
            return
        period = 1.0 / self.pace_hz
        self._next_t = self._next_t + period if self._next_t + period > now else now + period
        frame = self.signer.pack(PROBE)
        self.sent_t.append(self.clock())                  # as it goes
        self.ack_t.append(None)
        try:
            self.sock.sendto(frame, self.vehicle)
        except OSError:
            pass

    def _answered(self, arrived: float) -> None:
        """A PROBE's COMMAND_ACK arrived (Unix time): the waiting command's."""
        if self.ack_t and self.ack_t[-1] is None:
            self.ack_t[-1] = arrived
        else:
            self.stale_acks += 1

    def answers(self) -> dict:
        """The paced commands sent ANSWER_WAIT_S or more before the vehicle's last frame
        (the link still ticked): how many, answered in time (ANSWER_IN_TIME_S), late,
        missing; the answer latency [ms]; ACKs of no waiting command; the longest time
        between two commands sent [ms] (this thread's own stalls show there)."""
        import numpy as np
        judged = [(s, a) for s, a in zip(self.sent_t, self.ack_t) if s < self.last_rx_t - ANSWER_WAIT_S]
        lat = [a - s for s, a in judged if a is not None]
        in_time = sum(x <= ANSWER_IN_TIME_S for x in lat)
        a = np.asarray(lat or [np.nan]) * 1e3
        gaps = np.diff([s for s, _ in judged]) * 1e3
        return {"pace_hz": self.pace_hz, "in_time_s": ANSWER_IN_TIME_S, "sent": len(judged), "in_time": int(in_time),
                "late": len(lat) - int(in_time), "missing": len(judged) - len(lat),
                "latency_p50_ms": float(np.percentile(a, 50)), "latency_p99_ms": float(np.percentile(a, 99)),
                "latency_max_ms": float(np.max(a)), "stale_acks": self.stale_acks,
                "send_gap_max_ms": float(gaps.max()) if gaps.size else None}

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self.sock.close()

    def _loop(self) -> None:
        st = self.client.state
        while not self._stop.is_set():
            if self.pace_hz:
                self._send_due()
            try:
                data, anc, _, addr = self.sock.recvmsg(65536, 64)
            except (socket.timeout, InterruptedError):
                continue
            except OSError:
                return
            now = time.time()
            arrived = next((sec + ns * 1e-9 for lvl, typ, raw in anc if lvl == socket.SOL_SOCKET
                            and typ == SO_TIMESTAMPNS for sec, ns in (_TIMESPEC.unpack(raw[:16]),)), now)
            n_ev, n_time = st.events_total, st.rx_counts.get("SYSTEM_TIME", 0)
            n_ack = st.rx_counts.get("COMMAND_ACK", 0)
            fed = self.client.feed(data, addr, now)
            if fed:
                self.last_rx_t = arrived
            if st.rx_counts.get("COMMAND_ACK", 0) != n_ack and st.acks[-1].command == PROBE.command:
                self._answered(arrived)
            if fed and self.flood is not None:
                hdr = parse_header(data)
                if hdr is not None and hdr.msgid == mav.MAVLINK_MSG_ID_HEARTBEAT and vehicle_signed(data):
                    self.flood.reflect.append(bytes(data[:hdr.frame_len]))
            for ev in list(st.events)[len(st.events) - (st.events_total - n_ev):]:
                self.arrivals.append((ev.t_unix_s, ev.text))
            if st.rx_counts.get("SYSTEM_TIME", 0) != n_time:
                m = st.latest["SYSTEM_TIME"]
                self.offsets_s.append(m.time_unix_usec * 1e-6 - m.time_boot_ms * 1e-3)

    def event_latencies(self, event_log: list[dict], source: str = "fdir") -> tuple[int, list[float]]:
        """The FSW's events of ``source`` (fsw.json's event_log, mission time) against their
        arrival here: (how many there were, the latency [s] of each that arrived)."""
        import statistics
        from interfaces.mavlink.framing import printable_text
        evs = [e for e in event_log if e["source"] == source]
        if not evs or not self.offsets_s:
            return len(evs), []
        offset = statistics.median(self.offsets_s)
        out = []
        for e in evs:
            sent = e["t_s"] + offset
            text = printable_text(e["text"][:50])
            got = [t for t, x in self.arrivals if x == text and t >= sent - 0.5]
            if got:
                out.append(max(0.0, got[0] - sent))
        return len(evs), out


def sil_run(duration_s: float, flood_s: float | None, rate: float = 2500.0, timeout_s: float = 300.0,
            scenario: str = "case1", dt_control_s: float | None = None, pace_hz: float = 0.0) -> dict:
    """One real-time SIL (``ellipsled run SCENARIO --realtime``, at ``dt_control_s`` if
    given), flooded for ``flood_s`` from its first jet command (None: quiet), watched by a
    ground station: the FSW's cycle compute, ground-link task cost and slips from its
    fsw.json; what the flood changed (commands accepted, parameters set, telemetry peers
    added: none of it is genuine); how late the FDIR events (case1: jets fail at 2.5 s,
    under the flood) reached the ground. ``pace_hz``: the ground station also sends a signed
    command at that pace from the first jet command on (warm-up over) and counts the answers
    (``GroundWatch.answers``)."""
    import subprocess
    import tempfile
    from pathlib import Path
    with tempfile.TemporaryDirectory(prefix="bench-flood-") as d:
        key_file = Path(d) / "keys" / "signing.key"
        key_file.parent.mkdir()
        key = SigningKey.generate()
        key.write_file(key_file)
        vehicle, gcs = _free_udp(), _free_udp()
        fl = Flood(1) if flood_s else None
        watch = GroundWatch(key, gcs, fl, pace_hz, ("127.0.0.1", vehicle))
        watch.start()
        log_path = Path(d) / "run.log"
        with open(log_path, "w") as log:
            dt = ["--dt-control", f"{dt_control_s:g}"] if dt_control_s else []
            run = subprocess.Popen(ELLIPSLED + ["run", scenario, "--realtime", "--duration", f"{duration_s:g}",
                                                *dt, "--out", d, "--rerun", "none", "--no-plots",
                                                "--signing-key", str(key_file),
                                                "--mavlink-bind", f"udp:127.0.0.1:{vehicle}",
                                                "--gcs", f"udp:127.0.0.1:{gcs}"],
                                   stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
            sent = None
            try:
                end = time.monotonic() + timeout_s
                while "first jet command" not in log_path.read_text():
                    if run.poll() is not None or time.monotonic() > end:
                        raise RuntimeError(f"the SIL did not fly: {log_path.read_text()[-300:]}")
                    time.sleep(0.1)
                watch.pace()
                if flood_s:
                    sent = send(("127.0.0.1", vehicle), rate, flood_s, flood=fl)
                run.wait(timeout_s)
            finally:
                stop_process(run, 10.0)
                watch.stop()
        fsw = read_fsw(d)
        answers = watch.answers() if pace_hz else None
    ex, gl = fsw["executive"], fsw["tasks_us"].get("groundlink", {})
    lis = fsw["tasks_us"].get("groundlink_rx", {})          # the listens between ticks (GroundLink.listen)
    link = fsw.get("ground_link") or {}
    n_fdir, lat = watch.event_latencies(fsw.get("event_log", []))
    return {"compute_p50_us": ex["compute_p50_us"], "compute_p99_us": ex["compute_p99_us"],
            "compute_max_us": ex["compute_max_us"], "slips": ex["slips"],
            "groundlink_p50_us": gl.get("p50"), "groundlink_p99_us": gl.get("p99"), "groundlink_max_us": gl.get("max"),
            "listen_p99_us": lis.get("p99"), "listen_max_us": lis.get("max"),
            "kernel_drops": link.get("kernel_drops") if link else None,
            "jitter_p99_us": fsw.get("jitter_p99_us"), "ground_link": link, "flood": sent,
            "state_changes": (link.get("commands_accepted", 0) + link.get("params_set", 0)) if link else None,
            "peers_added": link.get("peers_added") if link else None,
            "fdir_events": n_fdir, "fdir_events_received": len(lat),
            "fdir_latency_max_s": max(lat) if lat and len(lat) == n_fdir else None,
            "duration_s": duration_s, "scenario": scenario, "dt_control_s": dt_control_s, "answers": answers}


def run(quick: bool) -> dict:
    """Benchmark section: the real-time SIL quiet and flooded (same run of the suite), and
    the receive work per RG2 tick in process."""
    dur, flood_s = (20.0, 10.0) if quick else (40.0, 20.0)
    res = {"figure": "real-time SIL (case1) with a ground flood of 2,500 datagrams/s vs quiet: cycle compute, "
                     "ground-link task cost per RG2 tick and listening between, slips; what the flood changed; FDIR events to the ground",
           "quiet": sil_run(dur, None), "flood": sil_run(dur, flood_s), "receive": receive_cost(quick),
           "targets": dict(TARGETS)}
    f, q = res["flood"], res["quiet"]
    res.update(flood_compute_p99_us=f["compute_p99_us"], flood_compute_max_us=f["compute_max_us"],
               flood_groundlink_p99_us=f["groundlink_p99_us"], flood_groundlink_max_us=f["groundlink_max_us"],
               flood_listen_p99_us=f["listen_p99_us"], flood_listen_max_us=f["listen_max_us"],
               flood_kernel_drops=f["kernel_drops"], flood_slips=f["slips"], flood_state_changes=f["state_changes"], flood_peers_added=f["peers_added"],
               flood_fdir_latency_max_s=f["fdir_latency_max_s"], quiet_compute_p99_us=q["compute_p99_us"],
               quiet_groundlink_p99_us=q["groundlink_p99_us"], quiet_groundlink_max_us=q["groundlink_max_us"])
    return res


def rows(res: dict) -> list[Row]:
    fl = res.get("flood") or {}
    if not fl:
        return []
    gl_max = TARGETS["groundlink_max_us_max"]
    rc = fl.get("receive") or {}
    changes, peers, lat = fl.get("flood_state_changes"), fl.get("flood_peers_added"), fl.get("flood_fdir_latency_max_s")
    lat_max = TARGETS["fdir_event_latency_s_max"]
    return [row(f"real-time SIL under a ground flood ({fmt(g(fl, 'flood', 'flood', 'rate_per_s'))} datagrams/s): "
                "cycle compute p99 / max [us]",
                f"{fmt(fl.get('flood_compute_p99_us'))} / {fmt(fl.get('flood_compute_max_us'))}",
                f"quiet {fmt(fl.get('quiet_compute_p99_us'))} / {fmt(g(fl, 'quiet', 'compute_max_us'))}",
                f"{fmt(ratio(fl.get('flood_compute_p99_us'), fl.get('quiet_compute_p99_us')))}x (p99)",
                f"{TARGETS['slips']} slips",
                None if fl.get("flood_slips") is None else fl.get("flood_slips") == TARGETS["slips"]),
            row("  ground-link task per RG2 tick under flood p99 / max [us]",
                f"{fmt(fl.get('flood_groundlink_p99_us'))} / {fmt(fl.get('flood_groundlink_max_us'))}",
                f"quiet {fmt(fl.get('quiet_groundlink_p99_us'))} / {fmt(fl.get('quiet_groundlink_max_us'))}",
                f"{fmt(ratio(fl.get('flood_groundlink_max_us'), gl_max))}x period (max)",
                f"max < {gl_max:,.0f} (a period)", NO_TARGET,
                absolute=(fl.get("flood_groundlink_max_us"), gl_max, "<="), machine=speed(res)),
            *([row("  ground link listening between ticks under flood p99 / max [us]; datagrams the kernel dropped",
                   f"{fmt(fl.get('flood_listen_p99_us'))} / {fmt(fl.get('flood_listen_max_us'))}; "
                   f"{fmt(fl.get('flood_kernel_drops'))} dropped",
                   f"of {fmt(g(fl, 'flood', 'flood', 'sent'))} sent; quiet listen max {fmt(g(fl, 'quiet', 'listen_max_us'))}",
                   "", "the socket read every cycle: none dropped unless the host stalls the FSW", NO_TARGET)]
              if "flood_listen_max_us" in fl else []),        # runs before the listens (2026-11-28) have none
            row("  under the flood: state changes / telemetry peers added / FDIR events to the ground, max latency [s]",
                f"{fmt(changes)} / {fmt(peers)} / {fmt(lat)}",
                f"FDIR events received {fmt(g(fl, 'flood', 'fdir_events_received'))} of "
                f"{fmt(g(fl, 'flood', 'fdir_events'))}; quiet max {fmt(g(fl, 'quiet', 'fdir_latency_max_s'))}",
                "", f"0 / 0 / <= {lat_max:g}",
                None if None in (changes, peers, lat) else (changes == TARGETS["state_changes"]
                                                            and peers == TARGETS["peers_added"] and lat <= lat_max)),
            row("  receive work per tick, in process, flood: intake / previous path p99 [us]",
                f"{fmt(g(rc, 'flood_intake', 'p99_us'))} / {fmt(g(rc, 'flood_previous', 'p99_us'))}",
                f"quiet {fmt(g(rc, 'quiet', 'p99_us'))}; genuine commands through: "
                f"{fmt(g(rc, 'flood_intake', 'genuine_handled'))} / {fmt(g(rc, 'flood_previous', 'genuine_handled'))}"
                f" of {fmt(g(rc, 'flood_intake', 'genuine_sent'))}"
                + (f"; the intake read every control period (as the vehicle): p99 {fmt(e['p99_us'])} a call, "
                   f"{fmt(e['genuine_handled'])} of {fmt(e['genuine_sent'])} through, {fmt(e['kernel_drops'])} dropped"
                   if (e := rc.get("flood_every_cycle")) else ""), "", "", NO_TARGET)]


def main(argv: list[str] | None = None) -> int:
    from interfaces.vocabulary import parse_udp
    from gse.tlog import read_records
    ap = argparse.ArgumentParser(prog="python -m ellipsled.bench.flood", description=__doc__.splitlines()[0])
    ap.add_argument("--target", required=True, help="udp:127.0.0.1:PORT (the vehicle's MAVLink address)")
    ap.add_argument("--rate", type=argtypes.float_range(1.0, 1e6), default=2500.0, help="datagrams per second")
    ap.add_argument("--seconds", type=argtypes.timeout_s, default=12.0)
    ap.add_argument("--seed", type=argtypes.seed, default=1)
    ap.add_argument("--replay", default=None, metavar="FILE.tlog", help="genuine frames to replay")
    ap.add_argument("--reflect", default=None, metavar="FILE.tlog",
                    help="frames sniffed off the link: those the vehicle signed are sent back to it")
    a = ap.parse_args(argv)
    replay = [f for _, f in read_records(a.replay)] if a.replay else None
    reflect = [f for _, f in read_records(a.reflect)] if a.reflect else None
    print("flooding", flush=True)
    res = send(parse_udp(a.target, "target"), a.rate, a.seconds, a.seed, replay, reflect)
    print(json.dumps(res), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
