"""``ellipsled gse ...``: the ground console and the same commands for scripts.

Each scripted command sends one signed request, waits for the vehicle's answer (COMMAND_ACK
or PARAM_VALUE, with retries) and exits with:
  0  ACCEPTED (param set: the vehicle echoed the requested value)
  1  refused: the MAV_RESULT name (DENIED, UNSUPPORTED, TEMPORARILY_REJECTED, FAILED, ...)
     or the STATUSTEXT reason of a refused parameter is printed on stderr
  2  usage or configuration error (bad arguments, no signing key, port in use)
  3  no answer within the timeout and retries (TIMEOUT)

Scripts listen on an ephemeral port (``--gcs-port 0``, the default) and send to
``--vehicle`` (default udp:127.0.0.1:14555, the FSW ground link's default), so they work
while the console holds 14550. The console listens on 14550 by default and learns the
vehicle's address from its telemetry unless ``--vehicle`` is given.
"""
from __future__ import annotations

import argparse
import os
import sys

from common import argtypes
from interfaces.mavlink.signing.keys import SigningKeyError
from interfaces.vocabulary import DEFAULT_GCS, FAULT_KINDS, MARK_KINDS, N_JETS, Mode, parse_udp

from .client import DEFAULT_VEHICLE, GroundClient, float32_equal, load_key, result_name
from .commands import Request, make_request

EXIT_OK, EXIT_REFUSED, EXIT_USAGE, EXIT_TIMEOUT = 0, 1, 2, 3
REASON_WAIT_S = 0.5         # after a refusal, how long to wait for the vehicle's STATUSTEXT
REPLAY_SPEED = argtypes.float_range(0.01, 1000.0)      # times the recorded pace


def _common(p: argparse.ArgumentParser, gcs_port_default: int) -> None:
    p.add_argument("--gcs-port", type=argtypes.udp_port, default=gcs_port_default,
                   help=f"UDP port to listen on at 127.0.0.1 (default {gcs_port_default}; 0 = ephemeral)")
    p.add_argument("--gcs-host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--vehicle", default=None,
                   help=f"vehicle address udp:HOST:PORT (scripts default {DEFAULT_VEHICLE}; the console "
                        "learns it from the telemetry)")
    p.add_argument("--signing-key", default=None, metavar="FILE",
                   help="signing key file (64 hex chars), else $ELLIPSLED_SIGNING_KEY_FILE")
    p.add_argument("--tlog", default=None, metavar="PATH", help="record every frame sent and received")
    p.add_argument("--timeout", type=argtypes.timeout_s, default=1.0, help="seconds to wait for each answer (default 1)")
    p.add_argument("--retries", type=argtypes.retries, default=3, help="resends after a timeout (default 3)")


def add_gse_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``gse`` and its subcommands to an argparse subparsers object; each sets
    ``func(args) -> exit code``."""
    gse = subparsers.add_parser("gse", help="ground station: console and scripted commands (MAVLink 2, signed)",
                                description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = gse.add_subparsers(dest="gse_cmd", required=True)

    p = sub.add_parser("console", help="terminal UI: live state, jets, events; commands by key or line")
    _common(p, parse_udp(DEFAULT_GCS, "DEFAULT_GCS")[1])
    p.add_argument("--view-only", action="store_true",
                   help="watch without the signing key: nothing is sent, telemetry is shown unverified")
    p.add_argument("--replay", default=None, metavar="FILE.tlog", help="play a recorded .tlog on the same screens")
    p.add_argument("--speed", type=REPLAY_SPEED, default=1.0, help="replay pace, times the recorded one (default 1)")
    p.set_defaults(func=_run_console)

    p = sub.add_parser("inject", help="inject a jet fault in the plant (MAV_CMD_INJECT_FAILURE)")
    p.add_argument("--jet", required=True, help=f"1..{N_JETS}, 0 = all")
    p.add_argument("--kind", required=True, help="|".join(FAULT_KINDS) + " (or a unique prefix)")
    p.add_argument("--eta", default=None, help="thrust factor in (0, 1) for degraded")
    _common(p, 0)
    p.set_defaults(func=lambda a: _run_words(a, "inject", a.jet, a.kind, *([a.eta] if a.eta is not None else [])))

    p = sub.add_parser("mark", help="FDIR override: mark a jet's health (or inhibit it)")
    p.add_argument("--jet", required=True, help=f"1..{N_JETS}")
    p.add_argument("--kind", required=True, help="|".join(MARK_KINDS) + " (or a unique prefix)")
    p.add_argument("--eta", default=None, help="thrust factor in (0, 1) for degraded")
    _common(p, 0)
    p.set_defaults(func=lambda a: _run_words(a, "mark", a.jet, a.kind, *([a.eta] if a.eta is not None else [])))

    p = sub.add_parser("clear", help="clear a jet's FDIR latch, override and inhibit")
    p.add_argument("--jet", required=True, help=f"1..{N_JETS}, 0 = all")
    _common(p, 0)
    p.set_defaults(func=lambda a: _run_words(a, "clear", a.jet))

    for verb, choices, hlp in (("arm", ["on", "off"], "arm or disarm the jets"),
                               ("mode", [m.name.lower() for m in Mode], "set the FSW mode"),
                               ("ft", ["on", "off"], "fault-tolerant allocation on or off")):
        p = sub.add_parser(verb, help=hlp)
        p.add_argument("value", choices=choices)
        _common(p, 0)
        p.set_defaults(func=lambda a, verb=verb: _run_words(a, verb, a.value))

    p = sub.add_parser("delay", help="set the FDIR isolation-to-reconfiguration delay")
    p.add_argument("seconds")
    _common(p, 0)
    p.set_defaults(func=lambda a: _run_words(a, "delay", a.seconds))

    p = sub.add_parser("param", help="FSW parameters: list, get ID, set ID VALUE")
    p.add_argument("action", choices=["list", "get", "set"])
    p.add_argument("words", nargs="*", help="ID [VALUE]")
    _common(p, 0)
    p.set_defaults(func=lambda a: _run_words(a, "param", a.action, *a.words))
    return gse


# ---------------------------------------------------------------- running

def _client(a, link_id: int) -> GroundClient:
    key = None if getattr(a, "view_only", False) else load_key(a.signing_key)
    vehicle = a.vehicle
    if vehicle is None and a.gse_cmd != "console":
        vehicle = DEFAULT_VEHICLE
    return GroundClient(key, listen=f"udp:{a.gcs_host}:{a.gcs_port}", vehicle=vehicle, link_id=link_id,
                        tlog=a.tlog)


def _script_link_id() -> int:
    """Scripts sign on their own link id (1..255), apart from the console's 0."""
    return 1 + os.getpid() % 255


