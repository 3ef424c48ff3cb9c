"""``ellipsled router [--config FILE]``: the SIL's Zenoh router.

A Zenoh session opened in router mode is the same engine as the stand-alone ``zenohd``
(routing, TLS, access control), so no other program has to be installed on the router
host. Everything about it is in its configuration file (default
``data/zenoh/router.json5``: TLS with client certificates required, the access-control
policy per role); ``--listen`` replaces the file's listen endpoints.

With ``--rt`` every thread of the router runs SCHED_FIFO (``--rt-priority``, default one
above the SIL nodes' I/O threads) with memory locked: on a host it shares with real-time
nodes that spin-wait (``ellipsled sim|fsw --rt``), a time-shared router would get the CPU
only when they sleep, and every frame through it would be late.

It runs until SIGINT/SIGTERM and closes its session on the way out.
"""
from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path

from common import argtypes
from common.config import DATA_DIR

DEFAULT_CONFIG = DATA_DIR / "zenoh" / "router.json5"


def open_router(config_file: str | Path, listen: list[str] | None = None):
    """(router session, its listen endpoints). Raises ValueError (not a router configuration), zenoh.ZError
    (bad configuration, certificate not found, port taken...)."""
    import zenoh
    path = Path(config_file)
    if not path.is_file():
        raise FileNotFoundError(f"zenoh router configuration not found: {path}")
    conf = zenoh.Config.from_file(str(path))
    mode = json.loads(conf.get_json("mode"))
    if mode != "router":
        raise ValueError(f"{path}: mode is {mode!r}; `ellipsled router` needs mode: \"router\"")
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    return zenoh.open(conf), json.loads(conf.get_json("listen/endpoints"))


def add_router_parser(sub) -> None:
    p = sub.add_parser("router", help="the Zenoh router of a SIL across machines (TLS, access control)",
                       description=__doc__)
    p.add_argument("--config", default=str(DEFAULT_CONFIG), metavar="FILE",
                   help="Zenoh JSON5 configuration in router mode (default: data/zenoh/router.json5)")
    p.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                   help="listen here instead of the file's endpoints, e.g. tls/10.0.0.1:7447 (repeatable)")
    p.add_argument("--rt", action="store_true", help="every thread SCHED_FIFO --rt-priority, memory locked")
    p.add_argument("--rt-priority", type=argtypes.rt_priority, default=82,
                   help="SCHED_FIFO priority with --rt (the SIL nodes: loop 80, their I/O threads 81)")
    p.set_defaults(func=main)


def main(args) -> int:
    stop = {"flag": False}

    def _stop(signum, frame):
        stop["flag"] = True

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        rep = None
        if args.rt:
            from common import rt
            # threads created from here on inherit the policy; those zenoh started at import
            # are set after the session opens
            rep = rt.apply(priority=args.rt_priority)
        try:
            session, endpoints = open_router(args.config, args.listen)
        except Exception as e:     # zenoh.ZError carries the cause (file, certificate, address in use)
            print(f"ellipsled router: cannot start: {e}", file=sys.stderr)
            return 2
        try:
            if rep is not None:
                if rep["sched_fifo"]:
                    others = rt.other_threads(None, args.rt_priority)
                    rep["messages"] += others["messages"]
                    rep["threads"] = len(others["threads"]) + 1
                print(f"[router] real-time: SCHED_FIFO {rep['priority']} ({rep.get('threads', 1)} threads), "
                      f"mlockall {rep['mlockall']}" + (f"; {'; '.join(rep['messages'])}" if rep["messages"] else ""),
                      file=sys.stderr, flush=True)
            print(f"[router] {session.zid()} listening on {endpoints} ({args.config})", file=sys.stderr, flush=True)
            while not stop["flag"]:
                time.sleep(0.1)
        finally:
            session.close()
        print("[router] stopped", file=sys.stderr, flush=True)
        return 0
    finally:
        for s, h in old.items():
            signal.signal(s, h)
