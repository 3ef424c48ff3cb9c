"""The ground link's time budget per tick (fsw/groundlink/schedule.py), on an injected clock:
each packed frame costs a known time, so what a tick sends, defers and spends is exact on any
host. Proven: a tick stops sending once its budget is spent, over by at most the unit it was
sending; what it did not send stays due and is counted; under a short budget every stream
still gets its turn (the longest-waiting first), events and a mode change go out first; with
time to spare nothing is deferred; receiving leaves the send side its recent cost, at most
half the budget, and the cost of the streams a period overdue, keeping half; those go
first; a signed command sent before each tick is answered in that tick however much the
streams owe; the cycle's deadline shortens the budget; receiving is given its share less what
the tick spent before it and what it recently took past the intake's budget; a unit needs
room for its estimate and the units' recent estimate misses; a command is answered in the tick
it arrived before even when the socket read takes all of receiving's share, and the second
tick running with no time to receive still reads one frame."""
from __future__ import annotations

import time
from collections import Counter

import pytest

from fsw.groundlink.schedule import COST_SAMPLES, DUE_SLACK, END_RESERVE, RecentCost, StreamSchedule, TickBudget
from fsw.groundlink.streams import ATTITUDE_GROUP, ATTITUDE_UNITS
from interfaces.event_catalogue import EV
from tests.rig import ACCEPTED, NsClock, PricedReads, flown
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing.sign import Signer

FRAME_NS = 250_000                 # what one frame costs on the injected clock


@pytest.fixture
def priced(tmp_path):
    """A flown rig whose link runs on an NsClock that moves only when it packs a frame, every
    stream due every tick: (rig, clock, turns per stream); ``rig.log`` lists each stream's
    turn and each frame, in order."""
    with flown(tmp_path) as rig:
        gl = rig.gl
        clock = NsClock()                                # moves when the link packs a frame
        gl.budget.clock_ns = clock
        for name in gl.rates_hz:
            gl.rates_hz[name] = gl.max_rate_hz
            gl.schedule.next_due[name] = 0.0                 # all due now
        pack = gl.link.pack

        rig.log = []

        def priced_pack(msg):
            clock.t += FRAME_NS
            rig.log.append("frame")
            return pack(msg)
        gl.link.pack = priced_pack
        turns: Counter = Counter()
        take = gl.schedule.take

        def counted(name, now):
            due = take(name, now)
            turns[name] += due
            rig.log.append("turn")
            return due
        gl.schedule.take = counted
        yield rig, clock, turns


def _ticks(rig, n: int) -> list[int]:
    """n link ticks, one RG2 period apart on the scheduling clock; each tick's cost [ns].
    ``rig.waiting``: the streams due at the start of each tick, summed."""
    costs = []
    rig.waiting = 0
    for _ in range(n):
        rig.clock.t += 1.0 / rig.gl.max_rate_hz
        rig.waiting += sum(rig.gl.schedule.waiting(name, rig.clock.t) for name in rig.gl.rates_hz)
        before = rig.gl.budget.ticks
        rig.gl.tick(rig.frame)
        assert rig.gl.budget.ticks == before + 1
        costs.append(rig.gl.budget.costs[before % len(rig.gl.budget.costs)])
        rig.gcs.poll(0.0)
    return costs


def test_a_short_budget_stops_the_tick_defers_the_rest_and_every_stream_gets_its_turn(priced):
    rig, clock, turns = priced
    gl = rig.gl
    budget = gl.budget.budget_ns
    wanted = len(gl.rates_hz)
    assert budget == round(0.15 * rig.scn.dt_control_s * 1e9)
    n = 60
    deferred0 = gl.stats["tx_deferred"]
    costs = _ticks(rig, n)
    # the most frames one unit sent (a stream, or a group: its turns, then its frames)
    runs = "".join("t" if e == "turn" else "f" for e in rig.log).split("t")
    largest_unit = max(len(r) for r in runs[1:]) * FRAME_NS
    assert largest_unit >= len(ATTITUDE_GROUP) * FRAME_NS
    usable = budget - int(END_RESERVE * budget)          # the budget less its end reserve
    assert max(costs) >= usable - largest_unit           # the clock did price the frames: the budget was used
    assert max(costs) <= usable + largest_unit           # into the reserve only by the unit under way
    assert gl.stats["tx_deferred"] > deferred0           # it could not send everything ...
    sent = sum(turns.values())
    assert sent < wanted * n                             # ... and did not
    # ... yet every stream had its turns, the longest-waiting first: none starves
    assert set(turns) == set(gl.rates_hz)
    assert min(turns.values()) >= 0.5 * sent / wanted
    # each stream due at a tick went out or was counted as deferred: none is lost
    assert sent + gl.stats["tx_deferred"] - deferred0 == rig.waiting


