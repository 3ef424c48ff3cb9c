"""Ground link security: commands must arrive signed with the vehicle key; unsigned,
wrongly signed, tampered and replayed commands are rejected (no ACK, no effect), counted
and reported as rate-limited WARNING events; an unsigned ground heartbeat is accepted; a
forged frame with a far-future timestamp does not lock out the genuine ground station;
random bytes and malformed frames on the port never crash the link and the FSW flies on.

Independent truth: frames are built here with pymavlink's own packer (unsigned) and the
MAVLink signing/CRC rules, not with the link under test.
"""
from __future__ import annotations

import logging
import random
import re
import socket
import time

import pytest

from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing.keys import SigningKey
from interfaces.mavlink.signing.sign import Signer
from interfaces.mavlink.signing.verify import Reject

from gse.commands import make_request
from tests.rig import ACCEPTED, Rig, flown

ARM_OFF = mav.MAVLink_command_long_message(1, 1, mav.ELLIPSLED_CMD_ARM_JETS, 0, 0, 0, 0, 0, 0, 0, 0)


@pytest.fixture
def rig(tmp_path):
    with flown(tmp_path, 3) as r:
        yield r


def send_raw(rig, data: bytes) -> None:
    rig.gcs.sock.sendto(data, rig.gl.address)


def settle(rig, s: float = 0.1) -> None:
    rig.exchange(lambda: False, s)


def link_events(rig):
    return [e for e in rig.fsw.events.history if e.source == "link" and e.code == "link_refused"]


def resign_crc(frame: bytearray, msgid: int) -> None:
    """Recompute the CRC of a MAVLink 2 frame after a payload edit (signature untouched)."""
    plen = frame[1]
    crc = mav.x25crc(bytes(frame[1:10 + plen]))
    crc.accumulate(bytes((mav.mavlink_map[msgid].crc_extra,)))
    frame[10 + plen] = crc.crc & 0xFF
    frame[11 + plen] = crc.crc >> 8


def test_unsigned_command_rejected_counted_and_reported(rig):
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    send_raw(rig, ARM_OFF.pack(unsigned))
    settle(rig)
    assert rig.fsw.driver.armed                       # no effect; answered DENIED, so the client stops retrying
    assert [a.result for a in rig.gcs.state.acks] == [mav.MAV_RESULT_DENIED]
    assert rig.gl.link.counts[Reject.UNSIGNED] == 1 and rig.gl.rejections == 1
    ev = link_events(rig)
    assert len(ev) == 1 and ev[0].severity == mav.MAV_SEVERITY_WARNING
    assert ev[0].text == "link rejected unsigned 255/190 msg 76"
    assert ev[0].text in rig.texts()                 # and it went to the ground as STATUSTEXT


def test_wrong_key_and_tampered_and_replayed_commands_rejected(rig):
    attacker = Signer(SigningKey.generate(), system_id=255, component_id=190, link_id=3)
    send_raw(rig, attacker.pack(ARM_OFF))

    genuine = Signer(rig.key, system_id=255, component_id=190, link_id=5)
    # tamper: flip param1 (arm flag) of a genuinely signed "disarm" into "arm" = 1.0 float
    tampered = bytearray(genuine.pack(ARM_OFF))
    tampered[10:14] = bytes.fromhex("0000803f")       # param1 = 1.0 (payload starts with param1)
    resign_crc(tampered, mav.MAVLINK_MSG_ID_COMMAND_LONG)
    send_raw(rig, bytes(tampered))
    settle(rig)
    assert rig.gl.link.counts[Reject.BAD_SIGNATURE] == 2
    assert rig.fsw.driver.armed and not rig.gcs.state.acks

    good = genuine.pack(ARM_OFF)
    send_raw(rig, good)
    assert rig.exchange(lambda: len(rig.gcs.state.acks) == 1)
    assert rig.gcs.state.acks[0].result == mav.MAV_RESULT_ACCEPTED and not rig.fsw.driver.armed
    rig.fsw.driver.arm(rig.fsw.t_s, True)
    send_raw(rig, good)                               # replay of the accepted frame
    settle(rig)
    assert rig.gl.link.counts[Reject.REPLAY] == 1
    assert len(rig.gcs.state.acks) == 1 and rig.fsw.driver.armed
    assert rig.gl.rejections == 3


