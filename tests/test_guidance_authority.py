"""Guidance that knows its actuators: re-planning the bank profile with new limits (the running
transition included), from the controllability LP the FSW runs at every reconfiguration."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.model import load_scenario
from fsw.flightsoftware import FlightSoftware
from fsw.guidance.reference import BankProfile, _bang_bang
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


def _time_optimal_by_feedback(x, v, x1, rate_limit, accel_limit, dt=1e-3):
    """Independent truth for the continuation: fly a double integrator (|a| <= A) on the
    braking-curve feedback v_cmd = sign(e) min(R, sqrt(2 A |e|)) until it rests on x1;
    (arrival time, highest and lowest x)."""
    t, hi, lo = 0.0, x, x
    while t < 1000.0:
        e = x1 - x
        a = min(accel_limit, max(-accel_limit, (math.copysign(min(rate_limit, math.sqrt(2 * accel_limit * abs(e))), e)
                                                - v) / dt))
        x, v, t = x + v * dt + 0.5 * a * dt * dt, v + a * dt, t + dt
        hi, lo = max(hi, x), min(lo, x)
        if abs(x1 - x) < 1e-4 and abs(v) < 1e-3:
            break
    return t, hi, lo


D = math.radians


@pytest.mark.parametrize("phi, rate, target, rate_limit, accel_limit", [
    (D(-43.4), D(6.3), D(60.0), D(8.0), D(0.42)),     # campaign run 19's reversal at its reconfiguration
    (0.0, D(10.0), D(100.0), D(8.0), D(0.5)),         # faster than the rate limit, room to brake
    (0.0, D(-3.0), D(20.0), D(8.0), D(0.5)),          # moving away from the target
    (0.0, D(5.0), D(10.0), D(8.0), D(0.5)),           # cannot stop before the target: passes it by 15 deg
    (0.0, 0.0, D(30.0), D(2.0), D(1.0)),              # at rest, the rate limit active
    (D(20.0), D(-12.0), D(-80.0), D(8.0), D(1.0)),    # negative way, above the rate limit
])
def test_continuation_from_a_moving_state_is_the_time_optimal_path(phi, rate, target, rate_limit, accel_limit):
    pieces = _bang_bang(phi, rate, target, rate_limit, accel_limit)
    T = sum(pc[0] for pc in pieces)
    ts = np.concatenate([np.linspace(0.0, pc[0], 400) + sum(q[0] for q in pieces[:i]) for i, pc in enumerate(pieces)])
    x = np.array([_eval_piece(pieces, t) for t in ts])
    end = _eval_piece(pieces, T)
    assert end[0] == pytest.approx(target, abs=1e-12) and end[1] == pytest.approx(0.0, abs=1e-12)
    # rate continuous (pieces join), acceleration within the limit, rate within the state's or the limit
    for i in range(1, len(pieces)):
        t_j = sum(q[0] for q in pieces[:i])
        assert pieces[i][2] == pytest.approx(pieces[i - 1][2] + pieces[i - 1][3] * pieces[i - 1][0], abs=1e-12)
        assert pieces[i][1] == pytest.approx(_eval_piece(pieces[:i], t_j)[0], abs=1e-12)
    assert np.max(np.abs(x[:, 2])) <= accel_limit * (1 + 1e-12)
    assert np.max(np.abs(x[:, 1])) <= max(rate_limit, abs(rate)) * (1 + 1e-12)
    # overshoot: only what braking at once from this rate forces (v^2 / 2A past the target)
    forced = max(0.0, math.copysign(1.0, rate) * (phi + rate * abs(rate) / (2 * accel_limit) - target)) if rate else 0.0
    beyond = np.max(np.sign(target - phi) * (x[:, 0] - target)) if target != phi else 0.0
    assert beyond <= forced + 1e-9
    t_fb, hi, lo = _time_optimal_by_feedback(phi, rate, target, rate_limit, accel_limit)
    assert T == pytest.approx(t_fb, abs=0.3)                # same arrival (the feedback's lag is < 0.3 s)
    assert np.max(x[:, 0]) == pytest.approx(hi, abs=1e-3) and np.min(x[:, 0]) == pytest.approx(lo, abs=1e-3)


def _eval_piece(pieces, t):
    t0 = 0.0
    for i, (T, p, v, a) in enumerate(pieces):
        if t <= t0 + T or i == len(pieces) - 1:
            tau = t - t0
            return p + v * tau + 0.5 * a * tau * tau, v + a * tau, a
        t0 += T
    return None


def test_replan_continues_the_running_transition_from_its_state_within_the_new_limits():
    p, ref = _profile(), _profile()
    t0, T, a, b = ref.transitions()[0]
    t_now = t0 + 0.5 * T                                   # mid-reversal: at its peak rate
    phi, rate, acc = ref.evaluate(t_now)
    assert abs(rate) > math.radians(1.0)
    lim = math.radians(0.6)
    assert p.replan(t_now, SC.bank_rate_limit_radps, lim)
    tr = p.transitions()
    assert tr[0] == ref.transitions()[0]                   # flown before t_now: unchanged
    assert tr[1][0] == t_now and tr[1][2] == pytest.approx(phi) and tr[1][3] == b
    assert p.evaluate(t_now - 1e-9)[1] == pytest.approx(rate, rel=1e-6)
    _check_continuation(p, t_now, lim, (a, b), rate)
    # every later step is still reached, in order
    for t_start, dur, _, target in tr[1:]:
        assert p.evaluate(t_start + dur + 1e-6)[0] == pytest.approx(target)
    assert tr[1][1] == pytest.approx(sum(pc[0] for pc in _bang_bang(phi, rate, b, SC.bank_rate_limit_radps, lim)))


@pytest.mark.parametrize("frac, lim_deg", [(0.3, 0.05), (0.5, 0.05), (0.7, 0.02), (0.5, 5.0)])
def test_replan_mid_reversal_at_a_far_lower_limit_stays_bounded(frac, lim_deg):
    """A reversal running fast when the new limit is a small fraction of the old (a single
    quintic to rest has no feasible duration there): the reference still ends on the same
    target, no further past it than braking at the new limit forces, and within the limits."""
    p, ref = _profile(), _profile()
    t0, T, a, b = ref.transitions()[0]
    t_now = t0 + frac * T
    phi, rate, acc = ref.evaluate(t_now)
    lim = math.radians(lim_deg)
    assert p.replan(t_now, SC.bank_rate_limit_radps, lim)
    _check_continuation(p, t_now, lim, (a, b), rate)
    # replanned again inside the continuation (back to the old limit): continues from there
    t_mid = t_now + 0.4 * p.transitions()[1][1]
    mid = p.evaluate(t_mid)
    assert p.replan(t_mid, SC.bank_rate_limit_radps, SC.bank_accel_limit_radps2)
    assert p.evaluate(t_mid)[:2] == pytest.approx(mid[:2])
    _check_continuation(p, t_mid, SC.bank_accel_limit_radps2, (a, b), mid[1])


def _check_continuation(p, t_from, accel_limit, ab, rate, t_end=1500.0):
    """C1 everywhere (the acceleration steps only inside a continuation), within the limits from
    t_from, never further past the target than braking at once from ``rate`` forces, and at rest
    on the target at the end of the continuation."""
    a, b = ab
    ts = np.arange(0.0, t_end, 0.005)
    v = np.array([p.evaluate(t) for t in ts])
    assert np.max(np.abs(np.diff(v[:, 0]))) < 1e-3
    assert np.max(np.abs(np.diff(v[:, 1]))) <= max(accel_limit, SC.bank_accel_limit_radps2) * 0.005 * (1 + 1e-6)
    late = ts >= t_from
    assert np.max(np.abs(v[late, 2])) <= accel_limit * (1 + 1e-9)
    assert np.max(np.abs(v[:, 1])) <= SC.bank_rate_limit_radps * (1 + 1e-9)
    sg, phi = math.copysign(1.0, b - a), p.evaluate(t_from)[0]
    forced = max(0.0, sg * (phi + rate * abs(rate) / (2 * accel_limit) - b), sg * (phi - b))
    cont = p.transitions()[1]
    during = late & (ts <= cont[0] + cont[1])
    assert np.max(sg * (v[during, 0] - b)) <= forced + 1e-9
    assert p.evaluate(cont[0] + cont[1] + 1e-9)[:2] == pytest.approx((b, 0.0), abs=1e-9)
    bound = max(abs(x) for _, x in SC.bank_schedule) + forced
    assert np.max(np.abs(v[:, 0])) <= bound + 1e-9


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
    h2 = JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10])       # case 2
    f2 = _fsw(h2)
    r = f2.controllability
    assert r is not None and r.controllable
    # the same LP, asked directly with the FSW's models before flight (qbar 0, trim direction)
    ref = controllability(SC.vehicle.torque_matrix_Nm, h2, SC.vehicle.inertia_kgm2,
                          velocity_dir_B(SC.vehicle.aero.alpha_trim_rad), np.zeros((3, 2)), 5.0, 0.0,
                          inertia_unc_frac=SC.vehicle.inertia_uncertainty_frac)
    assert r.authority_neg_radps2 == pytest.approx(ref.authority_neg_radps2)
    weak = min(r.authority_pos_radps2, r.authority_neg_radps2)
    use = f2.params["guidance.authority_use"]
    assert f2.guidance.profile.accel_limit_radps2 == pytest.approx(use * weak)
    texts = [e.text for e in f2.events.history if e.code == "controllability"]
    assert texts and texts[-1].startswith("AUTH +") and len(texts[-1]) <= 50
    assert any(e.code == "reference_reshaped" for e in f2.events.history)
    f1 = _fsw(JetHealth.of(failed_off=[1, 2, 17, 18]))         # case 1: half its weaker way is above 1 deg/s^2
    assert f1.guidance.profile.accel_limit_radps2 == SC.bank_accel_limit_radps2
    assert not any(e.code == "reference_reshaped" for e in f1.events.history)


def test_an_answer_equal_to_the_event_precision_does_not_reshape_the_reference_again():
    """Equal LPs answer in their last bits differently; a re-plan to a limit that reads the same
    (0.01 deg/s^2, the event's precision) is no new reference and is not announced again."""
    import dataclasses
    f = _fsw(JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10]))       # case 2: reshaped once
    r = f.controllability
    limit = f.guidance.profile.accel_limit_radps2
    n = sum(e.code == "reference_reshaped" for e in f.events.history)
    assert n == 1
    for k, scale in enumerate((1 + 1e-12, 1 - 1e-9, 1 + 1e-4)):
        f.authority._replan_to(4.0 + k, 0.0, dataclasses.replace(r, authority_neg_radps2=r.authority_neg_radps2 * scale))
    assert sum(e.code == "reference_reshaped" for e in f.events.history) == n
    assert f.guidance.profile.accel_limit_radps2 == limit
    f.authority._replan_to(8.0, 0.0, dataclasses.replace(r, authority_neg_radps2=r.authority_neg_radps2 * 0.9))
    assert sum(e.code == "reference_reshaped" for e in f.events.history) == n + 1
    assert f.guidance.profile.accel_limit_radps2 == pytest.approx(0.9 * limit)
    f.close()


