"""Ground link parameter protocol: list / read / set -> PARAM_VALUE for every ground-
settable FSW parameter; refused sets answered with the unchanged value and a STATUSTEXT;
the documented param_id table equals the mapping the code derives.

Independent truth: the parameter declarations (Param.lo/hi/ground_settable) enumerated
from fsw.flightsoftware.all_params, and float32 rounding done by struct.
"""
from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest

from fsw.flightsoftware import all_params, declarations
from fsw.params import ParamRegistry, param_id, param_ids
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing.verify import Reject

from tests.rig import Rig, flown


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


@pytest.fixture
def rig(tmp_path):
    with flown(tmp_path, 3) as r:
        yield r


def settable():
    return [p for p in all_params() if p.ground_settable]


# The ids the console, scripts and tests use: a new parameter may add an id, none may change.
STABLE_IDS = {
    "allocator.fault_tolerance": "A_FAULT_TOLERANC", "allocator.penalty_per_N": "A_PENALTY_PER_N",
    "allocator.w_pitch": "A_W_PITCH", "allocator.w_roll": "A_W_ROLL", "allocator.w_yaw": "A_W_YAW",
    "control.d_max": "C_D_MAX", "control.d_min": "C_D_MIN", "control.deadzone": "C_DEADZONE",
    "control.gamma_d": "C_GAMMA_D", "control.gamma_h": "C_GAMMA_H", "control.h_bound_frac": "C_H_BOUND_FRAC",
    "control.h_prod_scale": "C_H_PROD_SCALE", "control.int_limit": "C_INT_LIMIT",
    "control.lambda_radps": "C_LAMBDA_RADPS", "control.q_weight": "C_Q_WEIGHT",
    "control.safe_rate_gain": "C_SAFE_RATE_GAIN", "control.shortfall_frac": "C_SHORTFALL_FRAC",
    "control.sigma_switch": "C_SIGMA_SWITCH", "driver.arm_on_entry": "D_ARM_ON_ENTRY",
    "fdir.accel_max_mps2": "F_ACCEL_MAX_MPS2", "fdir.alt_max_m": "F_ALT_MAX_M", "fdir.chamber_hi": "F_CHAMBER_HI",
    "fdir.chamber_lo": "F_CHAMBER_LO", "fdir.degraded_hi": "F_DEGRADED_HI", "fdir.degraded_lo": "F_DEGRADED_LO",
    "fdir.delay_s": "F_DELAY_S", "fdir.off_threshold": "F_OFF_THRESHOLD", "fdir.omega_max_radps": "F_OMEGA_MAX_RADP",
    "fdir.on_threshold": "F_ON_THRESHOLD", "fdir.persist_s": "F_PERSIST_S", "fdir.r_below_m": "F_R_BELOW_M",
    "fdir.res_persist_s": "F_RES_PERSIST_S", "fdir.res_rel": "F_RES_REL", "fdir.res_tau_s": "F_RES_TAU_S",
    "fdir.res_thr_Nm": "F_RES_THR_NM", "fdir.safe_track_deg": "F_SAFE_TRACK_DEG",
    "fdir.safe_track_s": "F_SAFE_TRACK_S", "fdir.sigma_tol": "F_SIGMA_TOL", "fdir.stale_s": "F_STALE_S",
    "fdir.v_max_mps": "F_V_MAX_MPS", "guidance.authority_use": "G_AUTHORITY_USE",
    "guidance.trim_max_deg": "G_TRIM_MAX_DEG",
    "npc.bank_final_deg": "N_BANK_FINAL_DEG", "npc.bank_max_deg": "N_BANK_MAX_DEG",
    "npc.bank_min_deg": "N_BANK_MIN_DEG", "npc.dpsi_hi_deg": "N_DPSI_HI_DEG", "npc.dpsi_lo_deg": "N_DPSI_LO_DEG",
    "npc.dt_pred_s": "N_DT_PRED_S", "npc.h_deploy_m": "N_H_DEPLOY_M", "npc.hdot_gain": "N_HDOT_GAIN",
    "npc.hdot_tau_s": "N_HDOT_TAU_S", "npc.k_drag_min": "N_K_DRAG_MIN", "npc.k_max": "N_K_MAX",
    "npc.k_min": "N_K_MIN", "npc.k_tau_s": "N_K_TAU_S", "npc.limit_frac": "N_LIMIT_FRAC",
    "npc.max_iter": "N_MAX_ITER", "npc.rev_gap_s": "N_REV_GAP_S", "npc.tgo_freeze_s": "N_TGO_FREEZE_S",
    "npc.tol_m": "N_TOL_M", "npc.v_norev_mps": "N_V_NOREV_MPS",
}


