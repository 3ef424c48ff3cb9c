"""fsw/output.py: the output record packed in runs of adjacent fields holds, byte for byte,
what a field-by-field fill through views writes, in a guided flight (every guidance field
live) and in profile mode; the loop timing fields are left to the rate-group driver."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.events import EventLog
from common.model import load_scenario
from fsw.flightsoftware import FlightSoftware
from interfaces.records import FSW_STATE, FSW_STATE_SHELL, GUID_NPC, GUID_PREDICTION, GUID_TARGET, new
from sim.plant import Plant


def reference_fill(rec, fsw, u) -> None:
    """The fill field by field through views (the oracle)."""
    g, h, e = fsw.guidance, fsw.health, fsw.entry
    rec["k"] = fsw.k
    rec["t_ns"] = int(round(fsw.t_s * 1e9))
    rec["bank_ref_rad"], rec["bankdot_ref_radps"], rec["bank_err_rad"] = g.phi_r, g.phidot_r, fsw.bank_err_rad
    rec["sigma_RN"], rec["u_cal_B"], rec["tau_alloc_B"] = g.sigma_RN, fsw.u_cal_B, fsw.tau_alloc_B
    rec["theta_hat"], rec["eta_hat"], rec["health"] = fsw.control.theta_hat, h.eta, h.state
    rec["alloc_us"] = fsw.alloc_ns * 1e-3
    rec["jets_cmd"] = u
    rec["mode"], rec["alloc_degraded"], rec["alloc_short"] = int(fsw.modes.mode), fsw.allocator.degraded, fsw.alloc_short
    rec["deploy"] = fsw.deploy.code if fsw.deploy is not None else 0
    tlat, tlon = fsw.scenario.target_lat_rad, fsw.scenario.target_lon_rad
    has_target = tlat is not None and math.isfinite(tlat) and math.isfinite(tlon)
    rec["target_lat_rad"], rec["target_lon_rad"] = (tlat, tlon) if has_target else (0.0, 0.0)
    flags = GUID_TARGET if has_target else 0
    rec["guid_cycles"], rec["bank_cmd_rad"], rec["pred_lat_rad"], rec["pred_lon_rad"] = 0, 0.0, 0.0, 0.0
    if e is not None:
        flags |= GUID_NPC
        rec["guid_cycles"] = e.cycles
        rec["bank_cmd_rad"] = e.bank_cmd if math.isfinite(e.bank_cmd) else 0.0
        p = e.pred_impact
        if e.cycles > 0 and math.isfinite(p[0]) and math.isfinite(p[1]):
            flags |= GUID_PREDICTION
            rec["pred_lat_rad"], rec["pred_lon_rad"] = p[0], p[1]
    rec["guid_flags"] = flags


@pytest.mark.parametrize("scenario, n", [("guided-nominal", 60), ("nominal", 20)])
def test_the_packed_fill_writes_what_a_field_by_field_fill_does(scenario, n):
    scn = load_scenario(scenario)
    plant = Plant(scn, scn.seed)
    fsw = FlightSoftware(scn, EventLog())
    shell = {name: fsw.output[name].copy() for name in FSW_STATE_SHELL}
    ref = new(FSW_STATE)
    frame = plant.sensors
    checked = set()
    for i in range(n):
        u = fsw.control_step(frame)
        if i % 25 == 0:
            fsw.entry_guidance_step()             # guidance answers: its fields change
            fsw.control_step(frame)               # (a duplicate frame: jets held off, refilled)
        for name in FSW_STATE_SHELL:
            ref[name] = fsw.output[name]
        reference_fill(ref, fsw, u)
        assert fsw.output.tobytes() == ref.tobytes(), i
        checked.update(name for name in FSW_STATE.names if np.any(ref[name] != 0))
        frame = plant.step(u)
    for name in FSW_STATE_SHELL:                  # the rate-group driver's, never written here
        np.testing.assert_array_equal(fsw.output[name], shell[name])
    # the comparison covered non-zero values of the fields a flight sets
    assert {"k", "t_ns", "bank_ref_rad", "sigma_RN", "u_cal_B", "theta_hat", "eta_hat", "mode"} <= checked
    if scenario.startswith("guided"):
        assert {"guid_cycles", "guid_flags", "target_lon_rad", "pred_lat_rad", "bank_cmd_rad"} <= checked
