"""FDIR jet monitor: detection, isolation, delay, overrides, against an independent plant-side
chamber-pressure model written here (docs/plant.md: eta*u for a working jet, 1 stuck on,
0 failed off, + white noise sigma 0.02) and expected detection times counted directly from
the command sequence (the N-th post-fault firing, or the N-th post-fault off period)."""
from __future__ import annotations

import re
import time

import numpy as np
import pytest

from common.events import EventLog, Severity
from fsw.fdir import Fdir
from fsw.health import DEGRADED, FAILED_OFF, NOMINAL, STUCK_ON
from fsw.params import load_params
from interfaces.vocabulary import HEALTH_NAMES, N_JETS

DT = 0.02
SIGMA = 0.02


def params(**over):
    p = load_params(Fdir.PARAMS)
    p.update({f"fdir.{k}": v for k, v in over.items()})
    return p


PERSIST = int(round(params()["fdir.persist_s"] / DT))


def plant_chamber(u, kind, eta, active, rng):
    """Chamber pressure the plant reports for the period in which command u was held."""
    thrust = u.astype(float)
    f = np.where(active, kind, 0)
    thrust = np.where(f == 3, eta * u, thrust)       # degraded
    thrust = np.where(f == 1, 0.0, thrust)           # failed off
    thrust = np.where(f == 2, 1.0, thrust)           # stuck on
    return thrust + rng.normal(0.0, SIGMA, u.shape)


def run(faults: dict[int, tuple[int, float]], t_fault=2.5, t_end=6.0, seed=0, duty=0.3, fdir=None, events=None,
        nan_jets=()):
    """Drive Fdir with random commands; faults: jet(1-based) -> (kind code, eta).
    Returns (fdir, commands (K,18), times (K,), changed (K,))."""
    rng = np.random.default_rng(seed)
    events = events if events is not None else EventLog()
    fdir = fdir if fdir is not None else Fdir(params(), DT, events)
    kind = np.zeros(N_JETS, dtype=int)
    eta = np.ones(N_JETS)
    for j, (kd, e) in faults.items():
        kind[j - 1], eta[j - 1] = kd, e
    n = int(round(t_end / DT))
    cmds = (rng.random((n, N_JETS)) < duty).astype(np.uint8)
    times = np.arange(1, n + 1) * DT
    changed = np.zeros(n, dtype=bool)
    for i in range(n):
        u_prev = cmds[i]                      # held over [t_i - DT, t_i)
        active = (times[i] - DT) >= t_fault - 1e-9
        p = plant_chamber(u_prev, kind, eta, active, rng)
        for j in nan_jets:
            p[j - 1] = np.nan
        changed[i] = fdir.update(times[i], u_prev, p)
    return fdir, cmds, times, changed


def expected_detection_time(cmds, times, jet, kind, t_fault=2.5):
    """Time of the PERSIST-th post-fault sample that carries evidence for this fault kind."""
    post = (times - DT) >= t_fault - 1e-9
    want_on = kind in (FAILED_OFF, DEGRADED)
    evid = post & ((cmds[:, jet - 1] == 1) if want_on else (cmds[:, jet - 1] == 0))
    idx = np.flatnonzero(evid)
    return times[idx[PERSIST - 1]]


