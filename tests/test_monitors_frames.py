"""Sensor-frame monitor: rejections by reason, staleness within 3 periods, recovery; one
record object refilled every period."""
from __future__ import annotations

import numpy as np
import pytest

from common.events import EventLog, Severity
from fsw.monitors import SensorMonitor
from interfaces.records import JETS, SENSORS, new

DT = 0.02
R_MARS = 3396.2e3


def fill(f, k_step):
    """A credible frame of step k_step, written into the record f."""
    f["k"] = k_step
    f["t_ns"] = int(k_step * DT * 1e9)
    f["omega_BN_B"][:] = [0.01, -0.02, 0.005]
    f["sigma_BN"][:] = [0.1, 0.2, -0.3]
    f["r_N"][:] = [R_MARS + 125e3, 0.0, 0.0]
    f["v_N"][:] = [-1500.0, 7000.0, 0.0]
    f["accel_B"][:] = [-3.0, 0.0, 1.0]
    f["chamber"][:] = 0.01
    return f


def frame(k_step, **fields):
    f = fill(new(SENSORS), k_step)
    for name, v in fields.items():
        f[name][...] = v
    return f


def monitor():
    ev = EventLog()
    return SensorMonitor(ev, DT, radius_m=R_MARS), ev


def test_good_frames_pass():
    m, ev = monitor()
    assert all(m.check(k * DT, frame(k)) for k in range(10))
    assert m.accepted == 10 and sum(m.counts.values()) == 0 and not m.stale and ev.history == []


@pytest.mark.parametrize("field,value,reason", [
    ("omega_BN_B", [np.nan, 0, 0], "nonfinite"),
    ("sigma_BN", [0, np.inf, 0], "nonfinite"),
    ("r_N", [np.nan] * 3, "nonfinite"),
    ("accel_B", [0, 0, -np.inf], "nonfinite"),
    ("omega_BN_B", [3.0, 0, 0], "range"),
    ("sigma_BN", [0.8, 0.8, 0], "range"),              # |sigma| = 1.13
    ("r_N", [R_MARS - 10e3, 0, 0], "range"),            # 10 km underground
    ("r_N", [1e12, 0, 0], "range"),
    ("r_N", [0.0, 0, 0], "range"),
    ("v_N", [1e5, 0, 0], "range"),
    ("accel_B", [5000.0, 0, 0], "range"),
    ("k", -4, "range"),
])
def test_bad_frames_are_rejected_and_counted(field, value, reason):
    m, ev = monitor()
    assert m.check(0.0, frame(0))
    assert not m.check(DT, frame(1, **{field: value}))
    assert m.counts[reason] == 1 and sum(m.counts.values()) == 1
    assert ev.history[-1].severity == Severity.WARNING and ev.history[-1].code == f"frame_{reason}"
    assert m.last_k == 0


def test_duplicates_and_out_of_order_rejected_and_counted():
    m, _ = monitor()
    for k in (0, 1, 2):
        assert m.check(k * DT, frame(k))
    assert not m.check(0.06, frame(2))
    assert not m.check(0.06, frame(1))
    assert m.check(0.06, frame(4))                      # a gap is fine: newer data
    assert m.counts["duplicate"] == 1 and m.counts["out_of_order"] == 1 and m.last_k == 4


def test_wrong_record_type_rejected():
    m, _ = monitor()
    assert not m.check(0.0, new(JETS))
    assert not m.check(0.0, "frame")
    assert not m.check(0.0, np.zeros((2,), dtype=SENSORS))
    assert m.counts["format"] == 3


def test_stale_within_three_periods_holds_jets_and_recovers():
    m, ev = monitor()
    assert m.check(0.0, frame(0))
    m.tick(DT, got_frame=False)
    m.tick(2 * DT, got_frame=False)
    assert not m.stale and not m.jets_must_hold_off
    m.tick(3 * DT, got_frame=False)
    assert m.stale and m.jets_must_hold_off
    stale_ev = [e for e in ev.history if e.code == "sensors_stale"]
    assert len(stale_ev) == 1 and stale_ev[0].severity == Severity.ERROR and stale_ev[0].t_s == pytest.approx(3 * DT)
    m.tick(4 * DT)                                       # stays stale, no new event
    assert len([e for e in ev.history if e.code == "sensors_stale"]) == 1
    assert m.check(5 * DT, frame(5))
    assert not m.stale and not m.jets_must_hold_off
    rec = [e for e in ev.history if e.code == "sensors_recovered"]
    assert len(rec) == 1 and rec[0].severity == Severity.NOTICE


