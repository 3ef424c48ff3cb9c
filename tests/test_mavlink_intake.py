"""The vehicle's bounded datagram intake: what cannot be a message for the vehicle is refused
before any CRC or signature work (and counted under the link's rejection reasons), genuine
frames get through, one call never exceeds its datagram and time budget, and datagrams the
kernel drops on a full queue are counted. Frames are built with the MAVLink signing rules
(Signer) and pymavlink's own packer, independent of the intake."""
from __future__ import annotations

import socket
import time

import pytest
from pymavlink.dialects.v10 import common as v10

from interfaces.mavlink import dialect as mav
from interfaces.mavlink.intake import DatagramIntake
from interfaces.mavlink.signing.keys import SigningKey
from interfaces.mavlink.signing.link import SignedLink
from interfaces.mavlink.signing.sign import Signer
from interfaces.mavlink.signing.verify import Reject
from tests.rig import PricedReads

ACCEPT = {mav.MAVLINK_MSG_ID_HEARTBEAT, mav.MAVLINK_MSG_ID_COMMAND_LONG, mav.MAVLINK_MSG_ID_PARAM_SET}
ARM = mav.MAVLink_command_long_message(1, 1, mav.ELLIPSLED_CMD_ARM_JETS, 0, 1, 0, 0, 0, 0, 0, 0)


class Bench:
    def __init__(self, **kw):
        self.key = SigningKey.generate()
        self.link = SignedLink(self.key, system_id=1, component_id=1)
        self.rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.rx.bind(("127.0.0.1", 0))
        self.rx.setblocking(False)
        self.tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        kw.setdefault("budget_us", 1e6)          # budgets are tested on their own, below
        self.intake = DatagramIntake(self.rx, self.link, accept=ACCEPT, **kw)
        self.got: list = []
        self.ground = Signer(self.key, system_id=255, component_id=190, link_id=1)

    def send(self, data: bytes) -> None:
        self.tx.sendto(data, self.rx.getsockname())

    def poll(self) -> int:
        time.sleep(0.01)                       # loopback delivery
        return self.intake.poll(lambda msg, addr: self.got.append(msg))

    def close(self):
        self.rx.close()
        self.tx.close()


def stepping_clock(step_ns: int):
    """A clock that advances ``step_ns`` at each reading (the intake's budget, made exact)."""
    t = [0]

    def clock_ns():
        t[0] += step_ns
        return t[0]
    return clock_ns


@pytest.fixture
def b():
    x = Bench()
    yield x
    x.close()


def test_genuine_single_and_multi_frame_datagrams_get_through(b):
    b.send(b.ground.pack(ARM))
    b.send(b.ground.pack(ARM) + b.ground.pack(ARM))
    assert b.poll() == 2
    assert [m.get_type() for m in b.got] == ["COMMAND_LONG"] * 3 and all(m.get_signed() for m in b.got)
    assert b.intake.stats["refused_early"] == 0


def test_what_cannot_be_for_the_vehicle_is_refused_before_crc_and_signature(b):
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    forged = Signer(SigningKey.generate(), system_id=255, component_id=190)
    genuine_telemetry = b.ground.pack(mav.MAVLink_attitude_message(0, 0, 0, 0, 0, 0, 0))
    cases = [
        (bytes(60_000), Reject.MALFORMED),                       # oversized
        (b"\x00" * 40, Reject.GARBAGE),                          # not MAVLink 2
        (ARM.pack(mav.MAVLink(None, srcSystem=255, srcComponent=190))[:20], Reject.TRUNCATED),
        (genuine_telemetry, Reject.UNKNOWN_MESSAGE),             # signed, but not a message the vehicle takes
        (ARM.pack(unsigned), Reject.UNSIGNED),
    ]
    for data, _ in cases:
        b.send(data)
    assert b.poll() == len(cases)
    counts = b.link.counts
    for _, reason in cases:
        assert counts[reason] >= 1, reason
    assert counts[Reject.BAD_CRC] == 0 and counts[Reject.BAD_SIGNATURE] == 0     # no CRC/HMAC work was done
    assert b.intake.stats["refused_early"] == len(cases) and not b.got
    # a forged signature is the one check that needs the HMAC: refused, nothing handled
    b.send(forged.pack(ARM))
    b.poll()
    assert counts[Reject.BAD_SIGNATURE] == 1 and not b.got
    # an unsigned HEARTBEAT is allowed through (it authorises nothing)
    b.send(mav.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(unsigned))
    b.poll()
    assert [m.get_type() for m in b.got] == ["HEARTBEAT"]


