"""Ground-link benchmark (fsw/groundlink/): cost of one ``GroundLink.tick`` (receive and
answer, sample the allocator, send the MAVLink telemetry that is due, signed) against its
budget per tick (fsw/groundlink/schedule.py: a share of the control period), at 50 and
200 Hz, beside the FSW control step measured in the same run; the loop runs SCHED_FIFO when
permitted, as the FSW's control thread does in the real-time SIL (``sched_fifo`` says), and
like that thread it sleeps a control period before the cycle whose link tick is measured (the
flight between link ticks is flown back to back). Without the sleep a SCHED_FIFO loop busy for
longer than the kernel's real-time budget (``sched_rt_runtime_us`` of each
``sched_rt_period_us``, 0.95 s of 1 s by default) is stopped for the rest of the period: a
~50-ms tick once a second of busy loop, the host's throttle, not the link's work
(``rt_throttle`` records the budget in force).

Three regimes, the scheduling clock advanced one RG2 period a tick: the default stream
rates; every stream at the fastest rate a ground station may set with
MAV_CMD_SET_MESSAGE_INTERVAL (the bound on what the interval command can cost); the default
rates while a keyless sender floods the link at FLOOD_PER_S (unsigned reads and commands,
MAVLink 1, garbage). Deferred stream sends are counted beside each. The telemetry goes to a
UDP socket on 127.0.0.1 that the benchmark drains.

And every command answered: the real-time SIL (``ellipsled run case1 --realtime``) at 50
and at 200 Hz (``--dt-control``), a ground station with the key sending a signed read-only
command at ANSWER_PACE_HZ from the first jet command on (the warm-up over), counting the
answers: in time when the COMMAND_ACK is back within flood.ANSWER_IN_TIME_S (two RG2 periods),
late, or missing (a command sent a second or more before the vehicle's last frame); one
command at a time, so each ACK is its own command's (flood.GroundWatch).
"""
from __future__ import annotations

import gc
import socket
import sys
import time

import numpy as np

from common import rt
from common.model import load_scenario
from fsw.executive import divisors
from fsw.flightsoftware import FlightSoftware
from fsw.groundlink import GroundLink
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing.keys import SigningKey
from sim.plant import Plant

from .rows import Row, fmt, le, ratio, row


class _Clock:
    def __init__(self, t: float = 1000.0):
        self.t = t

    def __call__(self) -> float:
        return self.t


def _pct(ns: list[int]) -> dict:
    a = np.asarray(ns, dtype=np.float64) * 1e-3
    return {"p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)), "max_us": float(a.max()),
            "n": int(a.size)}


FLOOD_PER_S = 2500                   # datagrams a second in the flood regime (the flood section's rate)
RATES_HZ = (50, 200)                 # control rates the link's budget is measured at
ANSWER_PACE_HZ = 5.0                 # signed commands a second in the real-time runs
PRIORITY = 50                        # SCHED_FIFO priority of the measured loop, when permitted
# the link's counters of work a tick put off to a later one, per kind (fsw/groundlink/schedule.py),
# and the received frames handled (what a flood leaves the intake room for)
DEFERRED = ("tx_deferred", "rx_deferred", "rx_budget_hits", "events_deferred", "params_deferred", "ftp_deferred")


def _flood_datagrams(n: int) -> list[bytes]:
    """A keyless mix: unsigned parameter reads (answered within the sender's read budget),
    unsigned commands (refused), MAVLink 1 frames and garbage (refused before any CRC)."""
    mav1 = mav.MAVLink(None, srcSystem=245, srcComponent=190)
    out = []
    for i in range(n):
        k = i % 4
        if k == 0:
            out.append(mav.MAVLink_param_request_read_message(1, 1, b"NO_SUCH_PARAM", -1).pack(mav1))
        elif k == 1:
            out.append(mav.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0).pack(mav1))
        elif k == 2:
            out.append(b"\xfe\x09" + bytes(15))
        else:
            out.append(bytes((i * 7 + j) & 0xFF for j in range(40)))
    return out