def test_param_ids_are_short_unique_stable_and_documented():
    reg = ParamRegistry(declarations())
    ids = reg.ids
    assert ids == param_ids([p.name for p in settable()])
    assert len(set(ids.values())) == len(ids)
    assert all(1 <= len(i) <= 16 and i.isascii() for i in ids.values())
    assert {n: ids[n] for n in STABLE_IDS} == STABLE_IDS
    # the table in the interface document is exactly the generated one
    doc = (Path(__file__).resolve().parents[1] / "interfaces" / "mavlink" / "README.md").read_text()
    table = doc.split("<!-- PARAMS BEGIN")[1].split("\n", 1)[1].split("<!-- PARAMS END")[0]
    assert table == reg.markdown(), "regenerate with: ellipsled params --markdown"
    rows = [r for r in reg.describe() if r["ground_settable"]]
    assert [r["param_id"] for r in rows] == [ids[n] for n in reg.settable()]
    assert all((r["default"] in r["choices"] if r["choices"] else r["min"] <= r["default"] <= r["max"])
               and r["owner"] and r["description"] for r in reg.describe())


def test_param_id_collisions_are_resolved_deterministically():
    names = ["fdir.omega_max_radps_a", "fdir.omega_max_radps_b", "fdir.omega_max_radps_c"]
    ids = param_ids(names)
    assert param_id(names[0]) == param_id(names[1]) == "F_OMEGA_MAX_RADP"
    assert list(ids.values()) == ["F_OMEGA_MAX_RADP", "F_OMEGA_MAX_RA~1", "F_OMEGA_MAX_RA~2"]
    assert param_ids(reversed(names)) == ids


def test_param_list_returns_every_ground_settable_parameter_with_its_value(rig):
    rig.gcs.param_request_list()
    n = len(settable())
    assert rig.exchange(lambda: len(rig.gcs.state.params) >= n)
    got = rig.gcs.state.params
    ids = param_ids([p.name for p in settable()])
    assert set(got) == set(ids.values())
    assert rig.gcs.state.param_count == n
    for name, pid in ids.items():
        assert got[pid] == f32(rig.fsw.params[name]), name
    assert "X_RG2_PERIOD_S" not in got                 # not ground-settable: not listed


def test_param_read_by_id_and_by_index(rig):
    rig.gcs.send(mav.MAVLink_param_request_read_message(1, 1, b"c_lambda_radps", -1))   # case-insensitive
    assert rig.exchange(lambda: "C_LAMBDA_RADPS" in rig.gcs.state.params)
    assert rig.gcs.state.params["C_LAMBDA_RADPS"] == f32(rig.fsw.params["control.lambda_radps"])
    names = sorted(p.name for p in settable())
    rig.gcs.send(mav.MAVLink_param_request_read_message(1, 1, b"", 0))
    first = param_id(names[0])
    assert rig.exchange(lambda: first in rig.gcs.state.params)
    msg = rig.gcs.state.latest["PARAM_VALUE"]
    assert msg.param_index == 0 and msg.param_count == len(names)


def test_param_set_within_bounds_changes_the_fsw(rig):
    v = _set_and_wait(rig, "C_LAMBDA_RADPS", 1.25)
    assert v == 1.25 and rig.fsw.params["control.lambda_radps"] == 1.25
    v = _set_and_wait(rig, "F_PERSIST_S", 0.14)
    assert v == pytest.approx(0.14) and rig.fsw.fdir._persist[0] == 7      # 0.14 s at 50 Hz
    v = _set_and_wait(rig, "A_FAULT_TOLERANC", 0)
    assert v == 0 and rig.fsw.allocator.fault_tolerance is False


def _set_and_wait(rig, pid, value):
    rig.gcs.state.params.pop(pid, None)
    rig.gcs.send(mav.MAVLink_param_set_message(1, 1, pid.encode(), value, mav.MAV_PARAM_TYPE_REAL32))
    assert rig.exchange(lambda: pid in rig.gcs.state.params)
    return rig.gcs.state.params[pid]


