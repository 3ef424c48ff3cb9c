"""Ground-link benchmark (fsw/groundlink/): cost of one ``GroundLink.tick`` (poll the
socket, sample the allocator, send the MAVLink telemetry that is due, signed) against the
FSW control step measured in the same run — the link runs in RG2 (10 Hz) of the FSW process.

Four regimes, driven by a fake scheduling clock: nothing due (idle tick), one RG2 step of
0.1 s (the 10 Hz streams due), 1 s (every stream due at once), and every stream at the
fastest rate a ground station may set with MAV_CMD_SET_MESSAGE_INTERVAL (the link's tick
rate: every stream every tick), the bound on what the interval command can cost. The
telemetry goes to a UDP socket on 127.0.0.1 that the benchmark drains.
"""
from __future__ import annotations

import gc
import socket
import sys
import time

import numpy as np

from common.model import load_scenario
from fsw.flightsoftware import FlightSoftware
from fsw.groundlink import GroundLink
from interfaces.mavlink.signing.keys import SigningKey
from sim.plant import Plant

from .rows import NO_TARGET, Row, fmt, g, row


class _Clock:
    def __init__(self, t: float = 1000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


def _pct(ns: list[int]) -> dict:
    a = np.asarray(ns, dtype=np.float64) * 1e-3
    return {"p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)), "max_us": float(a.max()),
            "n": int(a.size)}


def run(quick: bool) -> dict:
    n = 300 if quick else 2000
    scn = load_scenario("case1").with_(faults=())
    plant, fsw = Plant(scn), FlightSoftware(scn)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setblocking(False)
    clock = _Clock()
    gl = GroundLink(fsw, SigningKey.generate(), gcs=f"udp:127.0.0.1:{sink.getsockname()[1]}",
                    bind="udp:127.0.0.1:0", clock=clock)
    frame = plant.sensors
    ctl_ns: list[int] = []
    rx_bytes = 0

    def drain():
        nonlocal rx_bytes
        while True:
            try:
                rx_bytes += len(sink.recv(65536))
            except BlockingIOError:
                return

    def step():
        nonlocal frame
        t0 = time.perf_counter_ns()
        u = fsw.control_step(frame)
        ctl_ns.append(time.perf_counter_ns() - t0)
        frame = plant.step(u)

    for _ in range(100):                        # warm-up: flight under way, first sends
        step()
        clock.t += 0.02
        gl.tick(frame)
        drain()
    ctl_ns.clear()
    out = {}
    gc_was = gc.isenabled()
    gc.disable()
    try:
        for name, advance in (("idle_tick", 0.0), ("rg2_tick_10Hz", 0.1), ("all_streams_due_1s", 1.0),
                              ("all_streams_at_fastest", 0.1)):
            if name == "all_streams_at_fastest":
                for stream in gl.rates_hz:
                    gl.rates_hz[stream] = gl.max_rate_hz
            ns = []
            b0 = gl.stats["tx_bytes"]
            for _ in range(n):
                for _ in range(5):
                    step()
                clock.t += advance
                t0 = time.perf_counter_ns()
                gl.tick(frame)
                ns.append(time.perf_counter_ns() - t0)
                drain()
            out[name] = {**_pct(ns), "tx_bytes_per_tick": (gl.stats["tx_bytes"] - b0) / n}
    finally:
        if gc_was:
            gc.enable()
        gl.close()
        sink.close()
    ctl = _pct(ctl_ns)
    return {"figure": "ground link tick [us] vs the FSW control step, same run", "ticks": n,
            **out,
            "tick_p99_us": out["rg2_tick_10Hz"]["p99_us"],
            "fastest_rate_hz": gl.max_rate_hz, "tick_at_fastest_p99_us": out["all_streams_at_fastest"]["p99_us"],
            "tick_at_fastest_max_us": out["all_streams_at_fastest"]["max_us"],
            "baseline_control_step_p50_us": ctl["p50_us"], "baseline_control_step_p99_us": ctl["p99_us"],
            "tick_p99_over_control_p99": out["rg2_tick_10Hz"]["p99_us"] / ctl["p99_us"],
            "tx_errors": int(gl.stats["tx_errors"]), "telemetry_bytes_received": rx_bytes}


def rows(res: dict) -> list[Row]:
    gl = res.get("groundlink") or {}
    if not gl:
        return []
    return [row("ground link tick at 10 Hz p50 / p99 [us]",
                f"{fmt(g(gl, 'rg2_tick_10Hz', 'p50_us'))} / {fmt(gl.get('tick_p99_us'))}",
                f"control step p99 {fmt(gl.get('baseline_control_step_p99_us'))}",
                f"{fmt(gl.get('tick_p99_over_control_p99'))}x", "", NO_TARGET),
            row("ground link tick, every stream at the fastest settable rate p99 / max [us]",
                f"{fmt(gl.get('tick_at_fastest_p99_us'))} / {fmt(gl.get('tick_at_fastest_max_us'))}",
                f"control step p99 {fmt(gl.get('baseline_control_step_p99_us'))}", "", "", NO_TARGET)]


if __name__ == "__main__":
    import json
    print(json.dumps(run("--quick" in sys.argv), indent=2))
