"""The parameter registry: one declaration per parameter, every ground-settable one
applied by its owner's hook, a refused value leaves value and owner unchanged, and the
machine-readable description carries what a ground station needs (units, bounds, text)."""
from __future__ import annotations

import pytest

from fsw.flightsoftware import FlightSoftware, declarations
from fsw.params import Param, ParamRegistry
from common.model import load_scenario


def test_a_parameter_declared_by_two_owners_is_refused():
    p = Param("fdir.stale_n", 1, 1000)
    with pytest.raises(ValueError, match="declared by A and by B"):
        ParamRegistry((("A", [p]), ("B", [p])))


def test_a_ground_settable_parameter_without_its_owners_hook_is_a_construction_error():
    reg = ParamRegistry(declarations())
    for owner in ("AuthoritySupervisor", "SamiController", "Allocator", "Fdir", "SensorMonitor", "Failsafes"):
        reg.bind(owner, lambda n, v: None)
    with pytest.raises(ValueError, match="without an owner's hook: driver.arm_on_entry"):
        reg.check_bound()


def test_a_refused_set_changes_neither_the_value_nor_the_owner():
    fsw = FlightSoftware(load_scenario("nominal"))
    try:
        lo = fsw.params["fdir.degraded_lo"]
        with pytest.raises(ValueError, match="degraded_hi: must be > fdir.degraded_lo"):
            fsw.set_param("fdir.degraded_hi", lo)                  # in bounds, inconsistent with its sibling
        assert fsw.params["fdir.degraded_hi"] == fsw.fdir.p["fdir.degraded_hi"] == 0.93
        with pytest.raises(ValueError, match="not settable in flight"):
            fsw.set_param("executive.rg2_period_s", 0.2)
        assert fsw.set_param("fdir.stale_s", 0.18) == 0.18 and fsw.monitor.stale_n == 9
    finally:
        fsw.close()


def test_every_parameter_is_described_for_a_ground_station():
    rows = ParamRegistry(declarations()).describe()
    by_name = {r["name"]: r for r in rows}
    assert by_name["fdir.omega_max_radps"] == {
        "name": "fdir.omega_max_radps", "param_id": "F_OMEGA_MAX_RADP", "owner": "SensorMonitor", "unit": "rad/s",
        "min": 0.01, "max": 100.0, "choices": None, "integer": False, "ground_settable": True, "default": 2.0,
        "description": "largest credible |omega|"}
    assert by_name["executive.rg2_period_s"]["param_id"] is None
    assert all(r["description"] for r in rows)
