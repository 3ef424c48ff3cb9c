"""Round-trip latency between two processes on 127.0.0.1 (spec 50-performance.md):

- baseline: a plain Python UDP echo (blocking sockets), 64-byte datagrams;
- Zenoh + codec: the client publishes an encoded SENSORS frame (interfaces/transport.py
  sessions, publishers and polled subscribers, as the SIL shells use them), the echo
  process decodes it and publishes an encoded JETS frame back — the transport part of the
  SIL's sensor-to-actuator path, without the FSW compute.

Round trips are paced (``rate_hz``) like a control loop, not back to back, so each one
pays the wake-up of an idle process. Each echo runs in its own interpreter
(``python -m ellipsled.bench.latency --echo udp|zenoh --port P``), started and ended by pid.
"""
from __future__ import annotations

import argparse
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np

from .rows import NO_TARGET, Row, fmt, ratio, row

READY = "ECHO-READY"


def _stats(rtt_ns: list[int], lost: int) -> dict:
    a = np.asarray(rtt_ns, dtype=np.float64) * 1e-3
    if a.size == 0:
        return {"p50_us": None, "p99_us": None, "max_us": None, "n": 0, "lost": lost}
    return {"p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
            "max_us": float(a.max()), "n": int(a.size), "lost": int(lost)}


# --------------------------------------------------------------------------- echo processes
def _echo_udp(port: int) -> None:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", port))
    print(READY, flush=True)
    while True:
        data, addr = s.recvfrom(2048)
        if data == b"quit":
            return
        s.sendto(data, addr)


def _echo_zenoh(port: int) -> None:
    from interfaces import records, transport
    from interfaces.codec import Codec
    from interfaces.keys import keys
    k = keys("bench-latency")
    ses = transport.open_session("sim", [transport.loopback(port)], [])
    sub = transport.subscriber(ses, k.sensors)
    pub = transport.publisher(ses, k.jets)
    dec, enc = Codec.for_schema("SENSORS"), Codec.for_schema("JETS")
    jets = records.new(records.JETS)
    print(READY, flush=True)
    seq = 0
    try:
        while True:
            smp = transport.recv(sub, timeout_s=30.0)
            if smp is None:
                return
            rec = dec.decode(smp.payload)
            if rec is None:
                continue
            if int(rec["k"]) < 0:
                return
            jets["k"] = rec["k"]
            jets["t_release_ns"] = rec["t_ns"]
            pub.put(enc.encode(jets, seq, time.monotonic_ns()))
            seq += 1
    finally:
        transport.close(sub, pub, ses)


