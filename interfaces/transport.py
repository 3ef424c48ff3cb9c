"""Zenoh sessions and the few helpers every process shell needs (docs/interfaces/index.md).

Embedded default: peer mode, multicast and gossip scouting off, explicit endpoints on
loopback (one process listens on tcp/127.0.0.1:<port>, the others connect). Anything
else — a zenohd router, peers on real interfaces, TLS, access control — is a zenoh JSON5
configuration file given as ``config_file``: configuration, never code.

Rules kept here so that process shells cannot get them wrong:
- a publisher waits for a matching subscriber before a run starts (samples sent before
  matching are lost): ``wait_for_subscriber``;
- receiving polls ``try_recv`` (a blocking zenoh ``recv()`` ignores Ctrl-C): ``recv``,
  ``latest``; no callback subscribers (one left open hangs interpreter exit);
- every session is closed explicitly: ``close``.
"""
from __future__ import annotations

import json
import math
import socket
import time
from pathlib import Path

import zenoh

from interfaces.keys import Keys

# Connection retry while the listening process is not up yet (zenoh's default starts at 1 s).
CONNECT_RETRY = {"period_init_ms": 20, "period_max_ms": 500, "period_increase_factor": 2}
CONNECT_TIMEOUT_MS = 200
# Zenoh's lease: a peer silent this long is dropped (bounds any stall on a frozen peer).
LEASE_MS = 10_000


def default_config(role: str, listen: list[str] | None, connect: list[str] | None,
                   lowlatency: bool = True) -> dict:
    """The embedded configuration as a dict (zenoh's JSON5 schema)."""
    cfg = {
        "mode": "peer",
        "metadata": {"name": role},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        # no implicit listener on every interface (zenoh's peer default is tcp/[::]:0)
        "listen": {"endpoints": list(listen or [])},
        "connect": {"endpoints": list(connect or []), "timeout_ms": CONNECT_TIMEOUT_MS,
                    "exit_on_failure": False, "retry": dict(CONNECT_RETRY)},
    }
    # Zenoh's lease (its default, made explicit): a peer silent this long is dropped.
    cfg["transport"] = {"link": {"tx": {"lease": LEASE_MS, "keep_alive": 4}}}
    if lowlatency:
        # saves ~30-60 us per hop here; both ends must agree; excludes QoS (
        # docs/interfaces/index.md). A low-latency put writes to the socket itself, whatever
        # its congestion control: once a frozen subscriber's (SIGSTOP, a debugger) socket
        # buffers are full, put() blocks until the lease drops that peer. Seen: ~20 MB
        # absorbed on one machine; a block for the whole lease right at the freeze on another
        # (CI, 120 kB/s). docs/sil.md says so; the standard transport with DROP never blocks.
        # tests/test_transport_loopback.py holds both.
        cfg["transport"]["unicast"] = {"lowlatency": True, "qos": {"enabled": False}}
    return cfg


def open_session(role: str, listen: list[str] | None, connect: list[str] | None,
                 config_file: str | None = None, *, lowlatency: bool = True) -> zenoh.Session:
    """Open this process's Zenoh session.

    role: "sim", "fsw", "bridge", "console", ... (session metadata, for diagnostics).
    listen / connect: zenoh endpoints, e.g. ["tcp/127.0.0.1:7450"]. With ``config_file``
    (zenoh JSON5) that file is the configuration; listen / connect, when not None, then
    replace the file's endpoints (a shell's command-line options win over the file).
    Raises ValueError / FileNotFoundError / zenoh.ZError with the cause.
    """
    if not isinstance(role, str) or not role:
        raise ValueError(f"open_session: role must be a non-empty string, got {role!r}")
    for name, eps in (("listen", listen), ("connect", connect)):
        if eps is not None and (isinstance(eps, str) or not all(isinstance(e, str) for e in eps)):
            raise ValueError(f"open_session: {name} must be a list of endpoint strings, got {eps!r}")
    if config_file is not None:
        path = Path(config_file)
        if not path.is_file():
            raise FileNotFoundError(f"zenoh config file not found: {path}")
        conf = zenoh.Config.from_file(str(path))
        if listen is not None:
            conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
        if connect is not None:
            conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    else:
        conf = zenoh.Config.from_json5(json.dumps(default_config(role, listen, connect, lowlatency)))
    return zenoh.open(conf)


def loopback(port: int) -> str:
    """The loopback TCP endpoint of a port: "tcp/127.0.0.1:<port>"."""
    return f"tcp/127.0.0.1:{int(port)}"


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free right now on ``host`` (for tests; another process may take it later)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def publisher(session: zenoh.Session, key: str, *, express: bool = True,
              drop: bool = False) -> zenoh.Publisher:
    """A reliable publisher at real-time priority. ``express`` sends each sample at once
    instead of batching (lower latency for one small frame per cycle). ``drop``: when the
    subscriber cannot keep up (a frozen viewer, a stopped peer) samples are dropped and
    put() returns at once; otherwise put() waits for room (loss-free: lockstep, commands)."""
    cc = zenoh.CongestionControl.DROP if drop else zenoh.CongestionControl.BLOCK
    return session.declare_publisher(key, congestion_control=cc, priority=zenoh.Priority.REAL_TIME,
                                     express=express)