def _run_words(a, verb: str, *words) -> int:
    try:
        req = make_request(verb, *[str(w) for w in words])
    except ValueError as e:
        print(f"gse {verb}: {e}", file=sys.stderr)
        return EXIT_USAGE
    try:
        client = _client(a, _script_link_id())
    except (SigningKeyError, OSError, ValueError) as e:
        print(f"gse {verb}: {e}", file=sys.stderr)
        return EXIT_USAGE
    with client:
        return execute(client, req, timeout_s=a.timeout, retries=a.retries)


def _reasons(client: GroundClient, since: float, wait_s: float) -> list[str]:
    """STATUSTEXTs of severity WARNING or worse received after ``since`` (waits up to wait_s)."""
    def found():
        return [e for e in client.state.events if e.t_unix_s >= since and e.severity <= 4]
    client.wait_for(lambda: bool(found()), wait_s)
    return [f"{e.severity_name}: {e.text}" for e in found()]


def execute(client: GroundClient, req: Request, *, timeout_s: float = 1.0, retries: int = 3,
            out=None, err=None) -> int:
    """Send ``req``, wait for the answer, print it; the exit code (module docstring)."""
    out = out or sys.stdout
    err = err or sys.stderr
    t0 = client.clock()
    client.send_heartbeat()
    if req.command:
        result = client.command(req.command, *req.params, timeout_s=timeout_s, retries=retries)
        name = result_name(result)
        if result == 0:
            print(f"{req.label}: {name}", file=out)
            return EXIT_OK
        print(f"{req.label}: {name}", file=err)
        if result is not None:
            for r in _reasons(client, t0, REASON_WAIT_S):
                print(f"  vehicle says {r}", file=err)
        return EXIT_TIMEOUT if result is None else EXIT_REFUSED
    if req.param == "list":
        params = client.param_list(timeout_s=timeout_s * (retries + 1))
        count = client.state.param_count
        for pid in sorted(params):
            print(f"{pid:<16} {params[pid]:.9g}", file=out)
        if count is None or len(params) < count:
            print(f"param list: {len(params)} of {count if count is not None else '?'} received (TIMEOUT)", file=err)
            return EXIT_TIMEOUT
        return EXIT_OK
    if req.param == "get":
        v = client.param_get(req.param_id, timeout_s=timeout_s, retries=retries)
        if v is None:
            print(f"{req.label}: no answer (unknown id or TIMEOUT)", file=err)
            for r in _reasons(client, t0, 0.0):
                print(f"  vehicle says {r}", file=err)
            return EXIT_TIMEOUT
        print(f"{req.param_id} {v:.9g}", file=out)
        return EXIT_OK
    # set
    v = client.param_set(req.param_id, req.value, timeout_s=timeout_s, retries=retries)
    if v is None:
        print(f"{req.label}: no answer (unknown id or TIMEOUT)", file=err)
        for r in _reasons(client, t0, 0.0):
            print(f"  vehicle says {r}", file=err)
        return EXIT_TIMEOUT
    if float32_equal(v, req.value):
        print(f"{req.param_id} {v:.9g}: ACCEPTED", file=out)
        return EXIT_OK
    print(f"{req.label}: REFUSED (value stays {v:.9g})", file=err)
    for r in _reasons(client, t0, REASON_WAIT_S):
        print(f"  vehicle says {r}", file=err)
    return EXIT_REFUSED


def _run_console(a) -> int:
    try:
        if a.replay is not None:
            from .replay import TlogReplay
            client = TlogReplay(a.replay, speed=a.speed)
        else:
            client = _client(a, 0)
    except (SigningKeyError, OSError, ValueError) as e:
        print(f"gse console: {e}", file=sys.stderr)
        return EXIT_USAGE
    from .console import GroundConsole
    with client:
        GroundConsole(client, timeout_s=a.timeout, retries=a.retries).run()
    return EXIT_OK


def main(argv: list[str] | None = None) -> int:
    """``python -m gse.cli gse inject ...`` (the same as ``ellipsled gse ...``)."""
    ap = argparse.ArgumentParser(prog="ellipsled")
    sub = ap.add_subparsers(dest="cmd", required=True)
    add_gse_parser(sub)
    a = ap.parse_args(argv)
    try:
        return int(a.func(a) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
