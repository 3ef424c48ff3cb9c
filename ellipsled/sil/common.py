"""What the SIL processes share: command-line options, signals, the session set-up."""
from __future__ import annotations

import argparse
import os
import signal
import sys
import time

from common import argtypes
from interfaces import records, transport
from interfaces.codec import Codec
from interfaces.keys import DEFAULT_PREFIX, keys

from .variant import add_variant_arguments


def add_common_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", default="nominal", help="scenario name (data/scenarios) or .toml path")
    p.add_argument("--seed", type=argtypes.seed, default=None)
    p.add_argument("--ft-off", action="store_true", help="fault tolerance off")
    p.add_argument("--duration", type=argtypes.duration_s, default=None, help="stop after S seconds of simulated time")
    add_variant_arguments(p)
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="deterministic: the plant waits for each jet command (default)")
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="the plant runs on its own clock; the FSW on absolute deadlines")
    p.set_defaults(mode="lockstep")
    p.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                   help="Zenoh endpoint(s) to listen on, e.g. tcp/127.0.0.1:7447")
    p.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                   help="Zenoh endpoint(s) to connect to")
    p.add_argument("--zenoh-config", default=None, metavar="FILE",
                   help="a Zenoh JSON5 configuration (router, peers, TLS, access control) used instead of "
                        "the embedded loopback peer configuration")
    p.add_argument("--zenoh-lowlatency", action=argparse.BooleanOptionalAction, default=True,
                   help="Zenoh's low-latency transport in the embedded configuration (default on; every "
                        "process of the run must agree): ~30-60 us less per hop")
    p.add_argument("--prefix", default=DEFAULT_PREFIX, help="key-expression prefix of this run/vehicle")
    p.add_argument("--out", default=None, help="folder for this process's records")
    p.add_argument("--rt", action="store_true", help="real-time hygiene: SCHED_FIFO, affinity, mlockall")
    p.add_argument("--rt-priority", type=argtypes.rt_priority, default=80,
                   help="SCHED_FIFO priority of the main loop; Zenoh's I/O threads run one above it")
    p.add_argument("--cpu", type=argtypes.int_range(0, (os.cpu_count() or 1) - 1), default=None, help="pin to this CPU")
    p.add_argument("--io-cpu", type=argtypes.int_range(0, (os.cpu_count() or 1) - 1), default=None,
                   help="with --rt: the CPU of the transport's threads (Zenoh's I/O); default --cpu")


class Stop:
    """SIGINT/SIGTERM set a flag the loops poll; a blocking wait never ignores Ctrl-C."""

    def __init__(self):
        self.requested = False
        self.signal = None
        signal.signal(signal.SIGINT, self._on)
        signal.signal(signal.SIGTERM, self._on)

    def _on(self, signum, frame):
        self.requested = True
        self.signal = signum

    def __bool__(self) -> bool:
        return self.requested


def apply_rt(role: str, args) -> dict | None:
    """Real-time hygiene for a node when --rt is given: SCHED_FIFO --rt-priority, CPU
    affinity, mlockall (common.rt.apply). Call it before anything starts threads; ``open_node``
    then raises every other thread to one priority above the loop. Returns common.rt's report
    (None without --rt)."""
    if not args.rt:
        return None
    from common import rt
    rep = rt.apply(cpus=[args.cpu] if args.cpu is not None else None, priority=args.rt_priority)
    rep["io_priority"] = min(int(args.rt_priority) + 1, os.sched_get_priority_max(os.SCHED_FIFO)) \
        if rep["sched_fifo"] else None
    if not rep["sched_fifo"]:
        say(role, f"real-time: {rep}")          # else open_node says it, with the threads
    return rep


def rt_in_force(rt_report: dict | None) -> bool:
    """Whether ``apply_rt`` got SCHED_FIFO (then loops may spin: see ``open_node``)."""
    return bool(rt_report and rt_report.get("sched_fifo"))


# Where the real-time SIL puts its nodes on a machine of two CPUs or more (``ellipsled run
# --realtime``; the latency bench's "sil" placement): role -> (the loop's CPU, the CPU of its
# transport threads). The flight software's loop has CPU 1 to itself; its Zenoh threads run on
# CPU 0 with the plant's. On the loop's own CPU they preempted it in the wait for the frame
# and left its caches cold: control task p99 at 200 Hz 30.2 -> 25.5 us, sensor-to-actuator
# p99 265 -> 200 us, the two placements alternated in one run (docs/decisions.md).
RT_PLACEMENT = {"sim": (0, 0), "fsw": (1, 0)}


def rt_arguments(role: str) -> list[str]:
    """A node's real-time options as ``RT_PLACEMENT`` places it."""
    cpu, io_cpu = RT_PLACEMENT[role]
    return ["--rt", "--cpu", str(cpu), "--io-cpu", str(io_cpu)]


def open_node(role: str, args, rt_report: dict | None = None):
    """(session, keys) for a node, from its options. With SCHED_FIFO in force (``apply_rt``),
    every other thread of the process — Zenoh's I/O threads, the runtime threads its binding
    starts at import — goes to --io-cpu (default: this node's CPU) one priority above the loop,
    so an arriving sample preempts whatever runs there instead of queueing behind it; our own
    Python threads (background jobs: they take the GIL) stay on the loop's CPU one below the
    loop (common.rt.run_below_loop)."""
    session = transport.open_session(role, args.listen, args.connect, args.zenoh_config,
                                     lowlatency=bool(getattr(args, "zenoh_lowlatency", True)))
    if rt_in_force(rt_report):
        from common import rt
        loop_cpus = [args.cpu] if args.cpu is not None else None
        io_cpu = getattr(args, "io_cpu", None)
        io_cpus = [io_cpu] if io_cpu is not None else loop_cpus
        others = rt.other_threads(io_cpus, rt_report["io_priority"], python_priority=int(args.rt_priority) - 1,
                                  python_cpus=loop_cpus)
        rt_report["threads"] = [f"{name}:{prio}" for _, name, prio, _ in others["threads"]]
        rt_report["io_cpus"] = io_cpus
        rt_report["messages"] += others["messages"]
        say(role, f"real-time: loop SCHED_FIFO {rt_report['priority']}, I/O threads {rt_report['io_priority']} "
                  f"on CPUs {io_cpus}, CPUs {rt_report['affinity']}, mlockall {rt_report['mlockall']}"
                  + (f"; {'; '.join(rt_report['messages'])}" if rt_report["messages"] else ""))
    return session, keys(args.prefix)


def say(role: str, text: str) -> None:
    print(f"[{role}] {text}", file=sys.stderr, flush=True)


def now_ns() -> int:
    return time.monotonic_ns()


class DecodeRehearsal:
    """Real time: a key's decode path run once more, on a guard-less scratch codec, on the
    last payload the node accepted -- at a moment the node would spend waiting anyway, so
    that what the decode needs is in the caches when the next payload comes (idle for a
    period, with other work in between, that path runs an order of magnitude slower:
    docs/changelog.md). Nothing counted, nothing kept. ``copy``: decode into a scratch record,
    as the node does (else a view, as the node does)."""

    def __init__(self, schema: str, copy: bool):
        self._dec = Codec.for_schema(schema, guard=False)
        self._out = records.new(getattr(records, schema)) if copy else None
        self.last: bytes | None = None

    def run(self) -> None:
        if self.last is not None:
            self._dec.decode(self.last, out=self._out)
