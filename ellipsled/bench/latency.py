"""Round-trip latency between two processes on 127.0.0.1 (docs/benchmarks.md):

- baseline: a plain Python UDP echo (blocking sockets), 64-byte datagrams;
- Zenoh + codec: the client publishes an encoded SENSORS frame (interfaces/transport.py
  sessions, publishers and polled subscribers, as the SIL shells use them), the echo
  process decodes it and publishes an encoded JETS frame back — the transport part of the
  SIL's sensor-to-actuator path, without the FSW compute.

Round trips are paced (``rate_hz``) like a control loop, not back to back, so each one
pays the wake-up of an idle process. Each echo runs in its own interpreter
(``python -m ellipsled.bench.latency --echo udp|zenoh --port P``), started and ended by pid.

Payload variants (``--variants``, not in the suite): the same Zenoh round trip with each frame
put from a Zenoh shared-memory buffer (``zenoh.shm``; the receiver gets a reference into the
segment instead of a copy through the socket), with the low-latency and the standard
transport. Zenoh's own default sends a payload through shared memory only from 3 kB up
(``transport/shared_memory/transport_optimization``); our frames are ~330 bytes.

Two placements of the two processes:
- ``default``: both SCHED_OTHER, anywhere (what a plain program gets);
- ``sil``: as the real-time SIL places its nodes (``ellipsled run --realtime``, --rt;
  ellipsled/sil/common.py RT_PLACEMENT): the client (the plant's role) SCHED_FIFO 80 on CPU 0,
  the echo (the FSW's role) SCHED_FIFO 80 on CPU 1, each one's Zenoh threads one priority
  above on its role's I/O CPU (both on CPU 0), receiving as the nodes do
  (spinning when SCHED_FIFO is in force). The sensor-to-actuator target is a ratio to the
  UDP round trip of this placement: the SIL's latency includes one cross-CPU wake-up per
  hop by design, which a baseline free to run both ends on one CPU does not pay. Under
  ``sil`` the client runs in a child process too (the bench's own process keeps its
  scheduling).
"""
from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import time

import numpy as np

from common import argtypes
from ellipsled.procs import stop_process

from .rows import NO_TARGET, Row, fmt, ratio, row

READY = "ECHO-READY"


def stats_us(rtt_us, lost: int) -> dict:
    """p50 / p99 / max [us] and counts of round trips given in microseconds."""
    a = np.asarray(rtt_us, dtype=np.float64)
    if a.size == 0:
        return {"p50_us": None, "p99_us": None, "max_us": None, "n": 0, "lost": int(lost)}
    return {"p50_us": float(np.percentile(a, 50)), "p99_us": float(np.percentile(a, 99)),
            "max_us": float(a.max()), "n": int(a.size), "lost": int(lost)}


def _stats(rtt_ns: list[int], lost: int, samples: bool = False) -> dict:
    a = np.asarray(rtt_ns, dtype=np.float64) * 1e-3
    st = stats_us(a, lost)
    if samples:
        st["samples_us"] = [round(float(x), 3) for x in a]
    return st


# --------------------------------------------------------------------------- echo processes
ECHO_ROLE, CLIENT_ROLE, LOOP_PRIORITY = "fsw", "sim", 80     # the echo plays the FSW, the client the plant


def _place(placement: str, role: str) -> bool:
    """Apply the SIL's real-time placement of ``role`` (ellipsled/sil/common.py RT_PLACEMENT) to
    this process (``sil``); True if SCHED_FIFO is in force (then the receiving loops spin, as
    the SIL nodes do). Zenoh's threads are placed separately, after the session exists
    (``_raise_zenoh_threads``)."""
    if placement != "sil":
        return False
    from common import rt
    from ellipsled.sil.common import RT_PLACEMENT
    return bool(rt.apply([RT_PLACEMENT[role][0]], LOOP_PRIORITY)["sched_fifo"])


def _raise_zenoh_threads(fifo: bool, role: str) -> None:
    """Zenoh's threads one priority above the loop on the role's I/O CPU, as the SIL nodes do."""
    if fifo:
        from common import rt
        from ellipsled.sil.common import RT_PLACEMENT
        cpu, io_cpu = RT_PLACEMENT[role]
        rt.other_threads([io_cpu], LOOP_PRIORITY + 1, python_priority=LOOP_PRIORITY - 1, python_cpus=[cpu])


def _echo_udp(port: int, placement: str = "default") -> None:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", port))
    _place(placement, ECHO_ROLE)
    print(READY, flush=True)
    while True:
        data, addr = s.recvfrom(2048)
        if data == b"quit":
            return
        s.sendto(data, addr)


