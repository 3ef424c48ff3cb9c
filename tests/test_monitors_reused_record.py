"""Sensor monitor fed the same record object every period (the batch runner hands it the
plant's one SENSORS record): each check sees the record's current contents, and a record
made read-only or re-shaped since the last check is rejected as before."""
from __future__ import annotations

import numpy as np

from common.events import EventLog
from fsw.monitors import SensorMonitor
from interfaces.records import SENSORS, new
from tests.test_monitors_frames import DT, R_MARS, fill


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