def test_no_authority_one_way_keeps_the_schedule_pace_and_says_so():
    from fsw.controllability import schedule_accel_need_radps2
    h = JetHealth.of(failed_off=[6, 16], stuck_on=[15], degraded=[(7, .5), (13, .5)])   # no trim at qbar 0
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
        f.fdir.health_active = JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10])
        f.t_s = 3.0
        f.health_changed()
        assert f.authority.lp.alive and f.authority.lp.wait_idle(10.0)
        assert f.controllability is None                     # ready: applied by the next cycle
        f.authority.step(3.5, False)
        assert f.controllability is not None and not f.authority.lp.ready
        assert f.guidance.profile.accel_limit_radps2 < SC.bank_accel_limit_radps2
    finally:
        f.close()


def need_of(f, t_s):
    from fsw.controllability import schedule_accel_need_radps2
    return schedule_accel_need_radps2(f.scenario.bank_schedule, t_s)


def test_a_bias_left_to_the_air_is_assessed_again_as_the_dynamic_pressure_grows():
    """Campaign run 54's faults (jets 6 and 12 stuck on, four failed, two degraded) found at
    qbar 0: no trim exists yet. The 1 Hz re-assessment (RG3) finds the trim once the air can
    give it, sets the reference's offset and says so; from then on the trim is carried by its
    qbar scaling, not solved again. A stuck-on bias the jets cancel alone is not assessed
    again (its answer does not depend on qbar)."""
    from fsw.controllability import controllability as lp
    sc = load_scenario("mc/default-20110808-run054")
    h = JetHealth.of(failed_off=[1, 2, 10, 16], stuck_on=[6, 12], degraded=[(4, 0.5838198113373984), (7, 0.3871118055537681)])
    f = FlightSoftware(sc)
    try:
        f.fdir.health_active = h
        f.t_s, f.cycles = 230.0, 1
        f.health_changed()
        r0 = f.controllability
        assert not math.isfinite(r0.trim_needed_deg) and not r0.controllable and f.authority._trim_ref is None
        n_events = sum(e.code == "controllability" for e in f.events.history)
        f.nav.state.qbar_pa = 3000.0
        f.t_s = 231.0
        f.reassess_step()
        r1 = f.controllability
        assert r1 is not r0 and math.isfinite(r1.trim_needed_deg) and r1.qbar_pa == 3000.0
        assert 0.0 < r1.trim_needed_deg <= f.params["guidance.trim_max_deg"] and r1.controllable
        assert f.authority._trim_ref is not None and f.authority._trim_ref[2] == 3000.0
        # the same LP asked directly gives the same trim
        _, args = f.authority.lp_problem(231.0)
        assert lp(*args).trim_needed_deg == pytest.approx(r1.trim_needed_deg)
        texts = [e.text for e in f.events.history if e.code == "controllability"]
        assert len(texts) == n_events + 1 and texts[-1] == r1.text()
        f.nav.state.qbar_pa = 5000.0
        f.t_s = 232.0
        tr, limit = f.authority._trim_ref, f.guidance.profile.accel_limit_radps2
        f.authority.hold_trim(5000.0)                               # what the control cycle does
        f.reassess_step()          # a trim exists: carried by its qbar scaling, the authority asked from it
        r2 = f.controllability     # still the weak-way-best trim: not moved
        assert r2 is not r1 and f.authority._trim_ref[2] == 5000.0
        assert f.authority._trim_ref[:2] == pytest.approx((tr[0] * 3000.0 / 5000.0, tr[1] * 3000.0 / 5000.0))
        assert r2.trim_alpha_deg == pytest.approx(r1.trim_alpha_deg * 3000.0 / 5000.0)
        assert r2.trim_beta_deg == pytest.approx(r1.trim_beta_deg * 3000.0 / 5000.0)
        # the same LP asked directly with that trim held
        _, args = f.authority.lp_problem(232.0, (math.radians(r2.trim_alpha_deg), math.radians(r2.trim_beta_deg)))
        r3 = lp(*args)
        assert (r2.authority_pos_radps2, r2.authority_neg_radps2) == (r3.authority_pos_radps2, r3.authority_neg_radps2)
        # more air, more authority: the reference is not re-shaped, nothing said
        assert min(r2.authority_pos_radps2, r2.authority_neg_radps2) >= min(r1.authority_pos_radps2,
                                                                             r1.authority_neg_radps2)
        assert f.guidance.profile.accel_limit_radps2 == limit
        assert sum(e.code == "controllability" for e in f.events.history) == n_events + 1
        # less air than at the trim's solve: the jets take more of the bias, the authority drops
        # and the reference is slowed to it (once: the same answer again changes nothing)
        f.nav.state.qbar_pa = 200.0
        f.authority.hold_trim(200.0)
        f.t_s = 233.0
        f.reassess_step()
        r4 = f.controllability
        use = f.params["guidance.authority_use"]
        weak4 = min(r4.authority_pos_radps2, r4.authority_neg_radps2)
        assert weak4 < min(r1.authority_pos_radps2, r1.authority_neg_radps2)
        assert f.guidance.profile.accel_limit_radps2 == pytest.approx(max(use * weak4, need_of(f, 233.0)))
        n = len(f.events.history)
        f.t_s = 234.0
        f.reassess_step()
        assert len(f.events.history) == n
    finally:
        f.close()
    g = _fsw(JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10]))   # case 2: the jets cancel its bias alone
    r = g.controllability
    assert r.bias_Nm > 0.0 and r.trim_needed_deg == 0.0
    g.nav.state.qbar_pa = 3000.0
    g.cycles = 1
    g.reassess_step()
    assert g.controllability is r
    g.close()