def test_unsigned_ground_heartbeat_accepted(rig):
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    hb = mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
    send_raw(rig, hb.pack(unsigned))
    settle(rig)
    assert rig.gl.ground_heartbeat_t == rig.clock.t
    assert rig.gl.rejections == 0 and rig.gl.link.verifier.accepted_unsigned == 1


def test_forged_future_timestamp_does_not_lock_out_the_genuine_ground(rig):
    """The pymavlink 2.4.50 weakness: a forged frame (bad signature) on the ground's stream
    with a timestamp a day ahead; the genuine command right after must still be accepted."""
    now = time.time()
    forger = Signer(SigningKey.generate(), system_id=255, component_id=190, link_id=0,
                    clock=lambda: now + 86400.0)
    send_raw(rig, forger.pack(ARM_OFF))
    settle(rig)
    assert rig.gl.link.counts[Reject.BAD_SIGNATURE] == 1
    assert rig.command("arm", "off") == mav.MAV_RESULT_ACCEPTED      # rig.gcs: stream 255/190/0
    assert not rig.fsw.driver.armed


def test_rejection_events_are_rate_limited_but_every_rejection_is_counted(rig):
    rig.gl.refusal_event_interval_s = 1.0            # (default 60 s: test_groundlink_keyless.py)
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    for _ in range(30):
        send_raw(rig, ARM_OFF.pack(unsigned))
    settle(rig, 0.2)
    assert rig.gl.rejections == 30
    assert len(link_events(rig)) == 1                 # one per interval of FSW time
    rig.fly(60)                                       # 1.2 s of FSW time
    send_raw(rig, ARM_OFF.pack(unsigned))
    settle(rig)
    rig.fly(60)                                       # what the limit still holds is told
    ev = link_events(rig)
    # the 31 rejections are all accounted for in 3 events: the first, the held ones once the
    # interval is over ("+N suppressed"), the last
    told = sum(int((re.search(r"rejected (\d+)x", e.text) or [0, 1])[1])
               + sum(int(n) for n in re.findall(r"\(\+(\d+) suppressed\)", e.text)) for e in ev)
    assert len(ev) == 3 and told == 31, [e.text for e in ev]
    rig.gcs.state.latest.pop("SYS_STATUS", None)
    rig.clock.t += 1.0
    assert rig.exchange(lambda: "SYS_STATUS" in rig.gcs.state.latest)
    assert rig.gcs.state.latest["SYS_STATUS"].errors_comm == 31


def test_random_bytes_and_malformed_frames_never_crash_and_the_fsw_flies_on(rig, caplog):
    rng = random.Random(5)
    genuine = Signer(rig.key, system_id=255, component_id=190, link_id=9)
    good = genuine.pack(ARM_OFF)
    blobs = []
    for i in range(300):
        kind = i % 5
        if kind == 0:
            blobs.append(bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 600))))
        elif kind == 1:
            blobs.append(good[:rng.randint(1, len(good) - 1)])                  # truncated
        elif kind == 2:
            b = bytearray(good)
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)                    # bit flip
            blobs.append(bytes(b))
        elif kind == 3:
            blobs.append(b"\xfd" + bytes(rng.getrandbits(8) for _ in range(rng.randint(0, 300))))
        else:
            blobs.append(b"\xfe\xff" + b"\x00" * rng.randint(0, 20))            # v1 magic, long length
    cycles0 = rig.fsw.cycles
    with caplog.at_level(logging.ERROR):
        for i, blob in enumerate(blobs):
            send_raw(rig, blob)
            if i % 30 == 0:
                rig.fly(5, tick_every=1)
        rig.fly(20, tick_every=1)
        settle(rig, 0.2)
    assert not [r for r in caplog.records if "ground link" in r.getMessage()]
    assert rig.gl.stats["rx_datagrams"] >= 290         # (loopback UDP does not drop; margin anyway)
    assert rig.fsw.cycles == cycles0 + 10 * 5 + 20
    assert rig.fsw.driver.armed                         # none of the flipped frames got through
    assert rig.gl.rejections > 0 and not rig.gcs.state.acks
    assert rig.command("arm", "off") == mav.MAV_RESULT_ACCEPTED


