"""The event log: a bounded queue and a bounded history (a ring read by sequence number),
per-code rate limiting whose held events are told once the interval is over. Truth: the
counts of what the test emitted."""
from __future__ import annotations

from common.events import EventLog
from interfaces.vocabulary import Severity


def test_the_history_is_a_bounded_ring_read_by_sequence_number():
    log = EventLog()
    n = 20_000
    for i in range(n):
        log.emit(i * 1e-3, Severity.INFO, "test", f"c{i}", f"E{i}")
    assert log.total == n
    kept = log.history
    assert 0 < len(kept) < n and kept[-1].text == f"E{n - 1}"
    assert log.history_lost == n - len(kept)
    first, new = log.since(0)                      # a reader that fell behind learns what it missed
    assert first == n - len(kept) and [e.text for e in new] == [e.text for e in kept]
    first, new = log.since(n - 3)
    assert first == n - 3 and [e.text for e in new] == [f"E{n - 3}", f"E{n - 2}", f"E{n - 1}"]
    assert log.since(n) == (n, [])


def test_held_events_are_told_in_one_summary_once_the_interval_is_over():
    log = EventLog(min_interval_s=1.0)
    for i in range(10):
        log.emit(0.01 * i, Severity.WARNING, "link", "flood", f"flood {i}", rate_limited=True)
    assert [e.text for e in log.history] == ["flood 0"] and log.suppressed == 9
    assert log.release_held(0.5) == 0                # the interval is not over
    assert log.release_held(1.0) == 1
    assert [e.text for e in log.history] == ["flood 0", "flood 9 (+8 suppressed)"]
    assert log.release_held(5.0) == 0                # told once