def _at_rate(hz: int, quick: bool) -> dict:
    """One FSW at ``hz`` with its link: the link's tick cost against its budget in three
    regimes (default stream rates; every stream at the fastest settable rate; default rates
    under a keyless flood), and the FSW control step in the same run."""
    n = 300 if quick else 2000
    scn = load_scenario("case1").with_(faults=(), dt_control_s=1.0 / hz)
    plant, fsw = Plant(scn), FlightSoftware(scn)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setblocking(False)
    flood = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    clock = _Clock()
    gl = GroundLink(fsw, SigningKey.generate(), gcs=f"udp:127.0.0.1:{sink.getsockname()[1]}",
                    bind="udp:127.0.0.1:0", clock=clock)
    divisor = divisors(fsw.params, scn.dt_control_s)[1]
    tick_s = divisor * scn.dt_control_s
    per_tick = _flood_datagrams(max(1, round(FLOOD_PER_S * tick_s)))
    frame = plant.sensors
    ctl_ns: list[int] = []

    def drain():
        while True:
            try:
                sink.recv(65536)
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
        clock.t += scn.dt_control_s
        if fsw.cycles % divisor == 0:
            gl.tick(frame)
        drain()
    ctl_ns.clear()
    out = {}
    defaults = dict(gl.rates_hz)
    # the link ticks in the FSW's control thread, SCHED_FIFO in the real-time SIL: measured
    # so too when permitted (else a busy host's preemption is what the tail shows)
    rt_rep = rt.apply(priority=PRIORITY, lock_memory=False)
    gc_was = gc.isenabled()
    gc.disable()
    try:
        for name in ("default_rates", "all_streams_at_fastest", "flood"):
            for stream in gl.rates_hz:
                gl.rates_hz[stream] = gl.max_rate_hz if name == "all_streams_at_fastest" else defaults[stream]
            ns = []
            b0, over0 = gl.stats["tx_bytes"], gl.budget.over
            st0 = {k: gl.stats.get(k, 0) for k in (*DEFERRED, "rx_messages")}
            for _ in range(n):
                for _ in range(divisor - 1):
                    step()
                time.sleep(scn.dt_control_s)           # the period the link's cycle starts from
                step()
                if name == "flood":
                    for d in per_tick:
                        flood.sendto(d, gl.address)
                clock.t += tick_s
                t0 = time.perf_counter_ns()
                gl.tick(frame)
                ns.append(time.perf_counter_ns() - t0)
                drain()
            delta = {k: gl.stats.get(k, 0) - v for k, v in st0.items()}
            out[name] = {**_pct(ns), "tx_bytes_per_tick": (gl.stats["tx_bytes"] - b0) / n,
                         "over_budget": gl.budget.over - over0, "tx_deferred": delta["tx_deferred"],
                         "deferred": {k: delta[k] for k in DEFERRED}, "rx_messages_per_tick": delta["rx_messages"] / n}
    finally:
        rt.restore()
        if gc_was:
            gc.enable()
        gl.close()
        sink.close()
        flood.close()
    ctl = _pct(ctl_ns)
    budget_us = gl.budget.budget_ns * 1e-3
    return {"control_hz": hz, "period_us": scn.dt_control_s * 1e6, "budget_us": budget_us,
            "budget_share": budget_us / (scn.dt_control_s * 1e6), "link_tick_hz": 1.0 / tick_s,
            "flood_datagrams_per_tick": len(per_tick), "fastest_rate_hz": gl.max_rate_hz, **out,
            "worst_p99_us": max(out[k]["p99_us"] for k in out), "worst_max_us": max(out[k]["max_us"] for k in out),
            "baseline_control_step_p50_us": ctl["p50_us"], "baseline_control_step_p99_us": ctl["p99_us"],
            "tx_errors": int(gl.stats["tx_errors"]), "sched_fifo": bool(rt_rep.get("sched_fifo")),
            "rt_throttle": rt.throttle()}