def subscriber(session: zenoh.Session, key: str, *, newest_only: bool = False,
               capacity: int = 256) -> zenoh.Subscriber:
    """A polled subscriber. ``newest_only``: a ring keeping the newest ``capacity`` samples
    (real-time mode, the consumer wants the newest); else a FIFO that loses nothing
    (lockstep) — a full FIFO blocks zenoh's thread, so consume it."""
    if capacity < 1:
        raise ValueError("subscriber: capacity must be >= 1")
    handler = zenoh.handlers.RingChannel(capacity) if newest_only else zenoh.handlers.FifoChannel(capacity)
    return session.declare_subscriber(key, handler)


def wait_for_subscriber(pub: zenoh.Publisher, timeout_s: float, poll_s: float = 0.001) -> bool:
    """Wait (interruptibly) until a subscriber matches ``pub``; False on timeout."""
    deadline = time.monotonic() + timeout_s
    while True:
        if pub.matching_status.matching:
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(poll_s)


def recv(sub: zenoh.Subscriber, timeout_s: float, spin_s: float = 0.0,
         poll_s: float = 20e-6) -> zenoh.Sample | None:
    """The next sample, or None after ``timeout_s``. Spins on ``try_recv`` for ``spin_s``,
    then polls every ``poll_s``; Ctrl-C works. Measured here (2 shared cores, loaded):
    polling every 20 us gave the best round trip (p50 ~350 us vs ~250 us for zenoh's
    blocking recv, which ignores Ctrl-C); spinning helped only with an idle core."""
    s = sub.try_recv()
    if s is not None:
        return s
    t0 = time.perf_counter()
    spin_end, deadline = t0 + spin_s, t0 + timeout_s
    while True:
        s = sub.try_recv()
        if s is not None:
            return s
        now = time.perf_counter()
        if now >= deadline:
            return None
        if now >= spin_end:
            time.sleep(poll_s)


def latest(sub: zenoh.Subscriber) -> tuple[zenoh.Sample | None, int]:
    """Drain the subscriber: (newest sample or None, number of older samples skipped)."""
    newest, skipped = None, -1
    while True:
        s = sub.try_recv()
        if s is None:
            return newest, max(skipped, 0)
        newest, skipped = s, skipped + 1


def drain(sub: zenoh.Subscriber) -> list[zenoh.Sample]:
    """Every sample waiting in the subscriber, oldest first."""
    out = []
    while (s := sub.try_recv()) is not None:
        out.append(s)
    return out


def declare_alive(session: zenoh.Session, k: Keys, role: str) -> zenoh.LivelinessToken:
    """Announce this process (liveliness token ``<prefix>/alive/<role>``)."""
    return session.liveliness().declare_token(k.alive(role))


class Presence:
    """Whether the process holding a liveliness token is there, polled (no callback thread):
    ``gone_for_s()`` is how long its token has been gone, 0 while it is there or before it
    was ever seen."""

    def __init__(self, session: zenoh.Session, key: str, now=time.monotonic):
        self.sub = session.liveliness().declare_subscriber(key, zenoh.handlers.FifoChannel(64), history=True)
        self.now = now
        self.gone_since: float | None = None

    def gone_for_s(self) -> float:
        while (s := self.sub.try_recv()) is not None:
            self.gone_since = None if s.kind == zenoh.SampleKind.PUT else self.now()
        return 0.0 if self.gone_since is None else self.now() - self.gone_since

    def undeclare(self) -> None:
        self.sub.undeclare()


def wait_for_alive(session: zenoh.Session, key: str, timeout_s: float,
                   poll_s: float = 0.005, every=None, every_s: float = 0.02) -> bool:
    """Wait (interruptibly) until a liveliness token matching ``key`` exists; ``every()``,
    if given, is called at once and then every ``every_s`` while waiting."""
    sub = session.liveliness().declare_subscriber(key, zenoh.handlers.FifoChannel(16), history=True)
    try:
        deadline = time.monotonic() + timeout_s
        t_every = -math.inf
        while True:
            if every is not None and time.monotonic() - t_every >= every_s:
                every()
                t_every = time.monotonic()
            s = sub.try_recv()
            if s is not None and s.kind == zenoh.SampleKind.PUT:
                return True
            if time.monotonic() >= deadline:
                return False
            if s is None:
                time.sleep(poll_s)
    finally:
        sub.undeclare()


def close(*objs) -> None:
    """Undeclare publishers, subscribers and tokens, then close sessions; never raises,
    safe to call twice. Pass entities before their session (any order works: sessions
    are closed last)."""
    sessions = [o for o in objs if isinstance(o, zenoh.Session)]
    for o in objs:
        if o is None or isinstance(o, zenoh.Session):
            continue
        try:
            o.undeclare()
        except Exception:
            pass
    for s in sessions:
        try:
            if not s.is_closed():
                s.close()
        except Exception:
            pass