def test_one_call_reads_at_most_its_datagram_budget():
    b = Bench(max_datagrams=50)
    try:
        for _ in range(200):
            b.send(b"\x00" * 30)
        assert b.poll() == 50 and b.intake.stats["budget_hits"] == 1
        assert b.poll() == 50                   # the rest waits for the next call
    finally:
        b.close()


def test_one_call_stops_when_its_time_budget_is_spent():
    b = Bench(budget_us=1000.0, clock_ns=stepping_clock(300_000))
    try:
        for _ in range(100):
            b.send(b"\x00" * 30)
        n = b.poll()
        assert 1 <= n <= 4 and b.intake.stats["budget_hits"] == 1
    finally:
        b.close()


def test_a_calls_own_budget_caps_the_configured_one_and_none_left_reads_nothing():
    b = Bench(budget_us=1e6, clock_ns=stepping_clock(300_000))
    try:
        for _ in range(100):
            b.send(b"\x00" * 30)
        time.sleep(0.01)
        assert b.intake.poll(lambda m, a: None, budget_ns=0) == 0          # the caller's slack is gone
        n = b.intake.poll(lambda m, a: None, budget_ns=1_000_000)
        assert 1 <= n <= 4 and b.intake.stats["budget_hits"] == 2
        assert b.intake.poll(lambda m, a: None) == 100 - n                 # the configured budget: all
    finally:
        b.close()


def test_a_full_queue_is_bounded_by_the_receive_buffer_and_its_drops_are_counted():
    b = Bench(max_datagrams=64)
    try:
        assert b.intake.rcvbuf_bytes <= 4 * 64 * 1024          # sized for about one call's budget
        sent = 3000
        for _ in range(sent):
            b.send(b"\x00" * 30)
        time.sleep(0.05)
        read = 0
        while True:
            n = b.intake.poll(lambda m, a: None)
            read += n
            if n == 0:
                break
        st = b.intake.stats
        assert read < sent and st["kernel_drops"] > 0, (read, st)
        if b.intake.kernel_counts:
            assert read + st["kernel_drops"] == sent, (read, st)
    finally:
        b.close()


def test_bad_budgets_are_refused():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    link = SignedLink(SigningKey.generate(), system_id=1, component_id=1)
    try:
        for kw in ({"max_datagrams": 0}, {"budget_us": 0.0}, {"max_datagram_bytes": 100}):
            with pytest.raises(ValueError):
                DatagramIntake(s, link, accept=ACCEPT, **kw)
    finally:
        s.close()


def test_a_calls_alike_refusals_are_counted_each_and_reported_once():
    seen = []
    b = Bench()
    try:
        b.link.verifier.on_reject = seen.append
        for _ in range(3):
            b.send(b"\x00" * 30)
        assert b.poll() == 3
        assert b.link.counts[Reject.GARBAGE] == 3 and len(seen) == 1
        assert seen[0].text() == "link rejected 3x garbage"
    finally:
        b.close()


