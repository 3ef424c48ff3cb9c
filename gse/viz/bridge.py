"""The ``ellipsled viz`` process: Zenoh (sim/truth, fsw/state, fsw/events) -> RerunLogger.

A thin shell (docs/interfaces/index.md, Rerun): it polls three subscribers, decodes each
payload with the one codec (interfaces/codec.py) in ``decode_sample``, and hands the
records to the RerunLogger. The FSW never calls Rerun.

- It never slows the run down: subscribers are rings (``newest_only``): if the bridge
  falls behind, the oldest samples are dropped and counted (sequence gaps), not queued
  against the publishers.
- Bad payloads are rejected by the codec, counted, and shown as rate-limited
  ``bridge/bad_payload`` events; the bridge never crashes on them.
- Publishers that stop and come back (a restarted process has a new publisher id) are
  accepted again (SequenceGuard takeover); the zenoh session reconnects by itself.
- SIGINT / SIGTERM stop it cleanly: buffered rows are flushed, the file finalised, the
  session closed.
"""
from __future__ import annotations

import argparse
import math
import signal
import sys
import time
from pathlib import Path


from common import argtypes
from common.events import Event, EventLog, Severity
from gse.viz.logger import RerunLogger
from gse.viz.sinks import open_sinks
from interfaces import codec
from interfaces import keys as keymod
from interfaces.event_catalogue import EV
from interfaces.keys import DEFAULT_PREFIX

WALL_S = argtypes.float_range(0.0, 7 * 86_400.0, lo_open=True)     # a wall-clock limit [s], a week at most


def make_codecs(on_reject=None) -> dict[str, codec.Codec]:
    return {"truth": codec.Codec.for_schema("TRUTH", on_reject=on_reject),
            "fsw": codec.Codec.for_schema("FSW_STATE", on_reject=on_reject),
            "event": codec.Codec.for_schema("EVENT", on_reject=on_reject)}


def decode_sample(c: codec.Codec, kind: str, payload):
    """One payload -> ('truth'|'fsw', k, t_s, record) or ('event', Event), or None when
    the codec rejects it (reason counted in ``c.rejects``)."""
    rec = c.decode(payload)
    if rec is None:
        return None
    if kind == "event":
        return ("event", Event(int(rec["t_ns"]) * 1e-9, _severity(int(rec["severity"])),
                               codec.record_text(rec["source"]), codec.record_text(rec["code"]),
                               codec.record_text(rec["text"])))
    return (kind, int(rec["k"]), int(rec["t_ns"]) * 1e-9, rec)


def _severity(v: int) -> Severity:
    try:
        return Severity(v)
    except ValueError:
        return Severity.INFO


