"""The ground link's deferrable work item by item (fsw/groundlink/link.py, schedule.py), on an
injected clock where every packed frame costs FRAME_NS and every verified frame VERIFY_NS:
what a tick begins, sends and defers is exact on any host. Proven: events beyond the tick's
first, parameter-list entries and FTP burst replies are begun only while their recent cost
fits short of the budget's end reserve, so a tick ends inside its budget however much of
them waits; what was not begun goes out at the next ticks, in order, none lost, the waits
counted per kind (``events_deferred``, ``params_deferred``); and a keyless flood queued
ahead of a genuine signed command delays it by a bounded number of ticks, not for good."""
from __future__ import annotations

import math
import time

import pytest

from fsw.groundlink.schedule import END_RESERVE
from interfaces.event_catalogue import EV
from interfaces.mavlink import dialect as mav
from tests.rig import ACCEPTED, Keyless, NsClock, flown

FRAME_NS = 100_000                 # what one packed frame costs on the injected clock
VERIFY_NS = 50_000                 # what verifying and handling one received frame costs besides


@pytest.fixture
def quiet(tmp_path):
    """A flown rig on NsClock with no telemetry stream: (rig, clock); only the work a test
    queues costs time."""
    with flown(tmp_path) as rig:
        gl = rig.gl
        for _ in range(3):                               # the start-up events out
            rig.clock.t += 0.1
            gl.tick(rig.frame)
        rig.gcs.poll(0.05)
        clock = NsClock()
        gl.budget.clock_ns = gl.intake.clock_ns = clock
        for name in gl.rates_hz:
            gl.rates_hz[name] = 0.0
        pack, receive = gl.link.pack, gl.link.receive_single

        def priced_pack(msg):
            clock.t += FRAME_NS
            return pack(msg)

        def priced_receive(frame):
            clock.t += VERIFY_NS
            return receive(frame)
        gl.link.pack = priced_pack
        gl.link.receive_single = priced_receive
        yield rig, clock


def _tick(rig) -> int:
    """One link tick, an RG2 period later on the scheduling clock: its cost [ns]."""
    gl = rig.gl
    rig.clock.t += 1.0 / gl.max_rate_hz
    before = gl.budget.ticks
    gl.tick(rig.frame)
    return int(gl.budget.costs[before % len(gl.budget.costs)])


def _usable(gl) -> int:
    """The time work may be begun in: the budget less its end reserve [ns]."""
    return gl.budget.budget_ns - int(END_RESERVE * gl.budget.budget_ns)


def test_a_burst_of_events_goes_out_over_ticks_within_the_budget_in_order_none_lost(quiet):
    rig, clock = quiet
    gl = rig.gl
    gl.budget.budget_ns = 10 * FRAME_NS                  # 7 frames to work in
    n = 40
    n0 = len(rig.gcs.state.events)
    deferred0 = gl.stats.get("events_deferred", 0)
    for i in range(n):
        rig.fsw.events.emit(rig.fsw.t_s, EV.REVERSAL_WAY, miss_km=float(i))   # not throttled
    costs, waiting = [], 0
    for _ in range(30):
        costs.append(_tick(rig))
        waiting += rig.fsw.events.total - gl._event_index
        rig.gcs.poll(0.02)
        if len(rig.gcs.state.events) - n0 == n:
            break
    texts = [e.text for e in list(rig.gcs.state.events)[n0:]]
    assert texts == [f"REVERSAL TURNED ROUND: MISS +{i}.0 KM" for i in range(n)]   # all, in order
    assert len(costs) > 2                                # they could not all go in one tick ...
    event_ns = 2 * FRAME_NS                              # an event: its EVENT and its STATUSTEXT
    assert max(costs) <= _usable(gl) + event_ns          # ... and no tick began one past its time
    assert max(costs) <= gl.budget.budget_ns
    assert gl.stats.get("events_deferred", 0) - deferred0 == waiting > 0     # each wait counted
    assert gl.stats.get("events_missed", 0) == 0


