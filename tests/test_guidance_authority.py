"""Guidance that knows its actuators: re-planning the bank profile with new limits (the running
transition included), from the controllability LP the FSW runs at every reconfiguration."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.model import load_scenario
from fsw.flightsoftware import FlightSoftware
from fsw.guidance import BankProfile
from fsw.health import JetHealth

SC = load_scenario("case2")


def _profile():
    return BankProfile(SC.bank_schedule, SC.bank_rate_limit_radps, SC.bank_accel_limit_radps2)


def _check_c2_within(p, t_from, accel_limit, t_end=700.0):
    ts = np.arange(0.0, t_end, 0.005)
    v = np.array([p.evaluate(t) for t in ts])
    # C2: no jump in phi, phidot or phiddot anywhere (steps of 5 ms)
    assert np.max(np.abs(np.diff(v[:, 0]))) < 1e-3 and np.max(np.abs(np.diff(v[:, 1]))) < 1e-4
    assert np.max(np.abs(np.diff(v[:, 2]))) < 1e-4
    late = ts >= t_from
    assert np.max(np.abs(v[late, 2])) <= accel_limit * (1 + 1e-6)
    return ts, v


def test_replan_between_transitions_reshapes_the_later_ones():
    p, ref = _profile(), _profile()
    assert p.replan(110.0, SC.bank_rate_limit_radps, math.radians(0.5))   # the first reversal is over
    old, new = ref.transitions(), p.transitions()
    assert new[0] == old[0] and len(new) == len(old)
    for a, b in zip(old[1:], new[1:]):
        assert b[3] == a[3] and b[1] >= a[1]              # same targets, never faster
    assert any(b[1] > a[1] * 1.05 for a, b in zip(old[1:], new[1:]))
    _check_c2_within(p, 110.0, math.radians(0.5))


def test_replan_continues_the_running_transition_from_its_state_within_the_new_limits():
    p, ref = _profile(), _profile()
    t0, T, a, b = ref.transitions()[0]
    t_now = t0 + 0.5 * T                                   # mid-reversal: at its peak rate
    phi, rate, acc = ref.evaluate(t_now)
    assert abs(rate) > math.radians(1.0)
    lim = math.radians(0.6)
    assert abs(acc) < lim                                  # so the new limit can hold from t_now on
    assert p.replan(t_now, SC.bank_rate_limit_radps, lim)
    tr = p.transitions()
    assert tr[0] == ref.transitions()[0]                   # flown before t_now: unchanged
    assert tr[1][0] == t_now and tr[1][2] == pytest.approx(phi) and tr[1][3] == b
    assert p.evaluate(t_now - 1e-9)[1] == pytest.approx(rate, rel=1e-6)
    ts, v = _check_c2_within(p, t_now, lim)
    # every later step is still reached, in order
    for t_start, dur, _, target in tr[1:]:
        assert p.evaluate(t_start + dur + 1e-6)[0] == pytest.approx(target)
    assert tr[1][1] > T * 0.7                              # slower than the rest of the old transition


def test_replan_with_the_same_limits_changes_nothing():
    p = _profile()
    before = p.transitions()
    assert not p.replan(10.0, p.rate_limit_radps, p.accel_limit_radps2)
    assert p.transitions() == before


def test_replan_rejects_bad_limits():
    with pytest.raises(ValueError, match="accel_limit"):
        _profile().replan(1.0, 0.1, float("nan"))


def _fsw(health, **over):
    f = FlightSoftware(SC, param_overrides={"guidance": over} if over else None)
    f.fdir.health_active = health
    f.t_s = 3.0
    f.health_changed()
    return f


def test_reconfiguration_reports_the_lp_and_reshapes_to_its_weaker_way():
    from fsw.controllability import controllability, velocity_dir_B
    h2 = JetHealth.of(stuck=[2, 3, 4, 5, 8, 9, 10])       # case 2
    f2 = _fsw(h2)
    r = f2.controllability
    assert r is not None and r.controllable
    # the same LP, asked directly with the FSW's models before flight (qbar 0, trim direction)
    ref = controllability(SC.vehicle.torque_matrix_Nm, h2, f2.control.inertia_hat(),
                          velocity_dir_B(SC.vehicle.aero.alpha_trim_rad), np.zeros((3, 2)), 5.0, 0.0)
    assert r.authority_neg_radps2 == pytest.approx(ref.authority_neg_radps2)
    weak = min(r.authority_pos_radps2, r.authority_neg_radps2)
    use = f2.params["guidance.authority_use"]
    assert f2.guidance.profile.accel_limit_radps2 == pytest.approx(use * weak)
    texts = [e.text for e in f2.events.history if e.code == "controllability"]
    assert texts and texts[-1].startswith("AUTH +") and len(texts[-1]) <= 50
    assert any(e.code == "reference_reshaped" for e in f2.events.history)
    f1 = _fsw(JetHealth.of(failed=[1, 2, 17, 18]))         # case 1: half its weaker way is above 1 deg/s^2
    assert f1.guidance.profile.accel_limit_radps2 == SC.bank_accel_limit_radps2
    assert not any(e.code == "reference_reshaped" for e in f1.events.history)


def test_no_authority_one_way_keeps_the_schedule_pace_and_says_so():
    from fsw.controllability import schedule_accel_need_radps2
    h = JetHealth.of(failed=[6, 16], stuck=[15], degraded=[(7, .5), (13, .5)])   # no trim at qbar 0
    f = _fsw(h)
    assert not f.controllability.controllable
    codes = [e.code for e in f.events.history]
    assert "not_controllable" in codes and "authority_low" in codes
    need = schedule_accel_need_radps2(SC.bank_schedule, 3.0)
    assert need > math.radians(0.1)
    assert f.guidance.profile.accel_limit_radps2 == pytest.approx(need)


def test_the_lp_runs_off_the_loop_in_real_time_and_is_applied_when_ready():
    f = FlightSoftware(SC, realtime=True)
    try:
        f.fdir.health_active = JetHealth.of(stuck=[2, 3, 4, 5, 8, 9, 10])
        f.t_s = 3.0
        f.health_changed()
        assert f.controllability is None or f._lp_worker is not None
        import time
        t_end = time.monotonic() + 10.0
        while not f._lp_worker.ready() and time.monotonic() < t_end:
            time.sleep(0.01)
        need, r = f._lp_worker.take()
        f._apply_controllability(3.5, need, r)
        assert f.controllability is r and f.guidance.profile.accel_limit_radps2 < SC.bank_accel_limit_radps2
    finally:
        f.close()