def test_with_time_to_spare_every_stream_goes_every_tick_and_nothing_waits(priced):
    rig, clock, turns = priced
    rig.gl.budget.budget_ns = 10**12
    deferred0 = rig.gl.stats["tx_deferred"]
    _ticks(rig, 20)
    assert rig.gl.stats["tx_deferred"] == deferred0
    assert all(turns[name] >= 19 for name in rig.gl.rates_hz)


def test_with_no_budget_left_one_event_goes_a_tick_the_others_wait_counted_and_none_is_lost(priced):
    rig, clock, turns = priced
    gl = rig.gl
    gl.budget.budget_ns = 1                             # spent by the first frame
    _ticks(rig, 3)
    n0 = len(rig.gcs.state.events)
    deferred0 = gl.stats["events_deferred"]
    for i in range(3):
        rig.fsw.events.emit(rig.fsw.t_s, EV.REVERSAL_WAY, miss_km=float(i))   # not throttled
    turns.clear()
    got = []
    for _ in range(3):
        _ticks(rig, 1)
        rig.gcs.poll(0.05)
        got.append(len(rig.gcs.state.events) - n0)
    assert got == [1, 2, 3]                             # the tick's first event, over the budget; the rest wait
    assert gl.stats["events_deferred"] - deferred0 == 2 + 1     # waiting: two events, then one
    texts = [e.text for e in list(rig.gcs.state.events)[n0:]]
    assert texts == [f"REVERSAL TURNED ROUND: MISS +{i}.0 KM" for i in range(3)]   # in order, none lost
    assert sum(turns.values()) <= 3                     # the most overdue unit a tick, no more


def test_a_mode_change_is_the_first_stream_a_short_tick_sends(priced):
    rig, clock, turns = priced
    gl = rig.gl
    gl.budget.budget_ns = 1                             # one unit a tick
    _ticks(rig, 3)
    gl.schedule_now("CURRENT_MODE")                     # as a mode change does
    turns.clear()
    _ticks(rig, 1)
    assert turns == Counter({"CURRENT_MODE": 1})


def test_receiving_leaves_the_send_side_its_recent_cost_at_most_half_the_budget():
    t = [0]
    b = TickBudget(1000, lambda: t[0])
    b.start()                                            # work is begun in 700 (the end reserve: 300)
    assert b.receive_ns(300) == 400 and b.receive_ns(0) == 700
    assert b.receive_ns(900) == 350                      # a heavy send side: half
    b.start(cap_ns=400)                                  # the cycle's deadline is nearer: 280 to work in
    assert b.limit_ns == 400 and b.receive_ns(300) == 140
    b.start(cap_ns=-5)                                   # the deadline is past: nothing
    assert b.left_ns() <= 0 and b.receive_ns(0) == 0
    t[0] += 1500
    assert b.finish() == 1500 and b.over == 1 and b.report()["max_us"] == 1.5


def test_a_stream_is_due_once_a_period_and_may_go_a_little_early():
    s = StreamSchedule({"A": 10.0, "B": 0.0})
    assert s.take("A", 5.0) and not s.take("A", 5.0)    # due at once, then a period later
    assert not s.waiting("A", 5.1 - 0.1 * DUE_SLACK - 1e-9)
    assert s.take("A", 5.1 - 0.1 * DUE_SLACK)
    assert not s.waiting("B", 1e9)                       # 0 Hz: off
    s.take("A", 100.0)                                   # fell behind: a period from now
    assert s.next_due["A"] == pytest.approx(100.1)
    assert s.longest_waiting([("A",), ("B",)], 100.1) == [("A",)]


def test_a_budget_that_is_no_share_of_the_period_is_refused(tmp_path):
    from fsw.groundlink import GroundLink
    with flown(tmp_path, cycles=1) as rig:
        for frac in (0.0, -0.1, 1.5, float("nan")):
            with pytest.raises(ValueError, match="tick_budget_frac"):
                GroundLink(rig.fsw, rig.key, bind="udp:127.0.0.1:0", tick_budget_frac=frac)


