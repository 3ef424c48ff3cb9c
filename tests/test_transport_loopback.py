"""interfaces/transport.py + codec over real Zenoh sessions in two processes on loopback."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from interfaces import keys as K
from interfaces import records as R
from interfaces import transport as T
from interfaces.codec import Codec

ROOT = Path(__file__).resolve().parents[1]


def _echo_main(port: int, prefix: str) -> None:
    """Child process: the 'fsw' end. Listens, answers each SENSORS frame k with JETS k
    (u = jets whose chamber pressure > 0.5), exits on k < 0, prints its codec counters."""
    k = K.keys(prefix)
    s = T.open_session("fsw", [T.loopback(port)], None)
    token = T.declare_alive(s, k, "fsw")
    sub, pub = T.subscriber(s, k.sensors), T.publisher(s, k.jets)
    dec, enc = Codec.for_schema("SENSORS"), Codec.for_schema("JETS")
    jets = R.new(R.JETS)
    seq = 0
    try:
        while True:
            smp = T.recv(sub, 20.0)
            if smp is None:
                break
            rec = dec.decode(smp.payload)
            if rec is None:
                continue
            if rec["k"] < 0:
                break
            jets["k"] = rec["k"]
            jets["t_release_ns"] = rec["t_ns"]
            jets["u"] = rec["chamber"] > 0.5
            seq += 1
            jets["t_publish_ns"] = time.monotonic_ns()
            pub.put(enc.encode(jets, seq, jets["t_publish_ns"]))
    finally:
        T.close(token, sub, pub, s)
    print(json.dumps({"rejects": {r: n for r, n in dec.rejects.items() if n},
                      "decoded": dec.decoded}), flush=True)


def _spawn_echo(port: int, prefix: str) -> subprocess.Popen:
    code = f"from tests.test_transport_loopback import _echo_main; _echo_main({port}, {prefix!r})"
    return subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _reap(p: subprocess.Popen) -> tuple[str, str]:
    try:
        return p.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        p.kill()                       # only the child we started, by its pid
        return p.communicate(timeout=5)


@pytest.mark.slow
def test_two_processes_exchange_sensors_and_jets_over_loopback():
    port, prefix = T.free_port(), f"test-{os.getpid()}"
    k = K.keys(prefix)
    child = _spawn_echo(port, prefix)
    s = pub = sub = None
    try:
        s = T.open_session("sim", None, [T.loopback(port)])
        assert T.wait_for_alive(s, k.alive_fsw, 15.0), "fsw liveliness token never seen"
        pub, sub = T.publisher(s, k.sensors), T.subscriber(s, k.jets)
        assert T.wait_for_subscriber(pub, 15.0)
        enc, dec = Codec.for_schema("SENSORS"), Codec.for_schema("JETS")
        rec = R.new(R.SENSORS)
        rng = np.random.default_rng(3)
        n, rtt_ns, seq = 300, [], 0
        for i in range(n):
            if i == 100:
                pub.put(b"\x00garbage that is not a frame")      # must be rejected, not crash
            rec["k"], rec["t_ns"] = i, 20_000_000 * i
            rec["chamber"] = rng.uniform(0.0, 1.0, R.N_JETS)
            seq += 1
            t0 = time.perf_counter_ns()
            pub.put(enc.encode(rec, seq, t0))
            got = None
            while got is None:
                smp = T.recv(sub, 5.0)
                assert smp is not None, f"no answer to k={i}"
                got = dec.decode(smp.payload)
            rtt_ns.append(time.perf_counter_ns() - t0)
            assert int(got["k"]) == i and int(got["t_release_ns"]) == 20_000_000 * i
            np.testing.assert_array_equal(got["u"], rec["chamber"] > 0.5)
        rec["k"] = -1
        seq += 1
        pub.put(enc.encode(rec, seq, 0))
        assert dec.rejected() == 0 and dec.guard.lost == 0
    finally:
        T.close(pub, sub, s)
        out, err = _reap(child)
    assert child.returncode == 0, err[-2000:]
    report = json.loads(out.strip().splitlines()[-1])
    assert report["decoded"] == n + 1
    assert report["rejects"] == {"size": 1}
    a = np.array(rtt_ns[20:]) / 1e3
    print(f"\nzenoh loopback round trip (SENSORS -> JETS, 2 processes): "
          f"p50 {np.percentile(a, 50):.0f} us, p99 {np.percentile(a, 99):.0f} us, n={a.size}")
    assert np.percentile(a, 50) < 50_000          # sanity only: figures go to the benchmark


def test_recv_times_out_and_stays_interruptible():
    s = T.open_session("console", None, None)
    sub = T.subscriber(s, "ellipsled/test-nobody/fsw/jets")
    try:
        t0 = time.monotonic()
        assert T.recv(sub, 0.05) is None
        assert 0.05 <= time.monotonic() - t0 < 2.0
        assert T.latest(sub) == (None, 0)

        class Interrupted(Exception):
            pass

        def on_alarm(signum, frame):
            raise Interrupted
        old = signal.signal(signal.SIGALRM, on_alarm)
        try:
            signal.setitimer(signal.ITIMER_REAL, 0.1)
            t0 = time.monotonic()
            with pytest.raises(Interrupted):
                T.recv(sub, 30.0)               # a blocking zenoh recv() would ignore this
            assert time.monotonic() - t0 < 5.0
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)
    finally:
        T.close(sub, s)
        T.close(sub, s)                          # idempotent
    assert s.is_closed()


def test_latest_returns_the_newest_and_counts_the_skipped():
    port = T.free_port()
    a = T.open_session("sim", [T.loopback(port)], None)
    b = T.open_session("fsw", None, [T.loopback(port)])
    pub = sub = None
    try:
        sub = T.subscriber(b, "ellipsled/t/sim/sensors", newest_only=True, capacity=4)
        pub = T.publisher(a, "ellipsled/t/sim/sensors")
        assert T.wait_for_subscriber(pub, 15.0)
        for i in range(10):
            pub.put(bytes([i]))
        time.sleep(1.0)                             # all ten delivered: the ring keeps 6..9
        newest, skipped = T.latest(sub)
        assert newest is not None and newest.payload.to_bytes() == b"\x09"
        assert skipped == 3
        assert T.latest(sub) == (None, 0)
    finally:
        T.close(pub, sub, a, b)


def test_default_config_is_peer_without_scouting_and_config_file_wins(tmp_path):
    cfg = T.default_config("sim", ["tcp/127.0.0.1:1"], None, lowlatency=True)
    assert cfg["mode"] == "peer"
    assert cfg["scouting"]["multicast"]["enabled"] is False
    assert cfg["scouting"]["gossip"]["enabled"] is False
    assert cfg["listen"]["endpoints"] == ["tcp/127.0.0.1:1"] and cfg["connect"]["endpoints"] == []
    assert cfg["transport"]["unicast"] == {"lowlatency": True, "qos": {"enabled": False}}
    # a user file (JSON5, zenoh's format) is the configuration; two sessions talk through it
    port = T.free_port()
    f = tmp_path / "zenoh.json5"
    f.write_text("{ mode: 'peer', scouting: { multicast: { enabled: false } },\n"
                 f"  listen: {{ endpoints: ['tcp/127.0.0.1:{port}'] }} }}  // a comment\n")
    a = T.open_session("sim", None, None, config_file=str(f))
    b = T.open_session("fsw", None, [T.loopback(port)])
    try:
        pub = T.publisher(a, "ellipsled/cfg/x")
        assert T.wait_for_subscriber(pub, 0.05) is False     # nobody yet
        sub = T.subscriber(b, "ellipsled/cfg/x")
        assert T.wait_for_subscriber(pub, 15.0)
        pub.put(b"via file")
        smp = T.recv(sub, 5.0)
        assert smp is not None and smp.payload.to_bytes() == b"via file"
    finally:
        T.close(a, b)
    with pytest.raises(FileNotFoundError):
        T.open_session("sim", None, None, config_file=str(tmp_path / "missing.json5"))
    with pytest.raises(ValueError):
        T.open_session("", None, None)
    with pytest.raises(ValueError):
        T.open_session("sim", "tcp/127.0.0.1:1", None)


FROZEN_SUB = r"""
import sys, time
from interfaces import transport as T
s = T.open_session("bridge", None, [sys.argv[1]], lowlatency=sys.argv[2] == "True")
sub = T.subscriber(s, "ellipsled/frozen/state", capacity=16)
print("ready", flush=True)
time.sleep(600)
"""


def test_a_frozen_subscriber_holds_a_real_time_publisher_at_most_for_the_lease():
    """A stopped viewer or peer (SIGSTOP, a debugger). The standard transport with DROP never
    blocks, at any rate. The low-latency transport writes to the socket in put() itself: once
    the frozen peer's socket buffers are full, put() blocks until Zenoh's lease drops the peer
    (how much the buffers absorb is the kernel's: ~20 MB on one machine, nothing on another),
    so at 200 samples/s of 600 B no put blocks longer than the lease, the peer is dropped,
    and after the drop every put returns at once."""
    lease_s = T.LEASE_MS / 1000.0
    for lowlatency, rate, n in ((True, 200.0, 2_600), (False, None, 40_000)):
        port = T.free_port()
        s = T.open_session("fsw", [T.loopback(port)], None, lowlatency=lowlatency)
        child = subprocess.Popen([sys.executable, "-c", FROZEN_SUB, T.loopback(port), str(lowlatency)],
                                 cwd=ROOT, stdout=subprocess.PIPE, text=True)
        pub = None
        try:
            assert child.stdout.readline().strip() == "ready"
            pub = T.publisher(s, "ellipsled/frozen/state", express=False, drop=True)
            assert T.wait_for_subscriber(pub, 15.0)
            os.kill(child.pid, signal.SIGSTOP)
            payload = bytes(600)
            t0 = time.monotonic()
            worst = 0.0
            for i in range(n):
                a = time.monotonic()
                pub.put(payload)
                worst = max(worst, time.monotonic() - a)
                if rate:
                    time.sleep(max(0.0, t0 + (i + 1) / rate - time.monotonic()))
            if not lowlatency:
                assert worst < 0.5, worst
                continue
            assert worst < lease_s + 2.0, worst       # the lease bounds the stall
            assert time.monotonic() - t0 > lease_s + 2.0
            assert not pub.matching_status.matching    # the lease has dropped the peer
            after = 0.0
            for _ in range(400):                       # dropped: nothing left to block on
                a = time.monotonic()
                pub.put(payload)
                after = max(after, time.monotonic() - a)
            assert after < 0.5, after
        finally:
            child.kill()                          # SIGKILL works on a stopped process
            child.wait(10)
            T.close(pub, s)
