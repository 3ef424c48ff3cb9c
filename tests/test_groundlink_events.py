"""The MAVLink events interface of the ground link (fsw/groundlink/events.py): each event the
catalogue describes goes down as an EVENT beside its STATUSTEXT, numbered without gaps;
CURRENT_EVENT_SEQUENCE tells the last number; a station without the key gets missed events
again (REQUEST_EVENT), or RESPONSE_EVENT_ERROR for those no longer held, to itself only.

Independent truth: what the link sent (its frames, captured), decoded with the events
metadata file the vehicle serves, read as a ground station reads it; requests packed and
answers parsed by pymavlink.
"""
from __future__ import annotations

import json
import struct

import pytest

from fsw.groundlink import events as gl_events
from fsw.groundlink import metadata
from interfaces.event_catalogue import EV
from interfaces.mavlink import dialect as mav
from interfaces.vocabulary import DEGRADED, Severity

from tests.rig import flown, station  # noqa: F401  (the keyless station, over this module's rig)


@pytest.fixture
def rig(tmp_path):
    with flown(tmp_path, 3) as r:
        sent = r.sent = []
        send = r.gl._send
        r.gl._send = lambda msg, *a, **kw: (sent.append(msg), send(msg, *a, **kw))
        yield r


def _of(msgs, name: str) -> list:
    return [m for m in msgs if m.get_type() == name]


def _metadata(rig) -> tuple[dict, dict]:
    comp = json.loads(rig.gl.files[metadata.EVENTS_PATH])["components"]["1"]
    return comp["event_groups"]["default"]["events"], comp["enums"]


def _values(event: dict, enums: dict, arguments) -> list:
    codes = {"uint8_t": "B", "uint16_t": "H", "uint32_t": "I", "int64_t": "q", "float": "f"}
    out, off, raw = [], 0, bytes(arguments)
    for arg in event.get("arguments", []):
        t = enums[arg["type"]]["type"] if arg["type"] in enums else arg["type"]
        out.append(struct.unpack_from("<" + codes[t], raw, off)[0])
        off += struct.calcsize(codes[t])
    return out


def test_each_event_goes_down_as_an_event_numbered_without_gaps(rig):
    first = rig.gl.event_downlink.next_seq
    log = rig.fsw.events
    log.emit(rig.fsw.t_s, EV.JET_DEGRADED, jet=11, eta=0.5)
    log.emit(rig.fsw.t_s, EV.FDIR_RECONFIG, jet=11, health=DEGRADED, eta=0.5, override=True)
    log.emit(rig.fsw.t_s, Severity.ERROR, "fdir", "jet_failed_off", "JET 2 FAILED_OFF")   # text form: no values
    log.emit(rig.fsw.t_s, Severity.WARNING, "allocator", "alloc_degraded", "ALLOCATION DEGRADED (infeasible)")
    log.emit(rig.fsw.t_s, Severity.INFO, "test", "not_catalogued", "SOMETHING")
    rig.sent.clear()
    rig.gl.tick(rig.frame)
    events, texts = _of(rig.sent, "EVENT"), [m.text for m in _of(rig.sent, "STATUSTEXT")]
    assert texts[-5:] == ["JET 11 DEGRADED ETA 0.50", "RECONFIG JET 11 DEGRADED ETA 0.50 (GND OVERRIDE HO",
                          "JET 2 FAILED_OFF", "ALLOCATION DEGRADED (infeasible)", "SOMETHING"]
    assert [e.sequence for e in events] == [first, first + 1, first + 2]
    meta, enums = _metadata(rig)
    shown = []
    for e in events:
        ev = meta[str(e.id & 0xFFFFFF)]
        assert e.id >> 24 == 1 and e.destination_system == 0 and e.destination_component == 0
        shown.append((ev["name"], e.log_levels & 0xF, _values(ev, enums, e.arguments)))
    assert shown == [("jet_degraded", Severity.WARNING, [11, 0.5]),
                     ("fdir_reconfig_2", Severity.NOTICE, [11, DEGRADED, 0.5, 1]),
                     ("alloc_degraded", Severity.WARNING, [])]
    assert all(e.log_levels >> 4 == e.log_levels & 0xF for e in events)
    assert all(e.event_time_boot_ms == int(rig.fsw.t_s * 1000) for e in events)