def test_repeated_old_frames_make_the_monitor_stale():
    """Lockstep with a stuck publisher: k not increasing counts as no fresh data."""
    m, _ = monitor()
    assert m.check(0.0, frame(7))
    for i in range(3):
        assert not m.check((i + 1) * DT, frame(7))
    assert m.stale and m.counts["duplicate"] == 3
    m.tick(0.1, got_frame=True)                          # a frame arrived: tick does not count
    assert m.missed == 3


def test_bad_chamber_entries_are_masked_not_fatal():
    m, ev = monitor()
    ch = np.full(18, 0.02)
    ch[4] = np.nan
    ch[9] = 3.0
    ch[10] = -0.7
    f = frame(0, chamber=ch)
    assert m.check(0.0, f)
    assert np.isnan(f["chamber"][[4, 9, 10]]).all()
    assert np.isfinite(np.delete(f["chamber"], [4, 9, 10])).all()
    assert m.counts["chamber_nonfinite"] == 1 and m.counts["chamber_range"] == 2
    assert {e.code for e in ev.history} == {"chamber_nonfinite", "chamber_range"}


def test_params_loaded_by_default_and_validated():
    m = SensorMonitor(EventLog(), DT)
    assert m.stale_n == 3
    from fsw.params import load_params
    p = load_params(SensorMonitor.PARAMS)
    p["fdir.stale_s"] = 0
    with pytest.raises(ValueError, match="stale_s"):
        SensorMonitor(EventLog(), DT, p)
    with pytest.raises(ValueError, match="dt_s"):
        SensorMonitor(EventLog(), -1.0)


# ---------------------------------------------------------------- one record reused every period
# The batch runner hands the monitor the plant's one SENSORS record each period: each check
# sees the record's current contents, and a record made read-only or re-shaped since the last
# check is rejected as before.

def test_one_record_refilled_each_period_is_checked_afresh():
    m = SensorMonitor(EventLog(), DT, radius_m=R_MARS)
    f = fill(new(SENSORS), 0)
    assert m.check(0.0, f)
    fill(f, 1)
    f["r_N"][0] = R_MARS - 50e3                    # underground: range
    assert not m.check(DT, f) and m.counts["range"] == 1
    fill(f, 2)
    f["chamber"][4] = 99.0                          # one bad transducer: NaN in place, frame kept
    assert m.check(2 * DT, f) and np.isnan(f["chamber"][4]) and m.counts["chamber_range"] == 1
    assert not m.check(3 * DT, f) and m.counts["duplicate"] == 1     # k not advanced: k read afresh
    fill(f, 3)
    f["omega_BN_B"][1] = np.nan
    assert not m.check(3 * DT, f) and m.counts["nonfinite"] == 1
    g = fill(new(SENSORS), 4)                       # another record, then the first one again
    assert m.check(4 * DT, g)
    fill(f, 5)
    assert m.check(5 * DT, f) and m.last_k == 5 and m.accepted == 4


def test_a_record_made_read_only_or_reshaped_is_rejected_untouched():
    m = SensorMonitor(EventLog(), DT, radius_m=R_MARS)
    f = fill(new(SENSORS), 0)
    assert m.check(0.0, f)
    fill(f, 1)
    f["chamber"][0] = 99.0
    f.flags.writeable = False
    assert not m.check(DT, f) and m.counts["format"] == 1
    assert f["chamber"][0] == 99.0
    f.flags.writeable = True
    assert m.check(DT, f) and np.isnan(f["chamber"][0])
    fill(f, 2)
    f.shape = (1,)
    assert not m.check(2 * DT, f) and m.counts["format"] == 2


def test_stale_after_the_same_time_at_any_control_rate():
    assert SensorMonitor(EventLog(), 0.02).stale_n == 3              # 0.06 s at 50 Hz
    assert SensorMonitor(EventLog(), 0.005).stale_n == 12            # ... and at 200 Hz
