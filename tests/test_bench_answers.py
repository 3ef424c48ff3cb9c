"""How the ground-link benchmark judges the paced commands of a real-time run
(ellipsled/bench/flood.py GroundWatch.answers, ellipsled/bench/groundlink.py rows): from
times set by the test, a command is in time when its ACK is back within
ANSWER_IN_TIME_S, late after that, missing without one; commands sent too close to the
vehicle's last frame are not judged; the row passes only with none late or missing."""
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
    watch.ack_t = [10.0 + ANSWER_IN_TIME_S, 10.2 + ANSWER_IN_TIME_S + 0.01, 10.45]
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