def test_a_parameter_list_goes_out_over_ticks_within_the_budget_every_entry_once(quiet):
    rig, clock = quiet
    gl = rig.gl
    gl.budget.budget_ns = 10 * FRAME_NS
    deferred0 = gl.stats.get("params_deferred", 0)
    listed, value_msg = [], gl.params_in.value_msg

    def recorded(name):
        listed.append(name)
        return value_msg(name)
    gl.params_in.value_msg = recorded
    rig.gcs.param_request_list()                         # signed: no read pace, only the budget
    time.sleep(0.002)                                    # loopback delivery
    n = len(gl.params_in.names)
    sent, costs = [], []
    for _ in range(60):
        f0 = gl.stats["tx_frames"]
        costs.append(_tick(rig))
        sent.append(gl.stats["tx_frames"] - f0)
        rig.gcs.poll(0.02)
        if len(rig.gcs.state.params) >= n and not gl._param_lists:
            break
    assert len(rig.gcs.state.params) == n and not gl._param_lists          # every entry, none lost
    assert sorted(listed) == sorted(gl.params_in.names)                    # each once
    assert max(costs) <= _usable(gl) + FRAME_NS + VERIFY_NS                # none begun past its time
    ticks_with_entries = sum(1 for s in sent if s)
    assert ticks_with_entries >= math.ceil(n / (_usable(gl) // FRAME_NS))  # spread over ticks ...
    assert gl.stats.get("params_deferred", 0) - deferred0 == ticks_with_entries - 1   # ... each cut counted


def test_an_ftp_burst_is_cut_to_the_replies_the_ticks_time_covers(quiet):
    """A signed burst read of the metadata file (16 replies asked for): with time to spare all
    go; with the time for a few left the tick ends inside its budget (the client reads the
    rest by asking on)."""
    from fsw.groundlink import ftp
    rig, clock = quiet
    gl = rig.gl
    n_asked = gl.ftp.burst_packets
    path = max(gl.files, key=lambda p: len(gl.files[p]))
    assert len(gl.files[path]) > n_asked * ftp.DATA_MAX                      # a burst's worth

    def request(seq, opcode, session=0, data=b""):
        payload = ftp.HEADER.pack(seq, session, opcode, len(data), 0, 0, 0, 0) + data
        return mav.MAVLink_file_transfer_protocol_message(0, 1, 1, list(payload.ljust(ftp.PAYLOAD_LEN, b"\0")))

    def sent_by_tick(req) -> tuple[int, int]:
        rig.gcs.send(req)
        time.sleep(0.002)                                # loopback delivery
        f0 = gl.stats["tx_frames"]
        cost = _tick(rig)
        return gl.stats["tx_frames"] - f0, cost
    gl.budget.budget_ns = 100 * FRAME_NS
    sent_by_tick(request(1, ftp.OPEN_RO, data=path.encode()))
    replies, _ = sent_by_tick(request(2, ftp.BURST))     # the session the open made: the first
    assert replies == n_asked
    gl.budget.budget_ns = 10 * FRAME_NS                  # 7 frames to work in
    replies, cost = sent_by_tick(request(3, ftp.BURST))
    assert 1 <= replies < n_asked
    assert cost <= gl.budget.budget_ns


def test_a_flood_queued_ahead_of_a_signed_command_delays_it_a_bounded_number_of_ticks(quiet):
    """200 keyless datagrams (unsigned parameter reads and commands: each verified, handled
    and answered or refused, a frame's cost) ahead of a signed command, more of them arriving
    every tick: each tick reads at least what its receive share covers, so the command is
    answered within the ticks the backlog ahead of it takes, and the flood cannot keep it
    waiting longer."""
    rig, clock = quiet
    gl = rig.gl
    station = Keyless(rig)
    ahead = 200

    def flood(n):
        for i in range(n):
            if i % 2:
                station.send(mav.MAVLink_param_request_read_message(1, 1, b"NO_SUCH_PARAM", -1))
            else:
                station.command(400, 1)                  # arm, unsigned: refused
    flood(ahead)
    pc = rig.gcs.start_command(mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1, timeout_s=60.0, retries=0)
    time.sleep(0.01)
    # a keyless frame costs VERIFY_NS and at most an answer frame; a tick's receiving has at
    # least RECEIVE_FLOOR of the usable time, at least a quarter of it here (nothing due)
    per_tick = max(1, (_usable(gl) // 2) // (VERIFY_NS + FRAME_NS))
    bound = math.ceil((ahead + 1) / per_tick) + 1
    ticks = 0
    while pc.result is None and ticks < 4 * bound:
        ticks += 1
        _tick(rig)
        rig.gcs.poll(0.02)
        flood(20)                                        # the flood goes on
    station.close()
    assert pc.result == ACCEPTED
    assert ticks <= bound, f"answered after {ticks} ticks, bound {bound}"