def test_oversized_datagram_does_not_break_the_link(rig):
    big = b"\xfd" * 65000
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        s.sendto(big, rig.gl.address)
    finally:
        s.close()
    settle(rig)
    assert rig.command("ft", "off") == mav.MAV_RESULT_ACCEPTED


def test_a_tick_without_slack_before_the_cycle_deadline_leaves_datagrams_waiting(rig):
    """Real time: whatever ran late before the link in a cycle, the link does not receive
    past the cycle's deadline; what waits in the socket is read on a later tick."""
    for _ in range(5):
        send_raw(rig, b"\x00" * 40)
    time.sleep(0.02)
    before = dict(rig.gl.stats)
    rig.gl.tick(rig.frame, deadline_ns=time.monotonic_ns() - 1)           # the deadline is past
    assert rig.gl.stats["rx_deferred"] == before["rx_deferred"] + 1
    assert rig.gl.stats["rx_datagrams"] == before["rx_datagrams"]
    rig.gl.tick(rig.frame, deadline_ns=time.monotonic_ns() + 10_000_000_000)  # slack to spare
    assert rig.gl.stats["rx_datagrams"] == before["rx_datagrams"] + 5
    assert rig.gl.stats["rx_deferred"] == before["rx_deferred"] + 1


# --------------------------------------------------------------------------- who may steer the link

def attacker_socket():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.setblocking(False)
    return s


def vehicle_heartbeat():
    return mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GENERIC, mav.MAV_AUTOPILOT_GENERIC, 0, 0,
                                         mav.MAV_STATE_ACTIVE, 3)


def test_a_reflected_vehicle_signed_frame_is_refused_and_makes_no_peer(rig):
    """A frame the vehicle signed itself (sniffed off the link, or asked for by an unsigned
    read) sent back from another address, alone or behind another frame in one datagram:
    refused for its system id, no telemetry peer made."""
    evil = attacker_socket()
    try:
        unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        read = mav.MAVLink_param_request_list_message(1, 1).pack(unsigned)
        evil.sendto(rig.gl.link.pack(vehicle_heartbeat()), rig.gl.address)
        evil.sendto(read + rig.gl.link.pack(vehicle_heartbeat()), rig.gl.address)
        settle(rig)
        assert evil.getsockname() not in rig.gl.peers and rig.gl.stats["peers_added"] == 0
        assert rig.gl.link.counts[Reject.OWN_SYSTEM] == 2
        assert rig.gl.refused_by_sender[evil.getsockname()] == 2
    finally:
        evil.close()


def test_only_a_signed_command_class_frame_makes_a_telemetry_peer(rig):
    """A key holder's signed HEARTBEAT or read is not a request for telemetry; its signed
    command is."""
    other = Signer(rig.key, system_id=255, component_id=190, link_id=7)
    s = attacker_socket()
    try:
        hb = mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        s.sendto(other.pack(hb), rig.gl.address)
        s.sendto(other.pack(mav.MAVLink_param_request_read_message(1, 1, b"", 0)), rig.gl.address)
        settle(rig)
        assert rig.gl.link.verifier.accepted_signed == 2 and s.getsockname() not in rig.gl.peers
        s.sendto(other.pack(ARM_OFF), rig.gl.address)
        settle(rig)
        assert s.getsockname() in rig.gl.peers and rig.gl.stats["peers_added"] == 1
    finally:
        s.close()


