"""How the ground-link benchmark judges the paced commands of a real-time run
(ellipsled/bench/flood.py GroundWatch.answers, ellipsled/bench/groundlink.py rows): from
times set by the test, a command is in time when its ACK is back within
ANSWER_IN_TIME_S, late after that, missing without one; commands sent too close to the
vehicle's last frame are not judged; the row passes only with none late or missing. The
paced commands go one at a time (an ACK is the waiting command's, a lost one is missing
and moves no other), and a stall of the ground station's thread sends no burst."""
from __future__ import annotations

import socket

import pytest

from ellipsled.bench import groundlink
from ellipsled.bench.flood import ANSWER_IN_TIME_S, ANSWER_WAIT_S, GroundWatch
from interfaces.mavlink.signing.keys import SigningKey


@pytest.fixture
def watch():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    w = GroundWatch(SigningKey.generate(), port, None, pace_hz=5.0, vehicle=("127.0.0.1", 9))
    yield w
    w.sock.close()


def test_answers_are_in_time_late_or_missing_and_the_last_second_is_not_judged(watch):
    watch.sent_t = [10.0, 10.2, 10.4, 10.6, 19.5]
    watch.ack_t = [10.0 + ANSWER_IN_TIME_S, 10.2 + ANSWER_IN_TIME_S + 0.01, None, 10.65, None]
    watch.last_rx_t = 19.5 + ANSWER_WAIT_S - 0.01          # the last command had no time
    a = watch.answers()
    assert (a["sent"], a["in_time"], a["late"], a["missing"]) == (4, 2, 1, 1)
    assert a["latency_max_ms"] == pytest.approx(1e3 * (ANSWER_IN_TIME_S + 0.01))


def _verdict(answers: dict) -> str:
    res = {"groundlink": {f"{hz}Hz": {"budget_us": 1.0, "budget_share": 0.15, "answers": answers}
                          for hz in groundlink.RATES_HZ}}
    rows = [r for r in groundlink.rows(res) if r[0].startswith("signed commands")]
    assert len(rows) == len(groundlink.RATES_HZ)
    return rows[0][5]


def test_the_row_passes_only_with_every_command_answered_in_time(watch):
    watch.sent_t, watch.ack_t, watch.last_rx_t = [1.0, 1.2], [1.1, 1.3], 10.0
    good = watch.answers()
    assert _verdict(good) != _verdict({**good, "late": 1}) == _verdict({**good, "missing": 1})
    assert _verdict(good) != _verdict({**good, "sent": 0, "in_time": 0})


def test_one_command_at_a_time_each_ack_its_own_and_no_burst_after_a_stall(watch):
    watch.pace()
    period = 1.0 / watch.pace_hz
    now = [0.0]
    watch.clock = lambda: now[0]

    def send_due(t: float) -> None:
        now[0] = t
        watch._send_due()
    send_due(100.0)
    send_due(100.0 + period)                             # due, but the first is unanswered
    assert len(watch.sent_t) == 1
    watch._answered(100.25)
    send_due(100.25)                                     # answered: the second goes
    watch._answered(100.3)
    send_due(100.3)                                      # not due before 100.4
    send_due(100.0 + 2 * period)
    assert watch.sent_t == [100.0, 100.25, 100.0 + 2 * period]
    send_due(100.0 + 2 * period + ANSWER_WAIT_S - 0.01)  # the third, unanswered, still waits
    send_due(100.0 + 2 * period + ANSWER_WAIT_S)         # ... given up: the fourth goes
    assert len(watch.sent_t) == 4
    watch._answered(101.45)                              # the fourth's
    watch._answered(101.46)                              # no command waiting
    send_due(200.0)                                      # after a stall of this thread: one command ...
    watch._answered(200.01)
    send_due(200.01)                                     # ... and the next a period later, not at once
    send_due(200.0 + period)
    assert watch.sent_t[4:] == [200.0, 200.0 + period]
    watch._answered(200.0 + period + 0.1)
    watch.last_rx_t = 300.0
    a = watch.answers()
    # the first late (250 ms), the third missing: the fourth's ACK is its own, in time
    assert (a["sent"], a["in_time"], a["late"], a["missing"], a["stale_acks"]) == (6, 4, 1, 1, 1)
    assert a["latency_max_ms"] == pytest.approx(250.0)
    assert a["send_gap_max_ms"] == pytest.approx(1e3 * (200.0 - 100.0 - 2 * period - ANSWER_WAIT_S))