class _Putter:
    """put() a frame's bytes as they are, or copied into a freshly allocated Zenoh
    shared-memory buffer (``shm``); counts the frames received through shared memory."""

    def __init__(self, pub, shm: bool):
        import zenoh
        self.pub, self.shm_rx = pub, 0
        self._provider = zenoh.shm.ShmProvider.default_backend(1 << 20) if shm else None
        self._policy = zenoh.shm.BlockOn(zenoh.shm.GarbageCollect()) if shm else None

    def put(self, b: bytes) -> None:
        if self._provider is None:
            self.pub.put(b)
            return
        buf = self._provider.alloc(len(b), policy=self._policy)
        buf[:] = b
        self.pub.put(buf)

    def received(self, smp) -> None:
        if smp.payload.as_shm() is not None:
            self.shm_rx += 1


def _echo_zenoh(port: int, placement: str = "default", rate_hz: float = 100.0, shm: bool = False,
                lowlatency: bool = True) -> None:
    from interfaces import records, transport
    from interfaces.codec import Codec
    from interfaces.keys import keys
    k = keys("bench-latency")
    fifo = _place(placement, ECHO_ROLE)
    ses = transport.open_session("sim", [transport.loopback(port)], [], lowlatency=lowlatency)
    sub = transport.subscriber(ses, k.sensors)
    pub = transport.publisher(ses, k.jets)
    out = _Putter(pub, shm)
    _raise_zenoh_threads(fifo, ECHO_ROLE)
    # as the FSW node under SCHED_FIFO: release 100 us before the next frame is due, then spin
    # for it (3 ms at most); never a continuous spin (the kernel's real-time throttling
    # would stop every FIFO thread of the CPU, Zenoh's too, for 50 ms each second)
    spin, period_ns = (0.003 if fifo else 0.0), int(1e9 / rate_hz)
    from common import rt
    dec, enc = Codec.for_schema("SENSORS"), Codec.for_schema("JETS")
    jets = records.new(records.JETS)
    print(READY, flush=True)
    seq = 0
    try:
        while True:
            smp = transport.recv(sub, timeout_s=30.0, spin_s=spin)
            if smp is None:
                return
            out.received(smp)
            rec = dec.decode(smp.payload)
            if rec is None:
                continue
            if int(rec["k"]) < 0:
                print(f"SHM-RX {out.shm_rx}", flush=True)
                return
            jets["k"] = rec["k"]
            jets["t_release_ns"] = rec["t_ns"]
            out.put(enc.encode(jets, seq, time.monotonic_ns()))
            seq += 1
            if fifo:
                rt.sleep_until_ns(dec.last_t_pub_ns + period_ns - 100_000)
    finally:
        transport.close(sub, pub, ses)