CASES = {
    "case1": {j: (FAILED_OFF, 0.0) for j in (1, 2, 17, 18)},
    "case2": {j: (STUCK_ON, 1.0) for j in (2, 3, 4, 5, 8, 9, 10)},
    "case3": {j: (DEGRADED, 0.5) for j in (3, 7, 14, 15)},
    "mixed": {1: (FAILED_OFF, 0.0), 6: (STUCK_ON, 1.0), 11: (DEGRADED, 0.5), 13: (DEGRADED, 0.3)},
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("seed", [1, 2])
def test_detects_exactly_the_faulty_jets_with_kind_time_and_eta(case, seed):
    faults = CASES[case]
    fdir, cmds, times, changed = run(faults, seed=seed)
    got = {d["jet"]: d for d in fdir.detections}
    assert set(got) == set(faults), f"detected {sorted(got)}, injected {sorted(faults)}"
    for jet, (kind, eta) in faults.items():
        d = got[jet]
        assert d["kind"] == HEALTH_NAMES[kind]
        assert d["t_s"] == pytest.approx(expected_detection_time(cmds, times, jet, kind), abs=1e-9)
        assert fdir.health_isolated.state[jet - 1] == kind
        assert fdir.health_active.state[jet - 1] == kind          # delay 0: applied at once
        if kind == DEGRADED:
            assert abs(d["eta_hat"] - eta) < 0.05
            assert fdir.health_active.eta[jet - 1] == pytest.approx(d["eta_hat"])
    healthy = [j for j in range(1, N_JETS + 1) if j not in faults]
    assert np.all(fdir.health_active.state[np.array(healthy) - 1] == NOMINAL)


def test_detection_events_have_severity_and_short_text():
    ev = EventLog()
    run(CASES["mixed"], events=ev)
    det = [e for e in ev.history if e.code.startswith("jet_")]
    texts = {e.text: e.severity for e in det}
    assert texts["JET 1 FAILED_OFF"] == Severity.ERROR
    assert texts["JET 6 STUCK_ON"] == Severity.ERROR
    assert any(re.fullmatch(r"JET 11 DEGRADED ETA 0\.(4[5-9]|5[0-5])", t) and s == Severity.WARNING
               for t, s in texts.items())
    reconf = [e for e in ev.history if e.code == "fdir_reconfig"]
    assert len(reconf) == 4 and all(e.severity == Severity.NOTICE for e in reconf)
    assert all(len(e.text) <= 50 for e in ev.history)


@pytest.mark.parametrize("eta", [0.3, 0.9])
def test_degraded_at_the_monte_carlo_extremes(eta):
    """MC draws eta in [0.3, 0.9]; 0.9 sits 1.5 sigma below degraded_hi, so detection may
    need more firings than the minimum, but must come, with eta_hat within 0.05."""
    fdir, cmds, times, _ = run({4: (DEGRADED, eta)}, t_end=12.0, seed=7)
    assert [d["jet"] for d in fdir.detections] == [4]
    d = fdir.detections[0]
    assert d["kind"] == "degraded" and abs(d["eta_hat"] - eta) < 0.05
    firings = np.sum(cmds[(times - DT >= 2.5 - 1e-9) & (times <= d["t_s"] + 1e-9), 3])
    assert PERSIST <= firings <= 60


def test_failed_off_needs_firings_and_is_silent_while_jet_stays_off():
    fdir, cmds, times, _ = run({9: (FAILED_OFF, 0.0)}, duty=0.0)      # never commanded
    assert fdir.detections == []


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_no_false_alarm_over_a_full_entry_of_nominal_samples(seed):
    """22,500 cycles x 18 jets (450 s at 50 Hz), nominal jets, default noise."""
    rng = np.random.default_rng(seed)
    n = 22_500
    ev = EventLog()
    fdir = Fdir(params(), DT, ev)
    cmds = (rng.random((n, N_JETS)) < 0.4).astype(np.uint8)
    press = cmds + rng.normal(0.0, SIGMA, cmds.shape)
    for i in range(n):
        assert not fdir.update((i + 1) * DT, cmds[i], press[i])
    assert fdir.detections == [] and ev.history == []


def test_persistence_a_disagreeing_sample_resets_the_count():
    """Four failed-off firings, one good firing, four failed-off: never five in a row."""
    fdir = Fdir(params(), DT, EventLog())
    u = np.zeros(N_JETS, dtype=np.uint8)
    u[0] = 1
    seq = [0.0] * (PERSIST - 1) + [1.0] + [0.0] * (PERSIST - 1)
    for i, p0 in enumerate(seq):
        p = np.zeros(N_JETS)
        p[0] = p0
        fdir.update(i * DT, u, p)
    assert fdir.detections == []
    p = np.zeros(N_JETS)
    fdir.update(len(seq) * DT, u, p)                    # the 5th in a row
    assert [d["jet"] for d in fdir.detections] == [1]


def test_off_periods_are_neutral_for_failed_off():
    """Evidence gathered over firings separated by long off periods still accumulates."""
    fdir = Fdir(params(), DT, EventLog())
    on = np.zeros(N_JETS, dtype=np.uint8)
    on[2] = 1
    off = np.zeros(N_JETS, dtype=np.uint8)
    t = 0.0
    for _ in range(PERSIST):
        t += DT
        fdir.update(t, on, np.zeros(N_JETS))
        for _ in range(10):
            t += DT
            fdir.update(t, off, np.zeros(N_JETS))
    assert [(d["jet"], d["kind"]) for d in fdir.detections] == [(3, "failed_off")]


# ---------------------------------------------------------------- delay (paper case 4)
def test_case4_delay_applies_each_detection_exactly_delay_after_isolation():
    ev = EventLog()
    fdir = Fdir(params(delay_s=1.5), DT, ev)
    fdir_c, cmds, times, changed = run(CASES["case1"], fdir=fdir, events=ev, seed=3)
    assert {d["jet"] for d in fdir.detections} == {1, 2, 17, 18}
    # isolation happens during the run, reconfiguration delay_s later on the first step at or after it
    expect_change_steps = set()
    for d in fdir.detections:
        assert d["t_apply_s"] == pytest.approx(d["t_s"] + 1.5)
        i = int(np.flatnonzero(times >= d["t_s"] + 1.5 - 1e-9)[0])
        expect_change_steps.add(i)
        assert 4.0 <= times[i] <= 4.0 + 1.0          # case 4: reconfiguration at ~4.0 s + persistence
    assert set(np.flatnonzero(changed)) == expect_change_steps
    reconf = [e for e in ev.history if e.code == "fdir_reconfig"]
    assert sorted(e.t_s for e in reconf) == sorted(times[i] for d in fdir.detections
                                                    for i in [int(np.flatnonzero(times >= d["t_s"] + 1.5 - 1e-9)[0])])


def test_delay_active_health_lags_isolated_health():
    fdir = Fdir(params(delay_s=0.5), DT, EventLog())
    u = np.zeros(N_JETS, dtype=np.uint8)
    u[16] = 1
    t_det = None
    for i in range(1, 60):
        t = i * DT
        changed = fdir.update(t, u, np.zeros(N_JETS))
        if t_det is None and fdir.health_isolated.state[16] == FAILED_OFF:
            t_det = t
        assert fdir.reconfig_pending == (t_det is not None and t < t_det + 0.5 - 1e-9)
        if t_det is not None and t < t_det + 0.5 - 1e-9:
            assert fdir.health_active.state[16] == NOMINAL and not changed
        if t_det is not None and abs(t - (t_det + 0.5)) < 1e-9:
            assert changed and fdir.health_active.state[16] == FAILED_OFF
    assert t_det == pytest.approx(PERSIST * DT)
    assert fdir.health_version == 1


def test_set_delay_applies_to_later_detections_only():
    fdir = Fdir(params(delay_s=1.0), DT, EventLog())
    u = np.ones(N_JETS, dtype=np.uint8)
    p = np.ones(N_JETS)
    p[0] = 0.0
    t = 0.0
    for _ in range(PERSIST):
        t += DT
        fdir.update(t, u, p)
    fdir.set_delay(0.0, t)
    p[1] = 0.0
    for _ in range(PERSIST):
        t += DT
        fdir.update(t, u, p)
    assert fdir.health_active.state[1] == FAILED_OFF      # new delay 0
    assert fdir.health_active.state[0] == NOMINAL          # still waiting its own 1.0 s
    with pytest.raises(ValueError):
        fdir.set_delay(-1.0)
    with pytest.raises(ValueError):
        fdir.set_delay(float("nan"))


# ---------------------------------------------------------------- overrides and clear
def test_override_applies_immediately_and_wins_until_cleared():
    ev = EventLog()
    fdir = Fdir(params(), DT, ev)
    fdir.override(1.0, 5, "degraded", 0.4)
    assert fdir.health_active.state[4] == DEGRADED and fdir.health_active.eta[4] == pytest.approx(0.4)
    assert fdir.health_isolated.state[4] == NOMINAL
    assert fdir.health_version == 1
    fdir.override(1.0, 6, "stuck_on")
    fdir.override(1.0, 7, "failed_off")
    assert fdir.health_active.state[5] == STUCK_ON and fdir.health_active.state[6] == FAILED_OFF
    # 'nominal' masks a real detection: FDIR still reports it, the allocator keeps the jet
    fdir.override(1.0, 1, "nominal")
    u = np.ones(N_JETS, dtype=np.uint8)
    p = np.ones(N_JETS)
    p[0] = 0.0
    for i in range(PERSIST):
        fdir.update(1.0 + (i + 1) * DT, u, p)
    assert fdir.health_isolated.state[0] == FAILED_OFF
    assert fdir.health_active.state[0] == NOMINAL
    # clearing the jet drops override and latch: nominal everywhere, monitoring restarts
    fdir.clear(2.0, 1)
    assert fdir.health_isolated.state[0] == NOMINAL and fdir.health_active.state[0] == NOMINAL
    for i in range(PERSIST):
        fdir.update(2.0 + (i + 1) * DT, u, p)
    assert fdir.health_active.state[0] == FAILED_OFF           # re-detected after clear
    fdir.clear(3.0, 0)
    assert np.all(fdir.health_active.state == NOMINAL) and np.all(fdir.health_isolated.state == NOMINAL)
    codes = [e.code for e in ev.history]
    assert codes.count("fdir_override") == 4 and codes.count("fdir_clear") == 2
    assert any(e.text == "GND CLEAR ALL JETS" for e in ev.history)


def test_clear_before_the_delay_cancels_the_pending_reconfiguration():
    fdir = Fdir(params(delay_s=1.0), DT, EventLog())
    u = np.ones(N_JETS, dtype=np.uint8)
    p = np.ones(N_JETS)
    p[3] = 0.0
    for i in range(PERSIST):
        fdir.update((i + 1) * DT, u, p)
    assert fdir.health_isolated.state[3] == FAILED_OFF
    fdir.clear(0.2, 4)
    p[3] = 1.0
    for i in range(100):
        assert not fdir.update(0.2 + (i + 1) * DT, u, p)
    assert fdir.health_active.state[3] == NOMINAL


@pytest.mark.parametrize("args", [(0, "failed_off"), (19, "failed_off"), (True, "failed_off"), (2.0, "failed_off"),
                                  (3, "exploded"), (3, "degraded", 0.0), (3, "degraded", 1.0),
                                  (3, "degraded", float("nan")), (3, "degraded", "half")])
def test_override_rejects_bad_arguments_and_changes_nothing(args):
    fdir = Fdir(params(), DT, EventLog())
    with pytest.raises(ValueError):
        fdir.override(0.0, *args)
    assert np.all(fdir.health_active.state == NOMINAL) and fdir.health_version == 0


def test_clear_rejects_bad_jet():
    fdir = Fdir(params(), DT, EventLog())
    for bad in (-1, 19, "3", None):
        with pytest.raises(ValueError):
            fdir.clear(0.0, bad)


def test_degraded_jet_escalates_to_failed_off():
    fdir = Fdir(params(), DT, EventLog())
    u = np.ones(N_JETS, dtype=np.uint8)
    p = np.ones(N_JETS)
    p[7] = 0.5
    t = 0.0
    for _ in range(PERSIST):
        t += DT
        fdir.update(t, u, p)
    assert fdir.health_active.state[7] == DEGRADED
    p[7] = 0.0
    for _ in range(PERSIST):
        t += DT
        fdir.update(t, u, p)
    assert fdir.health_active.state[7] == FAILED_OFF
    assert [d["kind"] for d in fdir.detections] == ["degraded", "failed_off"]


# ---------------------------------------------------------------- bad input
def test_non_finite_chamber_samples_are_skipped_not_counted():
    ev = EventLog()
    fdir, cmds, times, _ = run({2: (FAILED_OFF, 0.0)}, events=ev, nan_jets=(5, 2))
    assert fdir.detections == []                  # jet 2's only evidence was NaN
    skips = [e for e in ev.history if e.code == "fdir_chamber_skip"]
    assert 1 <= len(skips) <= int(times[-1] / ev.min_interval_s) + 1      # rate-limited
    assert fdir.nonfinite_count == 2 * len(times)


def test_non_finite_samples_interleaved_do_not_break_persistence():
    fdir = Fdir(params(), DT, EventLog())
    u = np.ones(N_JETS, dtype=np.uint8)
    t = 0.0
    for i in range(2 * PERSIST - 1):
        t += DT
        p = np.ones(N_JETS)
        p[0] = 0.0 if i % 2 == 0 else np.inf
        fdir.update(t, u, p)
    assert [(d["jet"], d["t_s"]) for d in fdir.detections] == [(1, pytest.approx(t))]


def test_bad_shapes_and_params_raise():
    fdir = Fdir(params(), DT, EventLog())
    with pytest.raises(ValueError):
        fdir.update(0.0, np.zeros(17, dtype=np.uint8), np.zeros(18))
    with pytest.raises(ValueError):
        fdir.update(0.0, np.zeros(18, dtype=np.uint8), np.zeros((18, 1)))
    with pytest.raises(ValueError, match="degraded_lo"):
        Fdir(params(off_threshold=0.3, degraded_lo=0.2), DT, EventLog())
    with pytest.raises(ValueError, match="persist_s"):
        Fdir(params(persist_s=0.0), DT, EventLog())
    with pytest.raises(ValueError, match="dt_s"):
        Fdir(params(), 0.0, EventLog())
    with pytest.raises(ValueError):
        fdir.set_param("fdir.degraded_hi", 0.1)             # below degraded_lo
    assert fdir.p["fdir.degraded_hi"] == params()["fdir.degraded_hi"]
    assert fdir.set_param("fdir.persist_s", 0.16) == 0.16 and fdir._persist[0] == round(0.16 / DT)
    with pytest.raises(ValueError):
        fdir.set_param("fdir.nope", 1.0)


def test_bool_and_float_commands_are_accepted():
    fdir = Fdir(params(), DT, EventLog())
    u = np.zeros(N_JETS, dtype=bool)
    u[4] = True
    for i in range(PERSIST):
        fdir.update((i + 1) * DT, u.astype(float) if i % 2 else u, np.zeros(N_JETS))
    assert [d["jet"] for d in fdir.detections] == [5]


def test_update_cost_is_small():
    """Sanity bound only (figures go to the benchmark): well under a millisecond."""
    fdir = Fdir(params(), DT, EventLog())
    rng = np.random.default_rng(0)
    u = (rng.random(N_JETS) < 0.5).astype(np.uint8)
    p = u + rng.normal(0, SIGMA, N_JETS)
    fdir.update(0.0, u, p)
    n = 2000
    t0 = time.perf_counter()
    for i in range(n):
        fdir.update(i * DT, u, p)
    assert (time.perf_counter() - t0) / n < 200e-6


def test_inhibit_mirror_survives_reconfiguration():
    fdir = Fdir(params(), DT, EventLog())
    fdir.set_inhibit(0.0, 9, True)
    assert fdir.health_active.inhibited[8] and fdir.health_version == 1
    assert not fdir.health_active.usable()[8]
    fdir.override(0.1, 2, "failed_off")                    # a refresh keeps the mask
    assert fdir.health_active.inhibited[8]
    fdir.set_inhibit(0.2, 0, False)
    assert not fdir.health_active.inhibited.any() and fdir.health_version == 3
    with pytest.raises(ValueError):
        fdir.set_inhibit(0.0, 19, True)


def test_every_key_in_the_defaults_file_is_declared_by_one_owner():
    from common.config import load_toml
    from fsw.flightsoftware import all_params
    from fsw.params import DEFAULT_FILE
    declared = [p.name for p in all_params()]
    assert len(declared) == len(set(declared))
    in_file = {f"{section}.{key}" for section, tbl in load_toml(DEFAULT_FILE).items() for key in tbl}
    assert in_file == set(declared)


def test_persistence_is_a_time_whatever_the_control_rate():
    assert Fdir(params(), 0.02, EventLog())._persist[0] == 5          # 0.1 s at 50 Hz
    assert Fdir(params(), 0.005, EventLog())._persist[0] == 20        # ... and at 200 Hz
    assert Fdir(params(persist_s=0.001), 0.005, EventLog())._persist[0] == 1     # never below one sample
