"""Modes: every transition pair against the spec's table, and the ordered failsafe list."""
from __future__ import annotations

import itertools
import math

import pytest

from common.events import EventLog, Severity
from fsw.modes import FailsafeAction, Failsafes, Mode, ModeManager
from fsw.params import load_params

# the transition table: STANDBY -> ENTRY <-> SAFE, any -> STANDBY
ALLOWED = {(Mode.STANDBY, Mode.ENTRY), (Mode.ENTRY, Mode.SAFE), (Mode.SAFE, Mode.ENTRY), (Mode.ENTRY, Mode.STANDBY),
           (Mode.SAFE, Mode.STANDBY)}


def manager_in(mode: Mode, ev: EventLog) -> ModeManager:
    m = ModeManager(ev)
    if mode == Mode.ENTRY:
        m.request(0.0, Mode.ENTRY, "setup")
    elif mode == Mode.SAFE:
        m.request(0.0, Mode.ENTRY, "setup")
        m.request(0.0, Mode.SAFE, "setup")
    return m


@pytest.mark.parametrize("src,dst", list(itertools.product(Mode, Mode)))
def test_each_transition_pair(src, dst):
    ev = EventLog()
    m = manager_in(src, ev)
    n0 = len(ev.history)
    ok = m.request(1.0, dst, "test")
    new = ev.history[n0:]
    if src == dst:
        assert ok and m.mode == src and new == []
    elif (src, dst) in ALLOWED:
        assert ok and m.mode == dst
        assert len(new) == 1 and new[0].severity == Severity.NOTICE and new[0].code == "mode_change"
        assert f"{src.name}->{dst.name}" in new[0].text
    else:
        assert not ok and m.mode == src
        assert len(new) == 1 and new[0].severity == Severity.WARNING and new[0].code == "mode_refused"


def test_mode_properties():
    m = ModeManager(EventLog())
    assert (m.jets_enabled, m.adaptation_enabled, m.closed_loop) == (False, False, False)
    m.request(0, Mode.ENTRY, "go")
    assert (m.jets_enabled, m.adaptation_enabled, m.closed_loop, m.rate_damping) == (True, True, True, False)
    m.request(0, Mode.SAFE, "fdir")
    assert (m.jets_enabled, m.adaptation_enabled, m.closed_loop, m.rate_damping) == (True, False, False, True)


def test_requests_by_name_and_garbage():
    ev = EventLog()
    m = ModeManager(ev)
    assert m.request(0, "entry", "ground") and m.mode == Mode.ENTRY
    assert not m.request(0, "warp", "ground") and not m.request(0, 7, "ground") and m.mode == Mode.ENTRY
    assert all(len(e.text) <= 50 for e in ev.history)


def failsafes(**over):
    p = load_params(Failsafes.PARAMS)
    p.update(over)
    m = ModeManager(EventLog())
    m.request(0.0, Mode.ENTRY, "go")
    return Failsafes(p, m), m, p


def test_tracking_error_beyond_limit_for_the_persistence_goes_safe():
    fs, m, p = failsafes()
    dt = 0.02
    big = math.radians(p["fdir.safe_track_deg"]) * 1.1
    n_needed = math.ceil(p["fdir.safe_track_s"] / dt - 1e-9)
    for i in range(n_needed - 1):
        assert fs.evaluate(i * dt, dt, sensors_stale=False, tracking_error_rad=big) == FailsafeAction.NONE
    # one good sample resets the timer
    assert fs.evaluate(1.0, dt, sensors_stale=False, tracking_error_rad=0.0) == FailsafeAction.NONE
    acts = [fs.evaluate(2.0 + i * dt, dt, sensors_stale=False, tracking_error_rad=big) for i in range(n_needed)]
    assert acts[:-1] == [FailsafeAction.NONE] * (n_needed - 1) and acts[-1] == FailsafeAction.SAFE
    assert m.mode == Mode.SAFE and fs.last_rule == "tracking_error"


def test_stale_sensors_hold_jets_off_first_and_leave_mode_alone():
    fs, m, _ = failsafes(**{"fdir.safe_track_s": 0.0})
    assert fs.evaluate(0.0, 0.02, sensors_stale=True, tracking_error_rad=math.nan) == FailsafeAction.HOLD_JETS_OFF
    assert m.mode == Mode.ENTRY
    # a non-finite tracking error counts as beyond the limit
    assert fs.evaluate(0.02, 0.02, sensors_stale=False, tracking_error_rad=math.nan) == FailsafeAction.SAFE


def test_failsafe_params_validated():
    with pytest.raises(ValueError):
        failsafes(**{"fdir.safe_track_deg": -1.0})