# --------------------------------------------------------------------------- clients
def _start_echo(kind: str, port: int) -> subprocess.Popen:
    p = subprocess.Popen([sys.executable, "-m", "ellipsled.bench.latency", "--echo", kind, "--port", str(port)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    t_end = time.monotonic() + 30.0
    line = ""
    while time.monotonic() < t_end:
        line = p.stdout.readline()
        if READY in line or line == "":
            break
    if READY not in line:
        _stop(p)
        err = p.stderr.read()[-400:] if p.stderr else ""
        raise RuntimeError(f"{kind} echo process did not start: {err.strip()}")
    return p


def _stop(p: subprocess.Popen) -> None:
    if p.poll() is None:
        try:
            p.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            os.kill(p.pid, signal.SIGTERM)
            try:
                p.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                os.kill(p.pid, signal.SIGKILL)
                p.wait()


def udp_roundtrip(n: int, rate_hz: float) -> dict:
    from interfaces.transport import free_port
    port = free_port()
    p = _start_echo("udp", port)
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(1.0)
    rtt, lost = [], 0
    msg = bytearray(64)
    period = int(1e9 / rate_hz)
    try:
        t_next = time.monotonic_ns()
        for i in range(n + 50):
            t_next += period
            while time.monotonic_ns() < t_next:
                time.sleep(max((t_next - time.monotonic_ns()) * 1e-9, 0.0))
            msg[:8] = i.to_bytes(8, "little")
            t0 = time.perf_counter_ns()
            s.sendto(msg, ("127.0.0.1", port))
            try:
                while True:
                    data = s.recv(2048)
                    if data[:8] == msg[:8]:
                        break
            except socket.timeout:
                lost += 1
                if p.poll() is not None or lost > 20:
                    raise RuntimeError(f"udp echo not answering (exit code {p.poll()}, {lost} lost)")
                continue
            if i >= 50:                          # first 50: warm-up
                rtt.append(time.perf_counter_ns() - t0)
        s.sendto(b"quit", ("127.0.0.1", port))
    finally:
        s.close()
        _stop(p)
    return _stats(rtt, lost)


def zenoh_roundtrip(n: int, rate_hz: float) -> dict:
    from interfaces import records, transport
    from interfaces.codec import Codec
    from interfaces.keys import keys
    port = transport.free_port()
    p = _start_echo("zenoh", port)
    k = keys("bench-latency")
    ses = pub = sub = None
    rtt, lost = [], 0
    try:
        ses = transport.open_session("fsw", [], [transport.loopback(port)])
        sub = transport.subscriber(ses, k.jets)
        pub = transport.publisher(ses, k.sensors)
        if not transport.wait_for_subscriber(pub, 10.0):
            raise RuntimeError("zenoh echo never matched the sensors publisher")
        enc, dec = Codec.for_schema("SENSORS"), Codec.for_schema("JETS")
        rec = records.new(records.SENSORS)
        period = int(1e9 / rate_hz)
        t_next = time.monotonic_ns()
        for i in range(n + 50):
            t_next += period
            while time.monotonic_ns() < t_next:
                time.sleep(max((t_next - time.monotonic_ns()) * 1e-9, 0.0))
            rec["k"] = i
            rec["t_ns"] = i
            t0 = time.perf_counter_ns()
            pub.put(enc.encode(rec, i, time.monotonic_ns()))
            while True:
                smp = transport.recv(sub, timeout_s=1.0)
                if smp is None:
                    lost += 1
                    if p.poll() is not None or lost > 20:
                        raise RuntimeError(f"zenoh echo not answering (exit code {p.poll()}, {lost} lost)")
                    break
                back = dec.decode(smp.payload)
                if back is not None and int(back["k"]) == i:
                    if i >= 50:
                        rtt.append(time.perf_counter_ns() - t0)
                    break
        rec["k"] = -1
        pub.put(enc.encode(rec, n + 60, 0))
    finally:
        transport.close(sub, pub, ses)
        _stop(p)
    return _stats(rtt, lost)


def run(quick: bool) -> dict:
    n, rate = (1000, 100.0) if quick else (6000, 100.0)
    udp = udp_roundtrip(n, rate)
    zen = zenoh_roundtrip(n, rate)
    return {"figure": "round trip between two processes on 127.0.0.1 [us], paced at %g Hz" % rate,
            "round_trips": n, "rate_hz": rate,
            "udp_p50_us": udp["p50_us"], "udp_p99_us": udp["p99_us"], "udp_max_us": udp["max_us"],
            "udp_lost": udp["lost"],
            "zenoh_p50_us": zen["p50_us"], "zenoh_p99_us": zen["p99_us"], "zenoh_max_us": zen["max_us"],
            "zenoh_lost": zen["lost"],
            "zenoh_over_udp_p99": (zen["p99_us"] / udp["p99_us"]) if zen["p99_us"] and udp["p99_us"] else None}


def rows(res: dict) -> list[Row]:
    lat = res.get("latency") or {}
    if not lat:
        return []
    return [row("Zenoh + codec round trip p50 / p99 [us] (2 processes)",
                f"{fmt(lat.get('zenoh_p50_us'))} / {fmt(lat.get('zenoh_p99_us'))}",
                f"UDP {fmt(lat.get('udp_p50_us'))} / {fmt(lat.get('udp_p99_us'))}",
                f"{fmt(ratio(lat.get('zenoh_p99_us'), lat.get('udp_p99_us')))}x (p99)", "", NO_TARGET)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--echo", choices=("udp", "zenoh"))
    ap.add_argument("--port", type=int, default=0)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    if a.echo == "udp":
        _echo_udp(a.port)
    elif a.echo == "zenoh":
        _echo_zenoh(a.port)
    else:
        import json
        print(json.dumps(run(a.quick), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