def test_a_command_captured_in_one_run_is_refused_in_the_next_with_the_same_key(tmp_path):
    """Run A accepts a signed injection (signed 30 s ahead: within the clock tolerance, and
    after run B's start); run B, a new link with the same key file, refuses its replay."""
    a = Rig(tmp_path)
    inject = mav.MAVLink_command_long_message(1, 1, mav.MAV_CMD_INJECT_FAILURE, 0, mav.FAILURE_UNIT_SYSTEM_MOTOR,
                                              mav.FAILURE_TYPE_OFF, 18, 0, 0, 0, 0)
    ground = Signer(a.key, system_id=255, component_id=190, link_id=4, clock=lambda: time.time() + 30.0)
    captured = ground.pack(inject)
    try:
        a.fly(3)
        send_raw(a, captured)
        assert a.exchange(lambda: len(a.gcs.state.acks) == 1)
        assert a.injected == [(18, "failed_off", 1.0)]
    finally:
        a.close()
    b = Rig(tmp_path, key=a.key)
    try:
        b.fly(3)
        send_raw(b, captured)
        settle(b)
        assert b.injected == [] and not b.gcs.state.acks
        assert b.gl.link.counts[Reject.REPLAY] == 1
    finally:
        b.close()


def test_unknown_id_reads_are_counted_per_sender_and_told_in_one_throttled_event(rig):
    evil = attacker_socket()
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    n = 100
    try:
        for i in range(n):
            evil.sendto(mav.MAVLink_param_request_read_message(1, 1, b"NO_SUCH_%d" % i, -1).pack(unsigned),
                        rig.gl.address)
        assert rig.exchange(lambda: rig.gl.stats["rx_datagrams"] >= n)
        link_ev = [e for e in rig.fsw.events.history if e.source == "link"]
        assert len(link_ev) <= 2, [e.text for e in link_ev]          # one per kind, not one per request
        assert rig.gl.refused_by_sender[evil.getsockname()] == n
        assert rig.gl.stats["reads_unknown"] + rig.gl.stats["reads_limited"] == n
        rig.fly(3100)                                               # 62 s: the held ones are told
        told = [e.text for e in rig.fsw.events.history if e.code == "link_refused"]
        total = sum(1 + sum(int(k) for k in re.findall(r"\(\+(\d+) suppressed\)", t)) for t in told)
        assert len(told) == 2 and total == n, told
    finally:
        evil.close()


def test_events_keep_their_share_of_the_downlink_whatever_is_requested(rig):
    from fsw.groundlink.link import EVENT_SHARE
    rig.gl.max_tx_per_tick = EVENT_SHARE + 4
    rig.gl.tick(rig.frame)
    sent = []
    send = rig.gl._send
    rig.gl._send = lambda msg, *a, **kw: (sent.append(msg.get_type()), send(msg, *a, **kw))
    rig.gcs.param_request_list()                    # 63 parameters asked for
    assert rig.exchange(lambda: "PARAM_VALUE" in sent)
    sent.clear()
    for i in range(40):
        rig.fsw.events.emit(rig.fsw.t_s, mav.MAV_SEVERITY_CRITICAL, "test", f"fdir{i}", f"FDIR EVENT {i}")
    rig.gl.tick(rig.frame)
    assert sent.count("STATUSTEXT") >= EVENT_SHARE and sent.count("PARAM_VALUE") <= 4, sent


def test_text_from_the_link_reaches_events_with_control_characters_escaped(rig):
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    send_raw(rig, mav.MAVLink_param_request_read_message(1, 1, b"\x1b[2J\x07X", -1).pack(unsigned))
    settle(rig)
    texts = [e.text for e in rig.fsw.events.history if e.source == "link" and "UNKNOWN" in e.text]
    assert texts and all(c.isprintable() for t in texts for c in t) and "\\x1b[2J\\x07X" in texts[0], texts