def test_receiving_leaves_the_overdue_streams_their_cost_keeping_half_and_work_stops_short_of_the_end():
    b = TickBudget(1000, lambda: 0)
    b.start()
    assert b.left_ns() == 1000 - 300                     # the end reserve: 30 % of the budget
    assert b.receive_ns(300, 0) == 700 - 300             # the overdue streams:
    assert b.receive_ns(0, 300) == 700 - 300             # ... more than the recent cost
    assert b.receive_ns(0, 5000) == 350                  # ... but receiving keeps half
    b.start(cap_ns=500)
    assert b.left_ns() == 500 - 150 and b.receive_ns(0, 5000) == 175


def test_a_stream_a_period_overdue_goes_before_a_slower_one_waiting_longer(priced):
    """A 1 Hz stream due half a second ago (not overdue) and the 10 Hz attitude messages (a
    unit of three streams) due 1.5 periods ago (overdue), a budget of one unit: the attitude
    unit goes, not the stream."""
    rig, clock, turns = priced
    gl = rig.gl
    gl.budget.budget_ns = 1
    now = rig.clock.t + 1.0 / gl.max_rate_hz            # the next tick's time
    for name in gl.rates_hz:
        gl.rates_hz[name] = 0.0
    gl.rates_hz["HEARTBEAT"] = 1.0
    gl.schedule.next_due["HEARTBEAT"] = now - 0.5
    attitude = ATTITUDE_UNITS[0]
    for name in attitude:
        gl.rates_hz[name] = 10.0
        gl.schedule.next_due[name] = now - 0.15
    assert gl.schedule.longest_waiting([("HEARTBEAT",), attitude], now)[0] == ("HEARTBEAT",)
    _ticks(rig, 1)
    assert turns == Counter({name: 1 for name in attitude})


def test_a_signed_command_before_each_tick_is_answered_in_that_tick_however_much_the_streams_owe(priced):
    """Every stream at its fastest, due every tick and more than the budget can send (they
    fall overdue), receiving priced on the same clock: a signed command sent before each tick
    is answered (COMMAND_ACK) in that tick, and no tick exceeds its budget by more than the
    unit it was sending."""
    rig, clock, turns = priced
    gl = rig.gl
    gl.intake.clock_ns = clock
    budget = gl.budget.budget_ns = 8 * FRAME_NS         # a quarter: the command's ACK and reply
    costs = []
    for k in range(40):
        pc = rig.gcs.start_command(mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1, timeout_s=60.0, retries=0)
        time.sleep(0.002)                                 # loopback delivery
        costs += _ticks(rig, 1)
        rig.gcs.poll(0.05)
        assert pc.result == ACCEPTED, f"command {k} not answered in its tick"
    assert gl.stats["tx_deferred"] > 0 and gl.stats["rx_deferred"] == 0   # the streams wanted more
    # over by at most the unit under way, once every unit has gone once (before that, a
    # unit not sent yet is taken to cost nothing)
    assert max(costs[3:]) <= budget + len(ATTITUDE_GROUP) * FRAME_NS


def test_receiving_is_given_its_share_less_what_the_tick_spent_before_it():
    t = [0]
    b = TickBudget(1000, lambda: t[0])
    b.start()
    t[0] = 100                                           # the schedule's own work
    assert b.receive_ns(300) == 1000 - 300 - 300 - 100  # the end reserve: 300
    t[0] = 900
    assert b.receive_ns(300) == 0


def test_an_estimate_is_the_second_costliest_of_the_last_eight_costs():
    e = RecentCost()
    assert e.ns == 0
    e.add(10)
    assert e.ns == 10
    for ns in (20, 1000, 30):
        e.add(ns)
    assert e.ns == 30                                    # one slow time moves nothing
    e.add(900)
    assert e.ns == 900                                   # two do
    for _ in range(COST_SAMPLES):
        e.add(5)
    assert e.ns == 5                                     # forgotten within the ring


def _streams_off_but(gl, name: str) -> None:
    """Only stream ``name``, at the fastest rate; the estimates the rig's flight (on the host's
    clock) left forgotten."""
    for stream in gl.rates_hz:
        gl.rates_hz[stream] = 0.0
    gl.rates_hz[name] = gl.max_rate_hz
    gl.streams.unit_costs.clear()
    gl.streams.unit_ns.clear()
    gl.streams.miss = RecentCost()