# --------------------------------------------------------------------------- clients
def _start_echo(kind: str, port: int, placement: str = "default", rate_hz: float = 100.0,
                shm: bool = False, lowlatency: bool = True) -> subprocess.Popen:
    extra = (["--shm"] if shm else []) + ([] if lowlatency else ["--standard-transport"])
    p = subprocess.Popen([sys.executable, "-m", "ellipsled.bench.latency", "--echo", kind, "--port", str(port),
                          "--placement", placement, "--rate", f"{rate_hz:g}", *extra],
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
    """An echo process ends by itself once its client is done; one that has not after 2 s is stopped."""
    try:
        p.wait(timeout=2.0)
    except subprocess.TimeoutExpired:
        stop_process(p, 5.0)


def udp_roundtrip(n: int, rate_hz: float, placement: str = "default", samples: bool = False) -> dict:
    from interfaces.transport import free_port
    port = free_port()
    p = _start_echo("udp", port, placement)
    _place(placement, CLIENT_ROLE)
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
    return _stats(rtt, lost, samples)


def zenoh_roundtrip(n: int, rate_hz: float, placement: str = "default", shm: bool = False,
                    lowlatency: bool = True, samples: bool = False) -> dict:
    """The Zenoh + codec round trip; ``shm``: both ends put their frames from shared-memory
    buffers (the result then counts the frames each end received through shared memory:
    ``shm_rx_client``, ``shm_rx_echo``); ``lowlatency``: the transport both ends use;
    ``samples``: every round trip [us] in ``samples_us``."""
    from interfaces import records, transport
    from interfaces.codec import Codec
    from interfaces.keys import keys
    port = transport.free_port()
    p = _start_echo("zenoh", port, placement, rate_hz, shm, lowlatency)
    fifo = _place(placement, CLIENT_ROLE)
    spin = 0.003 if fifo else 0.0        # the plant node spins 3 ms for its command under SCHED_FIFO
    k = keys("bench-latency")
    ses = pub = sub = None
    rtt, lost, echo_shm_rx = [], 0, None
    try:
        ses = transport.open_session("fsw", [], [transport.loopback(port)], lowlatency=lowlatency)
        sub = transport.subscriber(ses, k.jets)
        pub = transport.publisher(ses, k.sensors)
        out = _Putter(pub, shm)
        _raise_zenoh_threads(fifo, CLIENT_ROLE)
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
            out.put(enc.encode(rec, i, time.monotonic_ns()))
            while True:
                smp = transport.recv(sub, timeout_s=1.0, spin_s=spin)
                if smp is None:
                    lost += 1
                    if p.poll() is not None or lost > 20:
                        raise RuntimeError(f"zenoh echo not answering (exit code {p.poll()}, {lost} lost)")
                    break
                out.received(smp)
                back = dec.decode(smp.payload)
                if back is not None and int(back["k"]) == i:
                    if i >= 50:
                        rtt.append(time.perf_counter_ns() - t0)
                    break
        rec["k"] = -1
        out.put(enc.encode(rec, n + 60, 0))
        try:
            tail, _ = p.communicate(timeout=5.0)
            echo_shm_rx = int(tail.split("SHM-RX")[-1].split()[0]) if "SHM-RX" in tail else None
        except (subprocess.TimeoutExpired, ValueError, IndexError):
            pass
    finally:
        transport.close(sub, pub, ses)
        _stop(p)
    st = _stats(rtt, lost, samples)
    st.update(shm=shm, lowlatency=lowlatency, shm_rx_client=out.shm_rx, shm_rx_echo=echo_shm_rx)
    return st


VARIANTS = (("low-latency, bytes", True, False), ("low-latency, shared memory", True, True),
            ("standard, bytes", False, False), ("standard, shared memory", False, True))


def variants(n: int, rate_hz: float, rounds: int = 2) -> dict:
    """Each payload/transport variant's round trip (default placement), the variants
    interleaved over ``rounds`` so that a change of the machine's load hits them alike."""
    res = {name: [] for name, _, _ in VARIANTS}
    for _ in range(rounds):
        for name, lowlat, shm in VARIANTS:
            res[name].append(zenoh_roundtrip(n, rate_hz, "default", shm=shm, lowlatency=lowlat))
    return res


ROUND_TRIPS = {"udp": udp_roundtrip, "zenoh": zenoh_roundtrip}     # each kind's measurement
KINDS = tuple(ROUND_TRIPS)


def _in_child(n: int, rate_hz: float, placement: str, kinds=KINDS, samples: bool = False) -> dict:
    """The round trips ``kinds`` measured by a child client (its scheduling changes stay there);
    ``samples``: each with every round trip [us]."""
    cmd = [sys.executable, "-m", "ellipsled.bench.latency", "--client", "--placement", placement,
           "--n", str(n), "--rate", f"{rate_hz:g}", "--kinds", ",".join(kinds)] + (["--samples"] if samples else [])
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = p.communicate(timeout=60.0 + 3.0 * len(kinds) * n / rate_hz)
    except subprocess.TimeoutExpired:
        _stop(p)
        raise RuntimeError(f"latency client ({placement}) timed out") from None
    if p.returncode != 0:
        raise RuntimeError(f"latency client ({placement}) exit {p.returncode}: {err.strip()[-400:]}")
    import json
    return json.loads(out)


def round_trips(n: int, rate_hz: float, placement: str, kinds=KINDS, samples: bool = False) -> dict:
    return {kind: ROUND_TRIPS[kind](n, rate_hz, placement, samples=samples) for kind in kinds}


def sil_floor(seconds: float, rate_hz: float) -> dict:
    """The Zenoh + codec round trip with the SIL's placement paced at ``rate_hz`` for
    ``seconds``, every round trip kept (``samples_us``): one part of the floor the real-time
    SIL's sensor-to-actuator latency is judged against (ellipsled/bench/sil.py measures it
    on both sides of the run it judges). The idle time between round trips (caches cooling,
    cores sleeping) is part of what each leg costs, as between the SIL's frames."""
    return _in_child(max(int(seconds * rate_hz), 1), rate_hz, "sil", kinds=("zenoh",), samples=True)["zenoh"]


def run(quick: bool) -> dict:
    n, rate = (1000, 100.0) if quick else (6000, 100.0)
    d = round_trips(n, rate, "default")
    udp, zen = d["udp"], d["zenoh"]
    res = {"figure": "round trip between two processes on 127.0.0.1 [us], paced at %g Hz" % rate,
           "round_trips": n, "rate_hz": rate,
           "udp_p50_us": udp["p50_us"], "udp_p99_us": udp["p99_us"], "udp_max_us": udp["max_us"],
           "udp_lost": udp["lost"],
           "zenoh_p50_us": zen["p50_us"], "zenoh_p99_us": zen["p99_us"], "zenoh_max_us": zen["max_us"],
           "zenoh_lost": zen["lost"],
           "zenoh_over_udp_p99": (zen["p99_us"] / udp["p99_us"]) if zen["p99_us"] and udp["p99_us"] else None}
    try:
        sil = _in_child(n, rate, "sil")
        for kind in ("udp", "zenoh"):
            for q in ("p50_us", "p99_us", "max_us", "lost"):
                res[f"sil_{kind}_{q}"] = sil[kind][q]
        res["sil_placement"] = sil.get("placement")
    except Exception as e:
        for kind in ("udp", "zenoh"):
            res[f"sil_{kind}_p99_us"] = None
            res[f"sil_{kind}_p99_us_reason"] = f"{type(e).__name__}: {e}"
    return res


def rows(res: dict) -> list[Row]:
    lat = res.get("latency") or {}
    if not lat:
        return []
    R = [row("Zenoh + codec round trip p50 / p99 [us] (2 processes)",
             f"{fmt(lat.get('zenoh_p50_us'))} / {fmt(lat.get('zenoh_p99_us'))}",
             f"UDP {fmt(lat.get('udp_p50_us'))} / {fmt(lat.get('udp_p99_us'))}",
             f"{fmt(ratio(lat.get('zenoh_p99_us'), lat.get('udp_p99_us')))}x (p99)", "", NO_TARGET)]
    if lat.get("sil_zenoh_p99_us") is not None or lat.get("sil_udp_p99_us") is not None:
        R.append(row("Zenoh + codec round trip, SIL placement (FIFO, a CPU each) p50 / p99 [us]",
                     f"{fmt(lat.get('sil_zenoh_p50_us'))} / {fmt(lat.get('sil_zenoh_p99_us'))}",
                     f"UDP {fmt(lat.get('sil_udp_p50_us'))} / {fmt(lat.get('sil_udp_p99_us'))}",
                     f"{fmt(ratio(lat.get('sil_zenoh_p99_us'), lat.get('sil_udp_p99_us')))}x (p99)", "", NO_TARGET))
    return R


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--echo", choices=("udp", "zenoh"))
    ap.add_argument("--port", type=argtypes.udp_port, default=0)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--placement", choices=("default", "sil"), default="default")
    ap.add_argument("--client", action="store_true", help="measure the round trips (--kinds), print JSON")
    ap.add_argument("--kinds", type=argtypes.choice_list(KINDS), default=",".join(KINDS),
                    help="(client) the round trips to measure, comma-separated")
    ap.add_argument("--samples", action="store_true", help="(client) every round trip [us] in the JSON")
    ap.add_argument("--shm", action="store_true", help="(echo) put frames from Zenoh shared memory")
    ap.add_argument("--standard-transport", action="store_true", help="(echo) Zenoh's standard transport")
    ap.add_argument("--variants", action="store_true",
                    help="the Zenoh round trip with bytes vs shared-memory payloads, low-latency vs standard transport")
    ap.add_argument("--n", type=argtypes.int_range(1, 10_000_000), default=1000)
    ap.add_argument("--rate", type=argtypes.float_range(0.0, 1e6, lo_open=True), default=100.0)
    a = ap.parse_args(argv)
    if a.echo == "udp":
        _echo_udp(a.port, a.placement)
    elif a.echo == "zenoh":
        _echo_zenoh(a.port, a.placement, a.rate, a.shm, not a.standard_transport)
    elif a.variants:
        import json
        res = variants(a.n, a.rate)
        print(json.dumps(res, indent=2))
        print("| variant | p50 [us] per round | p99 [us] per round | frames received via shared memory (client / echo) |")
        print("|---|---|---|---|")
        for name, runs in res.items():
            p50 = " / ".join(fmt(r["p50_us"]) for r in runs)
            p99 = " / ".join(fmt(r["p99_us"]) for r in runs)
            via = " / ".join(f"{r['shm_rx_client']}, {r['shm_rx_echo']}" for r in runs)
            print(f"| {name} | {p50} | {p99} | {via} |")
    elif a.client:
        import json
        from common import rt
        out = round_trips(a.n, a.rate, a.placement, a.kinds, a.samples)
        try:
            fifo = os.sched_getscheduler(0) == os.SCHED_FIFO
        except OSError:
            fifo = False
        out["placement"] = {"name": a.placement, "sched_fifo": fifo, "client_cpus": sorted(os.sched_getaffinity(0)),
                            "timer_slack_ns": rt.get_timer_slack_ns()}
        print(json.dumps(out))
    else:
        import json
        print(json.dumps(run(a.quick), indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