def test_the_bench_flood_mix_changes_nothing_and_events_still_go_out_each_tick(rig):
    """The benchmark's hostile mix (ellipsled/bench/flood.py: random, malformed, unsigned,
    forged, multi-frame, MAVLink 1, unsigned reads, the vehicle's own signed frames sent
    back), 1,000 datagrams from one socket: no command or parameter takes effect, no peer
    is made, and an FDIR event emitted meanwhile goes to the ground in the tick after it."""
    from ellipsled.bench.flood import Flood
    fl = Flood(3, reflect=[rig.gl.link.pack(vehicle_heartbeat())])
    evil = attacker_socket()
    params0 = dict(rig.fsw.params)
    sent = []
    send = rig.gl._send
    rig.gl._send = lambda msg, *a, **kw: (sent.append(msg), send(msg, *a, **kw))
    kinds = set()
    try:
        for burst in range(10):
            for _ in range(100):
                kind, data = fl.next()
                kinds.add(kind)
                evil.sendto(data, rig.gl.address)
            while True:                                  # what the vehicle answered: to reflect
                try:
                    fl.take(evil.recv(65536))
                except BlockingIOError:
                    break
            sent.clear()
            rig.fsw.events.emit(rig.fsw.t_s, mav.MAV_SEVERITY_ERROR, "fdir", "jet_failed_off", f"JET {burst + 1} FAILED_OFF")
            rig.fly(5)                                   # one RG2 tick
            texts = [m.text for m in sent if m.get_type() == "STATUSTEXT"]
            assert f"JET {burst + 1} FAILED_OFF" in texts, texts
        settle(rig, 0.3)
    finally:
        evil.close()
    assert {"multiframe", "mavlink1", "reflected", "reads"} <= kinds
    st = rig.gl.stats
    assert st["commands_accepted"] == 0 and st["params_set"] == 0 and st["peers_added"] == 0, st
    assert rig.fsw.driver.armed and dict(rig.fsw.params) == params0 and not rig.gl.peers
    assert rig.gl.link.counts[Reject.OWN_SYSTEM] > 0 and rig.gl.link.counts[Reject.GARBAGE] > 0


def test_an_unsigned_parameter_list_goes_to_the_requester_at_the_read_pace(rig, monkeypatch):
    """Keyless, a stock ground station still gets the whole list, to its own address only;
    one 20-byte request cannot make the vehicle send more than the read pace allows (the
    pace made smaller than the list here: the default burst holds a whole connection)."""
    from fsw.groundlink import senders
    monkeypatch.setattr(senders, "READ_BURST", 30.0)
    monkeypatch.setattr(senders, "READ_RATE_HZ", 10.0)
    READ_BURST, READ_RATE_HZ = senders.READ_BURST, senders.READ_RATE_HZ
    evil = attacker_socket()
    to_requester = []
    send = rig.gl._send
    rig.gl._send = lambda msg, *a, only=None, **kw: (
        to_requester.append(msg) if only == evil.getsockname() and msg.get_type() == "PARAM_VALUE" else None,
        send(msg, *a, only=only, **kw))
    try:
        unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
        evil.sendto(mav.MAVLink_param_request_list_message(1, 1).pack(unsigned), rig.gl.address)
        assert rig.exchange(lambda: rig.gl.stats["rx_datagrams"] >= 1)
        assert len(to_requester) <= READ_BURST
        n_params = len(rig.gl.param_names)
        ticks = 0
        while len(to_requester) < n_params:
            before = len(to_requester)
            rig.fly(5)                                     # one RG2 tick: 0.1 s
            ticks += 1
            assert len(to_requester) - before <= READ_RATE_HZ * 0.1 + 1
            assert ticks < 100
        assert sorted(m.param_index for m in to_requester) == list(range(n_params))
    finally:
        evil.close()


def test_unsigned_reads_beyond_a_senders_budget_are_refused_counted_and_told_once(rig, monkeypatch):
    """Each keyless sender has its own read budget: what one sender asks beyond it is not
    answered, counted per sender and told in the one throttled refusal event; another
    sender is still answered (no refill here: the counts are exact)."""
    from fsw.groundlink import senders
    monkeypatch.setattr(senders, "READ_BURST", 10.0)
    monkeypatch.setattr(senders, "READ_RATE_HZ", 0.0)
    evil, other = attacker_socket(), attacker_socket()
    answers = {}
    send = rig.gl._send
    rig.gl._send = lambda msg, *a, only=None, **kw: (
        answers.__setitem__(only, answers.get(only, 0) + 1) if msg.get_type() == "PARAM_VALUE" else None,
        send(msg, *a, only=only, **kw))
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    try:
        for i in range(40):
            evil.sendto(mav.MAVLink_param_request_read_message(1, 1, b"", i % 8).pack(unsigned), rig.gl.address)
        other.sendto(mav.MAVLink_param_request_read_message(1, 1, b"", 0).pack(unsigned), rig.gl.address)
        assert rig.exchange(lambda: rig.gl.stats["rx_datagrams"] >= 41)
        assert answers.get(evil.getsockname()) == 10 and answers.get(other.getsockname()) == 1, answers
        assert rig.gl.stats["reads_limited"] == 30
        assert rig.gl.refused_by_sender[evil.getsockname()] == 30
        assert other.getsockname() not in rig.gl.refused_by_sender
        assert len(link_events(rig)) == 1, [e.text for e in link_events(rig)]
    finally:
        evil.close()
        other.close()


