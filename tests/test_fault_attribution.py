"""The fault-attributable bank error (docs/scenarios.md): max over t >= t_fault of
|e_case(t) - e_ref(t)|, e_ref from the same scenario and seed flown without faults.
Truth: a hand-computed synthetic history, and the determinism of the fault-free flight."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.model import load_scenario
from ellipsled import batch, reference
from ellipsled.metrics import fault_attributable_error_deg, fault_attributable_max_deg, settle_time
from ellipsled.sil.history import History
from ellipsled.sil.variant import prepare


def _history(k, bank_deg, ref_deg, dt=0.5) -> History:
    h = History(len(k))
    h.n = len(k)
    h.a["k"][:] = k
    h.a["t_s"][:] = np.asarray(k) * dt
    h.a["bank_rad"][:] = np.radians(bank_deg)
    h.a["bank_ref_rad"][:] = np.radians(ref_deg)
    return h


def test_fault_attributable_max_equals_a_hand_computed_value():
    # case errors e = bank - ref:   k=0..5 -> [5, 4, 3, 2, 1.5, 179]  (179 - (-178) wraps to -3)
    case = _history([0, 1, 2, 3, 4, 5], [90, 89, 88, 87, 86.5, 179], [85, 85, 85, 85, 85, -178])
    # twin errors, one step shorter (ended earlier): [5, 4.5, 2.5, 2.6, 1.0]
    ref = _history([0, 1, 2, 3, 4], [90, 89.5, 87.5, 87.6, 86.0], [85, 85, 85, 85, 85])
    t, d = fault_attributable_error_deg(case, ref)
    np.testing.assert_allclose(t, [0.0, 0.5, 1.0, 1.5, 2.0])              # only the common steps
    np.testing.assert_allclose(d, [0.0, -0.5, 0.5, -0.6, 0.5], atol=1e-12)
    # from t_fault = 1.0 s (k >= 2): max(|0.5|, |-0.6|, |0.5|) = 0.6; the wrapped step k=5 is not common
    assert fault_attributable_max_deg(case, ref, 1.0) == pytest.approx(0.6, abs=1e-12)
    assert fault_attributable_max_deg(case, ref, 0.0) == pytest.approx(0.6, abs=1e-12)
    assert fault_attributable_max_deg(case, ref, 2.1) is None           # nothing common after it


def test_fault_attributable_difference_wraps_across_180_degrees():
    case = _history([0, 1], [179.5, 179.5], [-179.5, -179.5])   # e = -1 (wrapped)
    ref = _history([0, 1], [-179.0, -179.0], [179.0, 179.0])    # e = +2 (wrapped)
    assert fault_attributable_max_deg(case, ref, 0.0) == pytest.approx(3.0, abs=1e-9)


def test_fine_settle_time_uses_its_band():
    t = np.arange(0.0, 10.0, 0.02)
    e = np.where(t < 3.0, 0.5, 0.1)
    assert settle_time(t, e, 0.0, band_deg=0.2) == pytest.approx(3.0, abs=0.021)
    assert settle_time(t, e, 0.0) == pytest.approx(0.0)      # inside the default 1-degree band at once


def test_nominal_against_its_fault_free_twin_is_zero(tmp_path):
    """The twin of a run without faults is flown from the same scenario and seed; it must
    match the run step for step (the figure is 0 because the flight is deterministic, not
    because the code skips it)."""
    s, h, _ = batch.run("nominal", duration_s=15.0, reference_cache=tmp_path)
    assert s["bank_err_fault_attrib_max_deg"] == 0.0
    twin = reference.fault_free_history(prepare("nominal", duration_s=15.0), 1, tmp_path)
    assert fault_attributable_max_deg(h, twin, 0.0) == 0.0
    assert twin.n == h.n


def test_a_faulted_run_is_judged_against_its_twin_and_the_twin_is_cached(tmp_path, monkeypatch):
    s, h, _ = batch.run("case1", duration_s=15.0, reference_cache=tmp_path)
    files = list(tmp_path.glob("*.npz"))
    assert len(files) == 1
    twin = History.load(files[0])
    assert s["bank_err_fault_attrib_max_deg"] == pytest.approx(fault_attributable_max_deg(h, twin, 2.5))
    assert s["bank_err_fault_attrib_max_deg"] > 0.0
    # the same scenario and seed again: from the cache, not flown
    monkeypatch.setattr(reference, "fly_twin", lambda *a: (_ for _ in ()).throw(AssertionError("flown again")))
    s2, _, _ = batch.run("case1", duration_s=15.0, reference_cache=tmp_path)
    assert s2["bank_err_fault_attrib_max_deg"] == s["bank_err_fault_attrib_max_deg"]


def test_twin_key_depends_on_what_decides_the_flight_only():
    c1 = prepare("case1")
    key = reference.twin_key(c1, 1)
    assert reference.twin_key(c1.with_(name="renamed", faults=()), 1) == key    # name and faults: not the twin's
    assert reference.twin_key(prepare("nominal"), 1) == key                # same flight without faults
    assert reference.twin_key(c1, 2) != key                                      # seed
    assert reference.twin_key(c1.with_(bank0_rad=math.radians(85.0)), 1) != key  # initial state
    assert reference.twin_key(load_scenario("case4"), 1) != key                  # FSW parameters (delay)


def test_no_initial_error_variant_starts_on_the_reference():
    s, h, _ = batch.run("case1", duration_s=12.0, initial_error=False, reference=False)
    e = np.degrees(h["bank_rad"] - h["bank_ref_rad"])
    assert s["scenario"] == "case1-no-init-err"
    assert abs(e[0]) < 0.01                       # the paper's set-up starts 5 deg off
    s5, h5, _ = batch.run("case1", duration_s=12.0, reference=False)
    assert np.degrees(h5["bank_rad"][0] - h5["bank_ref_rad"][0]) == pytest.approx(5.0, abs=0.01)


def test_effort_figures_equal_hand_computed_integrals():
    from ellipsled.metrics import effort
    h = _history([0, 1, 2, 3], [0, 0, 0, 0], [0, 0, 0, 0], dt=0.5)
    h.a["u_cal_B"][:] = [[3.0, 4.0, 0.0]] * 4          # |u|^2 = 25
    h.a["tau_alloc_B"][:] = [[3.0, 0.0, 0.0]] * 4      # missing (0, 4, 0): 16
    h.a["tau_jets_B"][:] = [[1.0, 0.0, 0.0]] * 4       # applied |tau|^2 = 1
    e = effort(h)                                       # zero-order hold: 3 intervals of 0.5 s
    assert e["control_effort_cmd"] == pytest.approx(25 * 1.5)
    assert e["control_effort_applied"] == pytest.approx(1 * 1.5)
    assert e["control_effort_undeliverable_share"] == pytest.approx(16 / 25)


def test_recovery_time_runs_from_reconfiguration_to_a_tenth_of_the_faults_peak():
    from ellipsled.metrics import recovery_time
    t = np.arange(0.0, 30.0, 0.02)
    # grows from the fault (2.5 s) to 0.2 deg at 4.5 s, falls linearly to 0 at 8.5 s, then a later
    # excursion of 1 deg at 20 s (a reversal: not the fault's transient)
    d = np.interp(t, [0, 2.5, 4.5, 8.5, 19, 20, 21], [0, 0, 0.2, 0.0, 0, 1.0, 0])
    # 10 % of 0.2 = 0.02, reached at 8.1 s; reconfiguration at 4.0 s -> 4.1 s
    assert recovery_time(t, d, 2.5, 4.0) == pytest.approx(4.1, abs=0.021)
    assert recovery_time(t, 0.001 * d, 2.5, 4.0) == 0.0          # nothing to recover from
    assert recovery_time(t, np.where(t > 2.5, 0.5, 0.0), 2.5, 4.0) is None   # never comes back