def _answers(hz: int, quick: bool) -> dict:
    """The real-time SIL at ``hz`` with paced signed commands: their answers, and the FSW's
    slips and ground-link task cost in the same run."""
    from .flood import sil_run
    r = sil_run(20.0 if quick else 60.0, None, dt_control_s=1.0 / hz, pace_hz=ANSWER_PACE_HZ)
    return {**(r["answers"] or {}), "slips": r["slips"], "groundlink_p99_us": r["groundlink_p99_us"],
            "groundlink_max_us": r["groundlink_max_us"], "duration_s": r["duration_s"]}


def run(quick: bool) -> dict:
    at = {f"{hz}Hz": _at_rate(hz, quick) for hz in RATES_HZ}
    base = at[f"{RATES_HZ[0]}Hz"]
    for hz in RATES_HZ:
        at[f"{hz}Hz"]["answers"] = _answers(hz, quick)
    return {"figure": "ground link tick [us] against its budget per tick (a share of the control period), "
                      "FSW control step in the same run; signed commands answered in the real-time SIL",
            "ticks": 300 if quick else 2000, **at,
            "tick_p99_us": base["default_rates"]["p99_us"],
            "baseline_control_step_p99_us": base["baseline_control_step_p99_us"]}


def rows(res: dict) -> list[Row]:
    gl = res.get("groundlink") or {}
    out = []
    for hz in RATES_HZ:
        r = gl.get(f"{hz}Hz")
        if not r:
            continue
        for name, what in (("default_rates", "default stream rates"), ("all_streams_at_fastest", "every stream at "
                           "the fastest settable rate"), ("flood", f"under a keyless flood ({FLOOD_PER_S}/s)")):
            x = r.get(name) or {}
            out.append(row(f"ground link tick at {hz} Hz, {what}: p99 / max [us]",
                           f"{fmt(x.get('p99_us'))} / {fmt(x.get('max_us'))}",
                           f"budget {fmt(r.get('budget_us'))} ({fmt(100 * r['budget_share'])} % of the period"
                           f"{', SCHED_FIFO' if r.get('sched_fifo') else ''}); "
                           f"control step p99 {fmt(r.get('baseline_control_step_p99_us'))}",
                           f"{fmt(ratio(x.get('p99_us'), r.get('budget_us')))} of the budget; "
                           f"{x.get('tx_deferred', 'n/m')} stream sends deferred"
                           + (f", {d['events_deferred']} event sends, {d['rx_budget_hits']} reads"
                              if (d := x.get("deferred")) else ""), "p99 <= budget",
                           le(x.get("p99_us"), r.get("budget_us"))))
    for hz in RATES_HZ:
        a = (gl.get(f"{hz}Hz") or {}).get("answers")
        if not a:
            continue
        judged = a.get("sent")
        ok = None if not judged else a.get("late") == 0 and a.get("missing") == 0
        out.append(row(f"signed commands answered in time in the real-time SIL at {hz} Hz "
                       f"({fmt(a.get('pace_hz'))}/s after warm-up): in time / sent",
                       f"{fmt(a.get('in_time'))} / {fmt(judged)}",
                       f"late {fmt(a.get('late'))}, missing {fmt(a.get('missing'))}; answer p99 / max "
                       f"{fmt(a.get('latency_p99_ms'))} / {fmt(a.get('latency_max_ms'))} ms; slips {fmt(a.get('slips'))}"
                       + (f"; one command at a time, longest gap {fmt(a['send_gap_max_ms'])} ms"
                          if "send_gap_max_ms" in a else ""),
                       f"in time: ACK within {fmt(1e3 * a['in_time_s']) if a.get('in_time_s') else 'n/m'} ms",
                       "0 late, 0 missing", ok))
    return out


if __name__ == "__main__":
    import json
    print(json.dumps(run("--quick" in sys.argv), indent=2))