def test_what_receiving_takes_past_the_intakes_budget_is_taken_from_its_next_share(priced):
    """No stream and no datagram: receiving may take the whole budget. An intake that runs
    40 us past whatever budget it is given (its last frame, its reports) carries the first
    tick past the budget; from the next tick on its share is cut by that much and the tick
    ends on its budget."""
    rig, clock, turns = priced
    gl = rig.gl
    for stream in gl.rates_hz:
        gl.rates_hz[stream] = 0.0
    _ticks(rig, 3)                                      # the start-up events out
    gl.send_ns_peak = gl.send_overhead_ns = 0
    gl.rx_tail = RecentCost()
    given, poll = [], gl.intake.poll

    def late_poll(handle, budget_ns=None, least=True):
        given.append(budget_ns)
        clock.t += budget_ns + 40_000
        return poll(handle, 0)
    gl.intake.poll = late_poll
    usable = gl.budget.budget_ns - int(END_RESERVE * gl.budget.budget_ns)
    costs = _ticks(rig, 4)
    assert given == [usable] + [usable - 40_000] * 3
    assert costs == [usable + 40_000] + [usable] * 3


def test_a_unit_waits_when_what_is_left_covers_its_estimate_but_not_the_recent_misses(priced):
    rig, clock, turns = priced
    gl = rig.gl
    _streams_off_but(gl, "HEARTBEAT")                   # one frame, every tick
    _ticks(rig, 3)
    assert gl.streams.unit_ns[("HEARTBEAT",)] == FRAME_NS and gl.streams.miss.ns == 0
    gl.budget.budget_ns = 400_000
    room = gl.budget.budget_ns - int(END_RESERVE * gl.budget.budget_ns)      # what the send side is left
    assert FRAME_NS <= room < 2 * FRAME_NS
    turns.clear()
    _ticks(rig, 1)
    assert turns["HEARTBEAT"] == 1                      # its estimate fits
    gl.streams.miss.add(FRAME_NS)                       # two units a frame dearer than their estimates
    gl.streams.miss.add(FRAME_NS)
    deferred0 = gl.stats["tx_deferred"]
    turns.clear()
    _ticks(rig, 1)
    assert turns["HEARTBEAT"] == 0 and gl.stats["tx_deferred"] == deferred0 + 1    # it waits, counted
    turns.clear()
    _ticks(rig, 1)
    assert turns["HEARTBEAT"] == 1                      # a period overdue: it goes


def test_a_unit_dearer_than_its_estimate_is_counted_as_a_miss(priced):
    rig, clock, turns = priced
    gl = rig.gl
    _streams_off_but(gl, "HEARTBEAT")
    _ticks(rig, 3)
    pack = gl.link.pack

    def dear(msg):
        clock.t += FRAME_NS
        return pack(msg)
    gl.link.pack = dear
    _ticks(rig, 1)
    assert list(gl.streams.miss.ring)[-1] == FRAME_NS
    assert gl.streams.unit_ns[("HEARTBEAT",)] == FRAME_NS     # one dear send does not move its estimate


def test_what_sending_leaves_is_read_when_the_intake_stopped_on_its_budget(priced):
    """Signed frames waiting, each costing 100 us to verify; the send side wanted more than
    half the budget but has nothing due: receiving is given half, then reads on in what
    sending left, to the end reserve (less one frame), and the tick stays within its budget."""
    rig, clock, turns = priced
    gl = rig.gl
    for stream in gl.rates_hz:
        gl.rates_hz[stream] = 0.0
    _ticks(rig, 3)
    gl.intake.clock_ns = clock
    verify_ns, verified = 100_000, []
    receive = gl.intake.link.receive_single

    def priced_receive(frame):
        clock.t += verify_ns
        verified.append(frame)
        return receive(frame)
    gl.intake.link.receive_single = priced_receive
    ground = Signer(rig.key, system_id=255, component_id=190, link_id=6)
    budget = gl.budget.budget_ns
    n = budget // verify_ns + 10                        # more than a whole tick can read
    for _ in range(n):
        rig.gcs.sock.sendto(ground.pack(mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GCS, 0, 0, 0, 0, 3)),
                            gl.address)
    time.sleep(0.05)                                    # loopback delivery
    gl.send_ns_peak = 10 * budget
    cost = _ticks(rig, 1)[0]
    can = (budget - int(END_RESERVE * budget)) // verify_ns
    assert can - 1 <= len(verified) <= can and len(verified) > budget // 2 // verify_ns + 1
    assert cost <= budget


