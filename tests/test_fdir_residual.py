"""FDIR analytic-redundancy residual: truth from an RK4 rigid-body integration written here
(I w_dot + w x I w = tau), sampled through a noisy gyro; the check must stay quiet when the
commanded and aero torques explain the motion (even with an inertia error the relative
threshold covers), and raise "unexplained torque" when a torque nobody commanded acts."""
from __future__ import annotations

import numpy as np
import pytest

from common.events import EventLog, Severity
from fsw.fdir import Fdir
from fsw.params import load_params

DT = 0.02
I_NOM = np.array([[2109.0, -21.0, 84.0], [-21.0, 5053.0, 12.0], [84.0, 12.0, 5053.0]])
GYRO_SIGMA = 2e-5


def rk4_step(I, Iinv, w, tau, h):
    f = lambda x: Iinv @ (tau - np.cross(x, I @ x))   # noqa: E731
    k1 = f(w)
    k2 = f(w + 0.5 * h * k1)
    k3 = f(w + 0.5 * h * k2)
    k4 = f(w + h * k3)
    return w + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def simulate(I_true, t_end, tau_unexplained_B=None, t_fault=None, seed=0, call_every=1):
    """Bang-bang-ish torques (what quantised jets give), aero torque known to the FSW, an
    optional unexplained torque from t_fault. Returns (fdir, events, residual norms)."""
    rng = np.random.default_rng(seed)
    ev = EventLog()
    fdir = Fdir(load_params(Fdir.PARAMS), DT, ev)
    w = np.array([0.02, -0.01, 0.015])
    n = int(round(t_end / DT))
    I_true_inv = np.linalg.inv(I_true)
    w_meas_prev = w + rng.normal(0, GYRO_SIGMA, 3)
    tau_hist, tau_aero_hist = [], []
    norms = []
    w_meas_at_last_call = w_meas_prev
    for i in range(n):
        t = i * DT
        tau_cmd = rng.choice([-1, 0, 1], size=3) * np.array([26.32, 41.72, 41.72]) * rng.integers(0, 3, 3)
        tau_aero = np.array([5.0 * np.sin(0.3 * t), 40.0 * np.cos(0.2 * t), -30.0])
        tau = tau_cmd + tau_aero
        if tau_unexplained_B is not None and t >= t_fault - 1e-9:
            tau = tau + tau_unexplained_B
        for _ in range(2):
            w = rk4_step(I_true, I_true_inv, w, tau, DT / 2)
        w_meas = w + rng.normal(0, GYRO_SIGMA, 3)
        tau_hist.append(tau_cmd)
        tau_aero_hist.append(tau_aero)
        if (i + 1) % call_every == 0:
            # mean commanded / aero torque over the interval since the last call
            tc = np.mean(tau_hist[-call_every:], axis=0)
            ta = np.mean(tau_aero_hist[-call_every:], axis=0)
            norms.append(fdir.residual_check(t + DT, w_meas, w_meas_at_last_call, DT * call_every, tc, ta, I_NOM))
            w_meas_at_last_call = w_meas
    return fdir, ev, np.array(norms)


@pytest.mark.parametrize("call_every", [1, 5])
def test_consistent_torque_is_quiet_with_exact_inertia(call_every):
    fdir, ev, norms = simulate(I_NOM, 15.0, call_every=call_every)
    assert not [e for e in ev.history if e.code == "unexplained_torque"]
    assert norms.max() < 5.0                        # gyro noise after the low-pass (~1.3 N m seen)
    assert not fdir.residual_alarm


def test_consistent_torque_is_quiet_with_a_30_percent_inertia_error():
    I_true = I_NOM * np.array([[1.3, 1.3, 1.3], [1.3, 0.85, 1.3], [1.3, 1.3, 1.2]])
    _, ev, _ = simulate(I_true, 15.0, seed=2)
    assert not [e for e in ev.history if e.code == "unexplained_torque"]


@pytest.mark.parametrize("call_every", [1, 5])
def test_unexplained_torque_raises_a_warning_after_the_persistence(call_every):
    """A 95 N down jet stuck on with its pressure sensor reading 0 (pitch/yaw 283 N m)."""
    t_fault = 5.0
    fdir, ev, norms = simulate(I_NOM, 10.0, tau_unexplained_B=np.array([-17.6, 283.1, -283.1]), t_fault=t_fault,
                               call_every=call_every)
    alarms = [e for e in ev.history if e.code == "unexplained_torque"]
    assert alarms and alarms[0].severity == Severity.WARNING
    persist = load_params(Fdir.PARAMS)["fdir.res_persist_s"]
    assert t_fault + persist <= alarms[0].t_s <= t_fault + persist + 1.0
    assert len(alarms) <= (10.0 - alarms[0].t_s) / ev.min_interval_s + 1   # rate-limited
    assert fdir.residual_alarm
    assert norms[-1] == pytest.approx(np.linalg.norm([17.6, 283.1, 283.1]), rel=0.15)


def test_non_finite_inputs_are_skipped():
    fdir = Fdir(load_params(Fdir.PARAMS), DT, EventLog())
    z = np.zeros(3)
    assert fdir.residual_check(0.0, np.array([np.nan, 0, 0]), z, DT, z, z, I_NOM) == 0.0
    assert fdir.residual_check(0.0, z, z, DT, np.array([0, np.inf, 0]), z, I_NOM) == 0.0
    with pytest.raises(ValueError):
        fdir.residual_check(0.0, z, z, 0.0, z, z, I_NOM)