def test_every_frame_of_a_datagram_is_judged_on_its_own(b):
    """Beside a genuine command in one datagram: a signed message the vehicle does not take,
    a MAVLink 1 heartbeat (which may be unsigned, but not MAVLink 1), a frame with the
    receiver's own system id; each refused as it would be alone, the command passed on."""
    b.intake.own_sysid = 1
    v1 = v10.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3).pack(v10.MAVLink(None, srcSystem=255, srcComponent=190))
    telemetry = b.ground.pack(mav.MAVLink_attitude_message(0, 0, 0, 0, 0, 0, 0))
    own = Signer(b.key, system_id=1, component_id=1).pack(mav.MAVLink_heartbeat_message(0, 8, 0, 0, 4, 3))
    b.send(b.ground.pack(ARM) + telemetry + v1)      # a MAVLink 1 frame ends the datagram
    b.send(own + b.ground.pack(ARM))
    assert b.poll() == 2
    assert [m.get_type() for m in b.got] == ["COMMAND_LONG", "COMMAND_LONG"]
    c = b.link.counts
    assert (c[Reject.GARBAGE], c[Reject.UNKNOWN_MESSAGE], c[Reject.OWN_SYSTEM]) == (1, 1, 1)
    assert sum(b.intake.refused_by_sender.values()) == 3


def test_the_time_budget_is_checked_before_each_frame_and_what_it_leaves_waits():
    b = Bench(budget_us=1000.0, clock_ns=stepping_clock(300_000))
    try:
        b.send(b"".join(b.ground.pack(ARM) for _ in range(4)))
        b.poll()
        first = len(b.got)
        assert first < 4 and b.intake.stats["frames_deferred"] == 1
        while len(b.got) < 4:
            n = len(b.got)
            b.intake.poll(lambda msg, addr: b.got.append(msg))
            assert len(b.got) > n
        assert all(m.get_type() == "COMMAND_LONG" for m in b.got) and not b.link.counts[Reject.REPLAY]
    finally:
        b.close()


class PricedHandle:
    """A clock that moves only while a verified frame is handled: each frame costs the next
    price of ``prices`` (cycled), so what a call spends is exact on any host."""

    def __init__(self, prices_ns):
        self.t = 0
        self.prices = list(prices_ns)
        self.n = 0

    def clock_ns(self) -> int:
        return self.t

    def __call__(self, msg, addr) -> None:
        self.t += self.prices[self.n % len(self.prices)]
        self.n += 1


def _priced_bench(prices_ns, budget_us: float = 1000.0):
    h = PricedHandle(prices_ns)
    return Bench(budget_us=budget_us, clock_ns=h.clock_ns), h


def _priced_polls(b, h, n: int) -> list[tuple[int, int]]:
    """n calls, each with a fresh command queued behind the ones left: (frames handled, ns spent) per call."""
    out = []
    for _ in range(n):
        n0, t0 = h.n, h.t
        b.intake.poll(h)
        out.append((h.n - n0, h.t - t0))
    return out


def test_a_frame_to_verify_is_begun_only_when_its_estimated_cost_is_left():
    """Frames costing 100 or 190 us in turn, a 1 ms budget: without an estimate (the first
    call) the last frame carries the call past its budget; once the costs are known no
    call exceeds it, and each still verifies as many frames as the estimate lets fit."""
    b, h = _priced_bench([100_000, 190_000])
    try:
        for _ in range(120):
            b.send(b.ground.pack(ARM))
        time.sleep(0.02)
        first, *rest = _priced_polls(b, h, 10)
        assert first[1] > 1_000_000                       # no estimate yet: over by the last frame
        assert all(ns <= 1_000_000 for _, ns in rest)      # the 0.9 quantile (190 us) bounds the last
        assert all(n >= 5 for n, _ in rest)                # ... and reading goes on: 810 us is begun
        assert b.intake.stats["frames_deferred"] == 9      # each later call: a frame not begun waits
    finally:
        b.close()


def test_one_slow_command_moves_neither_the_estimate_nor_the_reading():
    """A command that takes 40 ms (a reconfiguration) among 100 us ones: the calls after it
    read as many frames as before; frames all slow are capped at a quarter of the budget,
    so a call still verifies frames (the estimate never stops the intake)."""
    prices = [100_000] * 40
    prices[20] = 40_000_000
    b, h = _priced_bench(prices)
    try:
        for _ in range(120):
            b.send(b.ground.pack(ARM))
        time.sleep(0.02)
        polls = _priced_polls(b, h, 8)
        slow = next(i for i, (_, ns) in enumerate(polls) if ns >= 40_000_000)
        assert polls[slow + 1][0] == polls[1][0] >= 9       # the same frames a call after it
        assert b.intake.frame_estimate_ns(1_000_000) == 100_000
        b.intake.frame_ns.extend([40_000_000] * 32)           # every recent frame slow
        assert b.intake.frame_estimate_ns(1_000_000) == 250_000
        h.prices = [1_000]
        n, ns = _priced_polls(b, h, 1)[0]
        assert n >= 1 and ns <= 1_000_000
    finally:
        b.close()