class Bridge:
    """The bridge loop without process concerns: ``poll()`` drains the subscribers once."""

    def __init__(self, session, k: keymod.Keys, logger: RerunLogger, capacity: int = 4096):
        from interfaces import transport
        self.logger = logger
        self.events = EventLog(min_interval_s=1.0)
        self._last_t = 0.0
        self.codecs = make_codecs(on_reject=self._on_reject)
        self.subs = {"truth": transport.subscriber(session, k.truth, newest_only=True, capacity=capacity),
                     "fsw": transport.subscriber(session, k.state, newest_only=True, capacity=capacity),
                     "event": transport.subscriber(session, k.events, newest_only=True, capacity=capacity)}
        self.received = {kind: 0 for kind in self.subs}

    def _on_reject(self, reason: str, detail: str) -> None:
        self.events.emit(self._last_t, EV.BAD_PAYLOAD, reason=reason, detail=detail)

    def poll(self, max_per_topic: int = 1000) -> int:
        """Decode and log what has arrived; returns the number of samples handled."""
        n = 0
        for kind, sub in self.subs.items():
            c = self.codecs[kind]
            for _ in range(max_per_topic):
                s = sub.try_recv()
                if s is None:
                    break
                n += 1
                self.received[kind] += 1
                out = decode_sample(c, kind, s.payload)
                if out is None:
                    continue
                if out[0] == "event":
                    self.logger.log_event(out[1])
                elif out[0] == "truth":
                    self._last_t = out[2]
                    self.logger.log_truth(out[1], out[2], out[3])
                else:
                    self.logger.log_fsw(out[1], out[2], out[3])
        for ev in self.events.drain():
            self.logger.log_event(ev)
        self.logger.tick()
        return n

    def stats(self) -> dict:
        out = {"received": dict(self.received), "logger": dict(self.logger.stats)}
        for kind, c in self.codecs.items():
            out[f"{kind}_rejects"] = {r: v for r, v in c.rejects.items() if v}
            if c.guard is not None:
                out[f"{kind}_lost"] = c.guard.lost
        return out

    def close(self) -> None:
        from interfaces import transport
        transport.close(*self.subs.values())


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``ellipsled viz`` (the lead's cli.py adds them to its sub-parser)."""
    p.add_argument("--prefix", default=DEFAULT_PREFIX,
                   help=f"vehicle name or key prefix (interfaces/keys.py; default {DEFAULT_PREFIX}, as sim and fsw)")
    p.add_argument("--connect", action="append", default=None, help="zenoh endpoint to connect to (repeatable)")
    p.add_argument("--listen", action="append", default=None, help="zenoh endpoint to listen on (repeatable)")
    p.add_argument("--zenoh-config", default=None, help="zenoh JSON5 configuration file")
    p.add_argument("--zenoh-lowlatency", action=argparse.BooleanOptionalAction, default=True,
                   help="Zenoh's low-latency transport (default on; must match the run's processes)")
    p.add_argument("--rerun", default="auto", help="viewer | web | file | none | auto, or '+'-joined")
    p.add_argument("--out", default="out/viz", help="folder of the .rrd")
    p.add_argument("--name", default="run", help="recording / file name")
    p.add_argument("--flush-rows", type=argtypes.int_range(1, 1_000_000), default=50)
    p.add_argument("--flush-s", type=argtypes.timeout_s, default=1.0)
    p.add_argument("--max-seconds", type=WALL_S, default=math.inf, help="stop after this wall time (default: none)")
    p.add_argument("--idle-exit-s", type=WALL_S, default=math.inf,
                   help="stop when nothing has arrived for this long after data was seen (default: never)")


def bridge_main(args) -> int:
    """Entry point of ``ellipsled viz``; ``args`` from ``add_arguments``. Exit status 0."""
    from interfaces import transport
    stop = {"flag": False}

    def _stop(signum, frame):
        stop["flag"] = True

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    k = keymod.keys(args.prefix)
    sinks = open_sinks(args.rerun, Path(args.out), name=args.name)
    logger = RerunLogger(sinks.rec, flush_rows=args.flush_rows, flush_s=args.flush_s)
    session = transport.open_session("bridge", args.listen, args.connect, args.zenoh_config,
                                     lowlatency=bool(args.zenoh_lowlatency))
    token = bridge = None
    try:
        token = transport.declare_alive(session, k, "bridge")
        bridge = Bridge(session, k, logger)
        t0 = last_rx = time.monotonic()
        seen = False
        while not stop["flag"]:
            n = bridge.poll()
            now = time.monotonic()
            if n:
                seen, last_rx = True, now
            else:
                time.sleep(0.002)
            if now - t0 >= args.max_seconds or (seen and now - last_rx >= args.idle_exit_s):
                break
    finally:
        logger.close()
        if bridge is not None:
            print(f"bridge: {bridge.stats()}", file=sys.stderr)
            bridge.close()
        transport.close(token, session)
        sinks.close()
        for s, h in old.items():
            signal.signal(s, h)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="ellipsled viz", description=__doc__.splitlines()[0])
    add_arguments(p)
    return bridge_main(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
