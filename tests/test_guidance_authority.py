"""Guidance that knows its actuators: re-planning the bank profile with new limits, and
the roll authority the FSW measures through its allocator."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.model import load_scenario
from fsw.flightsoftware import FlightSoftware
from fsw.guidance import BankProfile
from fsw.health import FAILED_OFF, STUCK_ON

SC = load_scenario("case2")


def _profile():
    return BankProfile(SC.bank_schedule, SC.bank_rate_limit_radps, SC.bank_accel_limit_radps2)


def test_replan_keeps_started_transitions_and_reshapes_later_ones():
    p, ref = _profile(), _profile()
    assert p.replan(65.0, SC.bank_rate_limit_radps, math.radians(0.5))
    old, new = ref.transitions(), p.transitions()
    assert new[0] == old[0]                               # running at 65 s: flown as planned
    for a, b in zip(old[1:], new[1:]):
        assert b[3] == a[3] and b[1] >= a[1]              # same targets, never faster
    assert any(b[1] > a[1] * 1.05 for a, b in zip(old[1:], new[1:]))
    # the re-planned reference is still C2 and within the new acceleration limit after 65 s
    ts = np.arange(0.0, 600.0, 0.005)
    v = np.array([p.evaluate(t) for t in ts])
    assert np.max(np.abs(np.diff(v[:, 0]))) < 1e-3 and np.max(np.abs(np.diff(v[:, 1]))) < 1e-4
    late = ts > new[0][0] + new[0][1]
    assert np.max(np.abs(v[late, 2])) <= math.radians(0.5) * (1 + 1e-9)


def test_replan_with_the_same_limits_changes_nothing():
    p = _profile()
    before = p.transitions()
    assert not p.replan(10.0, p.rate_limit_radps, p.accel_limit_radps2)
    assert p.transitions() == before


def test_replan_rejects_bad_limits():
    with pytest.raises(ValueError, match="accel_limit"):
        _profile().replan(1.0, 0.1, float("nan"))


def _fsw(jets, state, factor):
    f = FlightSoftware(SC, param_overrides={"guidance": {"authority_factor": factor}})
    for j in jets:
        f.fdir.health_active.set(j, state)
    f.health_changed()
    return f


def test_roll_authority_matches_the_torque_matrix():
    """Healthy: +-140.48 N m (jets 3+4+9+10+15+16 one way, 1+6+7+12+13+18 the other, spec
    10-plant.md). With case 1's failures the negative side shrinks; the answer is the
    allocator's exact jet set, checked against the torque-matrix columns."""
    f = FlightSoftware(SC)
    pos, neg = f.roll_authority_Nm()
    assert pos == pytest.approx(140.48) and neg == pytest.approx(140.48)
    f1 = _fsw([1, 2, 17, 18], FAILED_OFF, 0.7)
    pos1, neg1 = f1.roll_authority_Nm()
    T = SC.vehicle.torque_matrix_Nm
    assert pos1 == pytest.approx(140.48)                  # jets 3, 4, 9, 10, 15, 16 untouched
    assert neg1 < 140.48 and neg1 == pytest.approx(-float(f1.allocator.tau_B[0]))
    # the answer is a real jet set: its torque is a sum of usable columns
    u = f1.allocator.u.astype(bool)
    assert not u[[0, 1, 16, 17]].any()
    assert np.allclose(T[:, u].sum(axis=1), f1.allocator.tau_B)


def test_reference_reshaped_only_when_the_jets_cannot_follow():
    f1 = _fsw([1, 2, 17, 18], FAILED_OFF, 0.7)          # case 1: 70 N m one way is enough for 1 deg/s^2
    f1.fit_reference_to_authority(3.0)
    assert f1.guidance.profile.accel_limit_radps2 == SC.bank_accel_limit_radps2
    f2 = _fsw([2, 3, 4, 5, 8, 9, 10], STUCK_ON, 0.7)    # case 2: ~9 N m of net negative roll
    f2.fit_reference_to_authority(3.0)
    assert f2.guidance.profile.accel_limit_radps2 < 0.3 * SC.bank_accel_limit_radps2
    assert any(e.code == "reference_reshaped" for e in f2.events.history)
    f0 = _fsw([2, 3, 4, 5, 8, 9, 10], STUCK_ON, 0.0)    # factor 0: the feature is off
    f0.fit_reference_to_authority(3.0)
    assert f0.guidance.profile.accel_limit_radps2 == SC.bank_accel_limit_radps2


def test_default_factor_reshapes_case2_and_leaves_case1_alone():
    """data/fsw/default.toml's factor (3.5): case 2's 8.9 N m one way -> 3.5 x 0.19 deg/s^2;
    case 1 (70 N m one way) keeps the scenario's 1 deg/s^2."""
    dflt = FlightSoftware(SC).params["guidance.authority_factor"]
    assert dflt == pytest.approx(3.5)
    f2 = FlightSoftware(SC)
    for j in (2, 3, 4, 5, 8, 9, 10):
        f2.fdir.health_active.set(j, STUCK_ON)
    f2.health_changed()
    f2.fit_reference_to_authority(3.0)
    assert np.degrees(f2.guidance.profile.accel_limit_radps2) == pytest.approx(0.67, abs=0.02)
    f1 = FlightSoftware(SC)
    for j in (1, 2, 17, 18):
        f1.fdir.health_active.set(j, FAILED_OFF)
    f1.health_changed()
    f1.fit_reference_to_authority(3.0)
    assert f1.guidance.profile.accel_limit_radps2 == SC.bank_accel_limit_radps2
