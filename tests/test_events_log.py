"""The event log: a bounded queue and a bounded history (a ring read by sequence number),
per-entry rate limiting (the catalogue's throttle, or the log's own for an entry) whose held
events are told once the interval is over. Truth: the counts and texts of what the test
emitted, written out by hand."""
from __future__ import annotations

import pytest

from common.events import EventLog
from interfaces.event_catalogue import EV
from interfaces.vocabulary import Severity


def test_the_history_is_a_bounded_ring_read_by_sequence_number():
    log = EventLog()
    n = 20_000
    for i in range(n):
        log.emit(i * 1e-3, EV.SENSORS_STALE, periods=i)
    assert log.total == n
    kept = log.history
    assert 0 < len(kept) < n and kept[-1].text == f"SENSORS STALE ({n - 1} PERIODS): JETS HELD OFF"
    assert log.history_lost == n - len(kept)
    first, new = log.since(0)                      # a reader that fell behind learns what it missed
    assert first == n - len(kept) and [e.text for e in new] == [e.text for e in kept]
    first, new = log.since(n - 3)
    assert first == n - 3 and [e.args for e in new] == [(("periods", n - 3),), (("periods", n - 2),),
                                                        (("periods", n - 1),)]
    assert log.since(n) == (n, [])


def test_an_event_takes_severity_source_name_and_text_from_its_entry():
    log = EventLog()
    assert log.emit(2.0, EV.JET_DEGRADED, jet=11, eta=0.4987)
    (ev,) = log.history
    assert (ev.t_s, ev.severity, ev.source, ev.code, ev.text) == (2.0, Severity.WARNING, "fdir", "jet_degraded",
                                                                  "JET 11 DEGRADED ETA 0.50")
    assert ev.entry is EV.JET_DEGRADED and dict(ev.args) == {"jet": 11, "eta": 0.4987}


def test_arguments_that_match_no_message_of_the_entry_are_refused():
    log = EventLog()
    with pytest.raises(TypeError, match="jet_degraded"):
        log.emit(0.0, EV.JET_DEGRADED, jet=3)
    with pytest.raises(TypeError, match="by name"):
        log.emit(0.0, EV.JET_DEGRADED, 3, 0.5)
    assert log.total == 0


def test_held_events_are_told_in_one_summary_once_the_interval_is_over():
    log = EventLog()
    for i in range(10):                            # link_flood: at most one a second (the catalogue)
        log.emit(0.01 * i, EV.LINK_FLOOD, dropped=i)
    assert [e.text for e in log.history] == ["link flooded: 0 datagrams dropped"] and log.suppressed == 9
    assert log.release_held(0.5) == 0                # the interval is not over
    assert log.release_held(1.0) == 1
    assert [e.text for e in log.history] == ["link flooded: 0 datagrams dropped",
                                             "link flooded: 9 datagrams dropped (+8 suppressed)"]
    assert log.history[-1].args == (("dropped", 9),) and log.history[-1].t_s == 1.0
    assert log.release_held(5.0) == 0                # told once


def test_a_log_may_give_an_entry_its_own_interval():
    log = EventLog()
    log.set_throttle(EV.LINK_REFUSED, 2.0)          # the catalogue says 60 s
    for t in (0.0, 1.0, 2.5):
        log.emit(t, EV.LINK_REFUSED, detail=f"refused at {t}")
    assert [e.text for e in log.history] == ["refused at 0.0", "refused at 2.5 (+1 suppressed)"]
    log.emit(3.0, EV.JETS_ARMED)
    log.emit(3.0, EV.JETS_ARMED)                     # no throttle: every one told
    assert log.total == 4


def test_the_text_form_still_works_for_modules_not_converted_yet():
    log = EventLog(min_interval_s=1.0)
    for i in range(3):
        log.emit(0.1 * i, Severity.WARNING, "allocator", "alloc_degraded", "ALLOCATION DEGRADED (infeasible)",
                 rate_limited=True)
    log.emit(0.0, 4, "test", "not_catalogued", "any text")
    assert [(e.code, e.args) for e in log.history] == [("alloc_degraded", None), ("not_catalogued", None)]
    assert log.history[0].entry is EV.ALLOC_DEGRADED and log.history[1].entry is None
    assert log.release_held(1.0) == 1 and log.history[-1].text == "ALLOCATION DEGRADED (infeasible) (+1 suppressed)"
