"""BankProfile: C2 continuity (finite differences), rate and acceleration limits, steps reached,
queued steps, validation."""
import math

import numpy as np
import pytest

from common.model import load_scenario
from fsw.guidance.reference import BankProfile

D = math.radians


def _grid(p, t_end, dt=1e-3):
    t = np.arange(0.0, t_end, dt)
    out = np.array([p.evaluate(x) for x in t])
    return t, out[:, 0], out[:, 1], out[:, 2]


@pytest.fixture(scope="module")
def nominal_profile():
    sc = load_scenario("nominal")
    return BankProfile(sc.bank_schedule, sc.bank_rate_limit_radps, sc.bank_accel_limit_radps2), sc


def test_profile_derivatives_match_finite_differences_and_are_continuous(nominal_profile):
    p, _ = nominal_profile
    dt = 1e-3
    t, phi, phid, phidd = _grid(p, 420.0, dt)
    # central differences of the analytic values reproduce the analytic derivatives
    fd1 = (phi[2:] - phi[:-2]) / (2 * dt)
    fd2 = (phid[2:] - phid[:-2]) / (2 * dt)
    assert np.max(np.abs(fd1 - phid[1:-1])) < 1e-6
    # (the jerk jumps at a transition's ends: the difference there is jerk * dt / 2 ~ 1.4e-6)
    assert np.max(np.abs(fd2 - phidd[1:-1])) < 5e-6
    # no jumps anywhere (C2): successive samples differ by at most (bound of next derivative) * dt
    assert np.max(np.abs(np.diff(phi))) <= p.rate_limit_radps * dt * (1 + 1e-9)
    assert np.max(np.abs(np.diff(phid))) <= p.accel_limit_radps2 * dt * (1 + 1e-9)
    jerk_bound = 60.0 * max(abs(d) for _, _, a, b in p.transitions() for d in [b - a]) / min(
        T for _, T, _, _ in p.transitions()) ** 3
    assert np.max(np.abs(np.diff(phidd))) <= jerk_bound * dt * (1 + 1e-9)


def test_profile_respects_limits_and_one_limit_is_active(nominal_profile):
    p, sc = nominal_profile
    t, phi, phid, phidd = _grid(p, 420.0, 1e-3)
    assert np.max(np.abs(phid)) <= sc.bank_rate_limit_radps * (1 + 1e-9)
    assert np.max(np.abs(phidd)) <= sc.bank_accel_limit_radps2 * (1 + 1e-9)
    for t0, T, a, b in p.transitions():
        m = (t >= t0) & (t <= t0 + T)
        rate_use = np.max(np.abs(phid[m])) / sc.bank_rate_limit_radps
        acc_use = np.max(np.abs(phidd[m])) / sc.bank_accel_limit_radps2
        assert max(rate_use, acc_use) > 0.999      # the duration is the shortest the limits allow


def test_profile_starts_at_first_step_and_reaches_every_step(nominal_profile):
    p, sc = nominal_profile
    assert p.evaluate(0.0) == (sc.bank_schedule[0][1], 0.0, 0.0)
    assert p.evaluate(-1.0)[0] == sc.bank_schedule[0][1]
    tr = p.transitions()
    assert len(tr) == len(sc.bank_schedule) - 1
    assert p.lag_s == 0.0                          # the nominal steps are far enough apart
    for (ts, bank), (t0, T, a, b) in zip(sc.bank_schedule[1:], tr):
        assert t0 == ts and b == bank
        phi, phid, phidd = p.evaluate(t0 + T)
        assert phi == pytest.approx(bank, abs=1e-12) and abs(phid) < 1e-12 and abs(phidd) < 1e-12
        assert p.evaluate(t0 + T + 1e-9) == (bank, 0.0, 0.0)
        assert p.evaluate(t0 + T - 1e-9)[0] == pytest.approx(bank, abs=1e-9)
        # just before the step the reference still holds the previous target
        assert p.evaluate(t0 - 1e-9)[0] == pytest.approx(a, abs=1e-12)
    # reversal 85 -> -85 goes through zero (lift up), not through 180
    t0, T, a, b = tr[0]
    mid = np.array([p.evaluate(t0 + x * T)[0] for x in np.linspace(0, 1, 101)])
    assert np.all(np.abs(mid) <= D(85) + 1e-12)


def test_close_steps_are_queued_and_stay_within_limits():
    sched = [(0.0, D(30)), (5.0, D(-30)), (6.0, D(60)), (7.0, D(60)), (50.0, D(0))]
    p = BankProfile(sched, D(8), D(1))
    tr = p.transitions()
    assert len(tr) == 3                            # the repeated 60 deg step adds nothing
    for (t0a, Ta, _, _), (t0b, _, _, _) in zip(tr, tr[1:]):
        assert t0b >= t0a + Ta - 1e-12             # never overlapping
    assert p.lag_s > 0
    t, phi, phid, phidd = _grid(p, 120.0, 1e-3)
    assert np.max(np.abs(phid)) <= D(8) * (1 + 1e-9)
    assert np.max(np.abs(phidd)) <= D(1) * (1 + 1e-9)
    assert np.max(np.abs(np.diff(phid))) <= D(1) * 1e-3 * (1 + 1e-9)
    assert phi[-1] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("sched, rate, acc, field", [
    ([], 0.1, 0.1, "schedule"),
    ([(1.0, 0.0)], 0.1, 0.1, "t = 0"),
    ([(0.0, 0.0), (0.0, 0.1)], 0.1, 0.1, "increase"),
    ([(0.0, float("nan"))], 0.1, 0.1, "finite"),
    ([(0.0, 4.0)], 0.1, 0.1, "pi"),
    ([(0.0, 0.0)], 0.0, 0.1, "rate_limit"),
    ([(0.0, 0.0)], 0.1, float("inf"), "accel_limit"),
    ([(0.0,)], 0.1, 0.1, "entry 1"),
])
def test_bad_profile_input_is_rejected_with_a_named_field(sched, rate, acc, field):
    with pytest.raises(ValueError, match=field):
        BankProfile(sched, rate, acc)