@pytest.mark.parametrize("pid, name, bad, why", [
    ("C_LAMBDA_RADPS", "control.lambda_radps", 20.0, "outside"),          # hi 10
    ("C_LAMBDA_RADPS", "control.lambda_radps", 0.0, "outside"),           # lo 0.05
    ("C_LAMBDA_RADPS", "control.lambda_radps", float("nan"), "finite"),
    ("C_LAMBDA_RADPS", "control.lambda_radps", float("inf"), "finite"),
    ("D_ARM_ON_ENTRY", "driver.arm_on_entry", 0.5, "integer"),
    ("F_DEGRADED_HI", "fdir.degraded_hi", 0.1, "degraded_lo"),            # consistency with degraded_lo
    ("N_BANK_MAX_DEG", "npc.bank_max_deg", 100.0, "not flown in mode profile"),   # case1: no npc
    ("N_K_MAX", "npc.k_max", 0.5, "outside"),                                 # bounds hold in any mode
])
def test_refused_set_answers_the_unchanged_value_and_says_why(rig, pid, name, bad, why):
    before = rig.fsw.params[name]
    v = _set_and_wait(rig, pid, bad)
    assert v == f32(before) and rig.fsw.params[name] == before
    texts = rig.texts()
    refusal = [t for t in texts if t.startswith(f"{pid} REFUSED")]
    assert refusal and why in refusal[-1] and len(refusal[-1]) <= 50
    sev = [e.severity for e in rig.gcs.state.events if e.text.startswith(f"{pid} REFUSED")]
    assert sev[-1] == mav.MAV_SEVERITY_WARNING


def test_npc_bounds_must_stay_ordered_and_a_set_applies_at_the_next_guidance_cycle(tmp_path):
    r = Rig(tmp_path, scenario="guided-nominal")
    try:
        r.fly(10)
        e = r.fsw.entry
        assert _set_and_wait(r, "N_BANK_MAX_DEG", 90.0) == 90.0
        v = _set_and_wait(r, "N_BANK_MIN_DEG", 90.0)                     # would empty [min, max)
        assert v == f32(10.0) and r.fsw.params["npc.bank_min_deg"] == 10.0
        assert any(t.startswith("N_BANK_MIN_DEG REFUSED: needs bank_min < bank_max") for t in r.texts())
        assert e.bank_max_rad == pytest.approx(math.radians(165.0))         # not before the next cycle
        r.fly(50)                                                     # the guidance cycle at 1 s
        assert e.bank_max_rad == pytest.approx(math.radians(90.0)) and e.params["npc.bank_max_deg"] == 90.0
        assert "GUIDANCE NPC.BANK_MAX_DEG 90" in r.texts()
    finally:
        r.close()


def test_unknown_and_not_settable_ids_get_no_value_but_a_statustext(rig):
    rig.gcs.send(mav.MAVLink_param_set_message(1, 1, b"X_RG2_PERIOD_S", 3, mav.MAV_PARAM_TYPE_REAL32))
    rig.gcs.send(mav.MAVLink_param_set_message(1, 1, b"NO_SUCH_PARAM", 3, mav.MAV_PARAM_TYPE_REAL32))
    texts = [t for t in rig.texts() if "UNKNOWN" in t]
    assert "PARAM X_RG2_PERIOD_S UNKNOWN" in texts and "PARAM NO_SUCH_PARAM UNKNOWN" in texts
    assert "PARAM_VALUE" not in rig.gcs.state.latest
    assert rig.fsw.params["executive.rg2_period_s"] == 0.1


def test_unsigned_param_set_is_rejected_but_unsigned_reads_are_answered(rig):
    unsigned = mav.MAVLink(None, srcSystem=255, srcComponent=190)
    before = rig.fsw.params["control.lambda_radps"]
    rig.gcs.sock.sendto(mav.MAVLink_param_set_message(1, 1, b"C_LAMBDA_RADPS", 2.0,
                                                      mav.MAV_PARAM_TYPE_REAL32).pack(unsigned), rig.gl.address)
    rig.gcs.sock.sendto(mav.MAVLink_param_request_read_message(1, 1, b"C_D_MIN", -1).pack(unsigned),
                        rig.gl.address)
    assert rig.exchange(lambda: "C_D_MIN" in rig.gcs.state.params)
    assert rig.fsw.params["control.lambda_radps"] == before
    assert "C_LAMBDA_RADPS" not in rig.gcs.state.params
    assert rig.gl.link.counts[Reject.UNSIGNED] == 1