def test_current_event_sequence_tells_the_last_number_once_a_second(rig):
    rig.fsw.events.emit(rig.fsw.t_s, EV.JETS_DISARMED)
    rig.sent.clear()
    rig.fly(100)                                        # 2 s of the fake clock
    told, last = [], None
    for m in rig.sent:
        if m.get_type() == "EVENT":
            last = m.sequence
        elif m.get_type() == "CURRENT_EVENT_SEQUENCE":
            told.append((m.sequence, m.flags, last))
    assert 2 <= len(told) <= 3 and last is not None
    assert all(seq == last_sent and flags == 0 for seq, flags, last_sent in told), told


def test_a_station_without_the_key_gets_missed_events_again_to_itself_only(rig, station):
    for j in range(1, 4):
        rig.fsw.events.emit(rig.fsw.t_s, EV.JET_FAILED_OFF, jet=j)
    rig.gl.tick(rig.frame)
    sent = {e.sequence: e for e in _of(rig.sent, "EVENT")}
    seqs = sorted(sent)[-3:]
    rig.sent.clear()
    station.send(mav.MAVLink_request_event_message(1, 1, seqs[0], seqs[2]))
    assert station.wait(lambda: len(station.of("EVENT")) == 3)
    again = station.of("EVENT")
    assert [(e.sequence, e.id, list(e.arguments)) for e in again] == \
        [(s, sent[s].id, list(sent[s].arguments)) for s in seqs]
    assert not _of([m for m in rig.sent if m not in again], "EVENT")          # nothing new for the ground
    assert rig.gl.stats["unsigned_reads"] >= 1 and rig.gl.stats["peers_added"] == 0 and not rig.gl.peers
    # a number not sent yet is not answered
    station.send(mav.MAVLink_request_event_message(1, 1, seqs[2] + 5, seqs[2] + 5))
    assert not station.wait(lambda: len(station.of("EVENT")) > 3 or station.of("RESPONSE_EVENT_ERROR"), 0.3)


def test_a_forgotten_event_is_answered_with_the_oldest_still_held(rig, station):
    for i in range(gl_events.HELD + 10):
        rig.fsw.events.emit(rig.fsw.t_s, EV.SENSORS_STALE, periods=i)
        if i % 4 == 3:
            rig.gl.tick(rig.frame)                      # 8 events a tick (their share: 16 frames)
    rig.exchange(lambda: False, 0.2)
    down = rig.gl.event_downlink
    oldest = (down.next_seq - gl_events.HELD) & 0xFFFF
    station.send(mav.MAVLink_request_event_message(1, 1, oldest - 2, oldest))
    assert station.wait(lambda: len(station.of("RESPONSE_EVENT_ERROR")) == 2 and station.of("EVENT"))
    errors = station.of("RESPONSE_EVENT_ERROR")
    assert [(e.sequence, e.sequence_oldest_available, e.reason) for e in errors] == \
        [(oldest - 2, oldest, mav.MAV_EVENT_ERROR_REASON_UNAVAILABLE), (oldest - 1, oldest, 0)]
    assert (errors[0].target_system, errors[0].target_component) == (245, 190)
    assert [e.sequence for e in station.of("EVENT")] == [oldest]


def test_the_arming_check_request_of_a_stock_station_is_answered_without_a_refusal_event(rig, station):
    n = rig.fsw.events.total
    station.command(mav.MAV_CMD_RUN_PREARM_CHECKS)
    assert station.wait(lambda: station.of("COMMAND_ACK"))
    assert station.of("COMMAND_ACK")[0].result == mav.MAV_RESULT_UNSUPPORTED
    assert rig.fsw.events.total == n and rig.gl.stats["unsigned_writes"] == 0