def test_answers_to_single_reads_leave_the_events_their_share_of_a_tick(rig):
    """More read requests in one tick than the tick may answer: the answers stop at what the
    events' share leaves (the rest counted), and the events still get their share."""
    from fsw.groundlink.link import EVENT_SHARE
    rig.gl.tick(rig.frame)
    rig.gl.intake.budget_ns = 10**9              # one tick reads them all: the send side is judged
    rig.gl.budget.budget_ns = 10**12             # (the tick's receive share bounds the intake's call too)
    n = rig.gl.max_tx_per_tick
    sent = []
    send = rig.gl._send
    rig.gl._send = lambda msg, *a, **kw: (sent.append(msg.get_type()), send(msg, *a, **kw))
    evil = attacker_socket()
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    try:
        for i in range(n):
            evil.sendto(mav.MAVLink_param_request_read_message(1, 1, b"", i % 8).pack(unsigned), rig.gl.address)
        for i in range(40):
            rig.fsw.events.emit(rig.fsw.t_s, mav.MAV_SEVERITY_CRITICAL, "test", f"fdir{i}", f"FDIR EVENT {i}")
        rig.gl.tick(rig.frame)
    finally:
        evil.close()
    assert rig.gl.stats["rx_datagrams"] >= n
    assert sent.count("PARAM_VALUE") <= n - EVENT_SHARE and sent.count("STATUSTEXT") >= EVENT_SHARE, sent
    assert rig.gl.stats["reads_limited"] >= EVENT_SHARE


@pytest.mark.parametrize("listen", [True, False])
def test_a_flood_at_the_control_rate_never_fills_the_queue_a_genuine_command_sent_once_is_answered(rig, listen):
    """The bench's hostile mix at 2,500 datagrams/s (50 a 50-Hz cycle, 60-kB datagrams among
    them) and ONE genuine signed command, sent once (no retry) between two link ticks.
    Listening every cycle (GroundLink.listen, as the SIL's FSW does), the kernel drops
    nothing, so the command cannot be lost at the queue and is answered. Reading only at
    RG2 ticks (the control experiment), the queue fills between ticks and the kernel drops
    datagrams: whether the command is among them is then chance.
    The intake's budget is kept on a clock that stands still (as the rig's tick budget is):
    what is judged is the reading schedule, not how much of the mix this host verifies in
    its 2 ms (about 3 ms for a cycle's 50 datagrams on a slow host: the budget then reads
    only part of them and the kernel drops whatever the schedule); the bench's flood
    section measures what a host's budget reads."""
    from ellipsled.bench.flood import Flood
    rig.gl.intake.clock_ns = lambda: 0
    fl = Flood(5)
    evil = attacker_socket()
    pc = None
    try:
        for cycle in range(60):
            for _ in range(50):
                evil.sendto(fl.next()[1], rig.gl.address)
            if cycle == 22:                               # between two ticks (every 5th cycle)
                pc = rig.gcs.start(make_request("arm", "on"), timeout_s=60.0, retries=0)
            rig.fly(1, listen=listen)
    finally:
        evil.close()
    drops = rig.gl.stats["kernel_drops"]
    if listen:
        assert drops == 0 and rig.gl.stats["rx_datagrams"] >= 60 * 50, rig.gl.stats
        assert rig.exchange(lambda: pc.done) and pc.result == ACCEPTED, pc.result
    else:
        assert drops > 0, rig.gl.stats