def test_a_call_begins_its_first_frame_however_little_its_socket_read_left():
    """Frames costing 100 us, known to the estimate; a call of 120 us whose socket read takes
    110 us has 10 us left, less than a frame's estimate: it begins that frame all the same
    (the budget bounds what follows: the next datagram waits), and a call of no budget reads
    nothing; a call that only reads on (``least=False``) keeps to its budget alone."""
    b, h = _priced_bench([100_000])
    try:
        for _ in range(4):
            b.send(b.ground.pack(ARM))
        time.sleep(0.02)
        assert _priced_polls(b, h, 1)[0][0] == 4            # the estimate: 100 us a frame
        b.intake.sock = PricedReads(b.rx, h, 110_000)
        for _ in range(2):
            b.send(b.ground.pack(ARM))
        time.sleep(0.02)
        t0 = h.t
        assert b.intake.poll(h, 120_000) == 1 and h.n == 5  # read, begun and handled: one frame
        assert h.t - t0 == 110_000 + 100_000
        assert b.intake.poll(h, 0) == 0 and h.n == 5        # no budget: nothing read
        assert b.intake.poll(h, 1) == 1 and h.n == 6        # the next call: the next datagram
        b.send(b.ground.pack(ARM))
        time.sleep(0.02)
        assert b.intake.poll(h, 120_000, least=False) == 1 and h.n == 6   # read, not begun: it waits
        assert b.intake.poll(h, 1) == 0 and h.n == 7        # ... and is the next call's first
    finally:
        b.close()


def test_frames_a_call_left_are_begun_first_in_the_next_call_whatever_its_budget():
    """Three frames in one datagram, each costing 100 us, the clock moving 1 us at each
    reading besides, calls of 1 ns: each call begins one frame (the first of the datagram,
    then those left, in order), none is lost."""
    b, h = _priced_bench([100_000])
    priced = h.clock_ns

    def clock_ns():
        h.t += 1_000
        return priced()
    b.intake.clock_ns = clock_ns
    try:
        b.send(b"".join(b.ground.pack(mav.MAVLink_command_long_message(1, 1, mav.ELLIPSLED_CMD_ARM_JETS, 0, k,
                                                                        0, 0, 0, 0, 0, 0)) for k in range(3)))
        time.sleep(0.02)
        got = []
        for _ in range(3):
            b.intake.poll(lambda msg, addr: (h(msg, addr), got.append(msg.param1)), 1)
            assert len(got) == h.n
        assert got == [0.0, 1.0, 2.0] and b.intake.stats["frames_deferred"] == 2
        assert not b.link.counts[Reject.REPLAY]
    finally:
        b.close()


def test_waiting_says_whether_a_call_has_anything_to_take_up():
    """``waiting()``: False on an empty socket; True with a datagram at the socket, or with
    frames a spent budget left in the intake (the socket empty); False once all is read."""
    b = Bench(budget_us=1000.0, clock_ns=stepping_clock(300_000))
    try:
        assert not b.intake.waiting()
        b.send(b"".join(b.ground.pack(ARM) for _ in range(4)))
        time.sleep(0.01)                                  # loopback delivery
        assert b.intake.waiting()
        b.poll()
        assert b.intake.stats["frames_deferred"] == 1 and b.intake.waiting()    # the socket empty, frames kept
        while b.intake.waiting():
            b.intake.poll(lambda msg, addr: b.got.append(msg))
        assert len(b.got) == 4
    finally:
        b.close()
