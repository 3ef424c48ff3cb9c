"""The paper's cases flown end to end in batch (docs/scenarios.md; issue: flight-software
core acceptance): every fault case completes to parachute conditions with the bank error
after the fault within the paper's 5 degrees, FDIR names exactly the injected jets with
the right kind, the nominal run has no false alarm, case 4 reconfigures at 4.0 s, and
fault tolerance off costs measurably more than case 1. Truth is the plant's own fault log
and the 5-degree bound of the paper, not the FSW's opinion of itself."""
from __future__ import annotations

import pytest

from common.model import load_scenario
from ellipsled import batch, reference, verdicts
from ellipsled.metrics import fault_attributable_error_deg
from ellipsled.sil.variant import prepare
from interfaces.vocabulary import FAULT_HEALTH, HEALTH_NAMES

BOUND_DEG = 5.0


@pytest.fixture(scope="module")
def flights():
    """{case: (summary, history)}; the fault-free twins land in the twin cache."""
    out = {}
    for name in ("nominal", "case1", "case2", "case3", "case4"):
        s, h, fsw = batch.run(name)
        fsw.close()
        out[name] = (s, h)
    s, h, fsw = batch.run("case1", ft_off=True)
    fsw.close()
    out["case1-ft-off"] = (s, h)
    return out


@pytest.fixture(scope="module")
def runs(flights):
    return {name: s for name, (s, _) in flights.items()}


@pytest.mark.parametrize("case", ["case1", "case2", "case3", "case4"])
def test_fault_case_completes_within_the_papers_bound(runs, case):
    s = runs[case]
    assert s["completed"] and s["end_reason"] == "mach", (s["end_reason"], s["t_end_s"])
    assert s["bank_err_max_after_fault_deg"] <= BOUND_DEG


@pytest.mark.parametrize("case", ["case1", "case2", "case3", "case4"])
def test_fdir_finds_exactly_the_injected_jets(runs, case):
    """Injected = the scenario file's fault schedule (what the plant applies)."""
    s = runs[case]
    injected = {(j, HEALTH_NAMES[FAULT_HEALTH[f.kind]]) for f in load_scenario(case).faults for j in f.jets}
    found = {(d["jet"], d["kind"]) for d in s["fdir"]["detections"]}
    assert found == injected
    assert len(s["fdir"]["detections"]) == len(injected)           # each once
    assert s["fdir"]["false_alarms"] == 0 and not s["fdir"]["missed"]
    # a stuck-on jet shows in its chamber pressure at once; a failed-off or degraded one only
    # when the allocator first fires it, which the spill box may not do for a while
    assert all(d["t_s"] >= 2.5 for d in s["fdir"]["detections"])
    assert all(d["t_s"] <= 5.0 for d in s["fdir"]["detections"] if d["kind"] == "stuck_on")


def test_nominal_has_no_false_alarm(runs):
    s = runs["nominal"]
    assert s["completed"] and s["fdir"]["detections"] == [] and s["fdir"]["false_alarms"] == 0


def test_case4_reconfigures_at_four_seconds(runs):
    """The paper's 4.0 s assumes instant detection: here the 1.5 s delay starts at the
    detector's first finding (0.1-0.2 s of persistence after the 2.5 s fault)."""
    s = runs["case4"]
    first = min(d["t_s"] for d in s["fdir"]["detections"])
    assert s["reconfig_t_s"] == pytest.approx(first + 1.5, abs=0.021)
    assert s["reconfig_t_s"] == pytest.approx(4.0, abs=0.2)
    assert runs["case1"]["reconfig_t_s"] < 3.5            # no added delay in case 1


def test_fault_tolerance_off_is_measurably_worse(runs):
    on, off = runs["case1"], runs["case1-ft-off"]
    assert off["completed"]
    assert off["propellant_kg"] > 2.0 * on["propellant_kg"]
    assert off["jet_pulses"] > 2.0 * on["jet_pulses"]
    # attitude excursions after the initial 5-degree transient: case 1's whole-run peak (0.40 deg
    # of beta at 1.1 s, before the 2.5 s fault) is the start-up transient the nominal run has too
    assert off["alpha_dev_max_after_transient_deg"] > 2.0 * on["alpha_dev_max_after_transient_deg"]
    assert off["beta_dev_max_after_transient_deg"] > 2.0 * on["beta_dev_max_after_transient_deg"]


def test_fault_tolerance_off_tracks_worse_once_the_initial_error_has_decayed(runs):
    """Paper figure 5: judged by what the faults cause (the run against its fault-free twin)
    and after the initial 5-degree transient, not by the transient's own peak."""
    on, off = runs["case1"], runs["case1-ft-off"]
    assert off["bank_err_fault_attrib_max_deg"] > on["bank_err_fault_attrib_max_deg"]
    assert off["bank_err_max_after_transient_deg"] > on["bank_err_max_after_transient_deg"]


def test_nominal_is_its_own_fault_free_twin(runs):
    assert runs["nominal"]["bank_err_fault_attrib_max_deg"] == 0.0


@pytest.mark.parametrize("case", ["case1", "case2", "case3", "case4"])
def test_fault_case_recovers_at_the_papers_scale(flights, case):
    """The recovery claim (6.1) as the report judges it, on the flown case against its
    fault-free twin: back within 0.5 deg of the twin, held, within 5 s of reconfiguration."""
    s, h = flights[case]
    twin = reference.fault_free_history(prepare(case), s["seed"])
    t, d = fault_attributable_error_deg(h, twin)
    x = verdicts.fault_transient(t, d, s["fault_t_s"], s["reconfig_t_s"])
    assert x["recover_s"] is not None and x["recover_s"] <= verdicts.FEW_S, x
    assert x["peak_deg"] <= verdicts.BOUND_DEG