def test_the_most_overdue_unit_goes_whatever_is_left_the_next_overdue_one_only_if_it_fits(priced):
    """Two one-frame streams a period overdue, room for one and a half frames: the one due
    earlier goes, the other waits (counted) and goes first at the next tick."""
    rig, clock, turns = priced
    gl = rig.gl
    _streams_off_but(gl, "HEARTBEAT")
    gl.rates_hz["SYSTEM_TIME"] = gl.max_rate_hz
    _ticks(rig, 3)
    assert gl.streams.unit_ns[("HEARTBEAT",)] == gl.streams.unit_ns[("SYSTEM_TIME",)] == FRAME_NS
    gl.budget.budget_ns = 400_000                       # room for 1.5 frames: see above
    now = rig.clock.t + 1.0 / gl.max_rate_hz
    gl.rates_hz["HEARTBEAT"] = gl.rates_hz["SYSTEM_TIME"] = 1.0
    gl.schedule.next_due["HEARTBEAT"], gl.schedule.next_due["SYSTEM_TIME"] = now - 1.6, now - 1.5
    deferred0 = gl.stats["tx_deferred"]
    turns.clear()
    cost = _ticks(rig, 1)[0]
    assert turns == Counter({"HEARTBEAT": 1}) and gl.stats["tx_deferred"] == deferred0 + 1
    assert cost <= gl.budget.budget_ns
    turns.clear()
    _ticks(rig, 1)
    assert turns == Counter({"SYSTEM_TIME": 1})


def test_a_signed_command_is_answered_in_its_tick_when_the_socket_read_takes_all_of_receivings_share(priced):
    """Every stream at its fastest and falling overdue (receiving keeps only its floor), each
    socket read costing a whole budget: the intake reads the command and, out of time, begins
    it all the same; it is answered in the tick it arrived before, every tick."""
    rig, clock, turns = priced
    gl = rig.gl
    gl.intake.clock_ns = clock
    gl.budget.budget_ns = 8 * FRAME_NS
    gl.intake.sock = PricedReads(gl.intake.sock, clock, gl.budget.budget_ns)
    for k in range(10):
        pc = rig.gcs.start_command(mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1, timeout_s=60.0, retries=0)
        time.sleep(0.002)                                 # loopback delivery
        _ticks(rig, 1)
        rig.gcs.poll(0.05)
        assert pc.result == ACCEPTED, f"command {k} not answered in its tick"
    assert gl.stats["tx_deferred"] > 0


def test_the_second_tick_running_with_no_time_to_receive_reads_one_frame(priced):
    """The streams' schedule pass taking a whole budget before receiving (as a stalled host
    does): the first such tick reads nothing (counted), the next reads the command and answers
    it, and so on in turn; with the cycle's deadline already past no tick reads."""
    rig, clock, turns = priced
    gl = rig.gl
    gl.intake.clock_ns = clock
    overdue_ns = gl.streams.overdue_ns

    def stalled(now):
        clock.t += gl.budget.budget_ns
        return overdue_ns(now)
    gl.streams.overdue_ns = stalled
    _ticks(rig, 1)                                        # the tick before: nothing to read, no time
    for k in range(3):
        deferred0 = gl.stats["rx_deferred"]
        pc = rig.gcs.start_command(mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1, timeout_s=60.0, retries=0)
        time.sleep(0.002)
        _ticks(rig, 1)                                    # the second tick with no time: reads one
        rig.gcs.poll(0.05)
        assert pc.result == ACCEPTED and gl.stats["rx_deferred"] == deferred0, f"command {k}"
        pc = rig.gcs.start_command(mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1, timeout_s=60.0, retries=0)
        time.sleep(0.002)
        _ticks(rig, 1)                                    # a first tick with no time: reads nothing
        rig.gcs.poll(0.05)
        assert pc.result is None and gl.stats["rx_deferred"] == deferred0 + 1
        _ticks(rig, 1)                                    # ... and the next one answers it
        rig.gcs.poll(0.05)
        assert pc.result == ACCEPTED
        _ticks(rig, 1)                                    # (the next pair begins with a skip)
    gl.streams.overdue_ns = overdue_ns
    pc = rig.gcs.start_command(mav.MAV_CMD_REQUEST_PROTOCOL_VERSION, 1, timeout_s=60.0, retries=0)
    time.sleep(0.002)
    deferred0 = gl.stats["rx_deferred"]
    for _ in range(2):
        gl.tick(rig.frame, deadline_ns=time.monotonic_ns())   # no time before the deadline
    rig.gcs.poll(0.05)
    assert pc.result is None and gl.stats["rx_deferred"] == deferred0 + 2
