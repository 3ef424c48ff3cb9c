"""Ground link parameter protocol: list / read / set -> PARAM_VALUE for every ground-
settable FSW parameter; refused sets answered with the unchanged value and a STATUSTEXT;
the documented param_id table equals the mapping the code derives.

Independent truth: the parameter declarations (Param.lo/hi/ground_settable) enumerated
from fsw.flightsoftware.all_params, and float32 rounding done by struct.
"""
from __future__ import annotations

import struct
from pathlib import Path

import pytest

import fsw.groundlink as groundlink
from fsw.flightsoftware import all_params
from fsw.groundlink import param_id, param_ids
from interfaces.mavlink import dialect as mav
from interfaces.mavlink.signing import Reject

from tests.test_groundlink_commands import Rig


def f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


@pytest.fixture
def rig(tmp_path):
    r = Rig(tmp_path)
    r.fly(3)
    yield r
    r.close()


def settable():
    return [p for p in all_params() if p.ground_settable]


def test_param_ids_are_short_unique_and_documented():
    ids = param_ids([p.name for p in settable()])
    assert len(set(ids.values())) == len(ids)
    assert all(1 <= len(i) <= 16 and i.isascii() for i in ids.values())
    # the table in the module docstring is exactly the derived mapping
    src = Path(groundlink.__file__).read_text()
    body = src.split("PARAM_ID_TABLE_BEGIN\n")[1].split("PARAM_ID_TABLE_END")[0]
    rows = {}
    for line in body.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 2 and "." in cells[0]:
            rows[cells[0]] = cells[1]
    assert rows == ids


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
    assert "X_RG2_DIVISOR" not in got                 # not ground-settable: not listed


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
    v = _set_and_wait(rig, "F_PERSIST_N", 7)
    assert v == 7 and rig.fsw.fdir._persist_n == 7
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
    ("F_PERSIST_N", "fdir.persist_n", 2.5, "integer"),
    ("F_DEGRADED_HI", "fdir.degraded_hi", 0.1, "degraded_lo"),            # consistency with degraded_lo
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


def test_unknown_and_not_settable_ids_get_no_value_but_a_statustext(rig):
    rig.gcs.send(mav.MAVLink_param_set_message(1, 1, b"X_RG2_DIVISOR", 3, mav.MAV_PARAM_TYPE_REAL32))
    rig.gcs.send(mav.MAVLink_param_set_message(1, 1, b"NO_SUCH_PARAM", 3, mav.MAV_PARAM_TYPE_REAL32))
    texts = [t for t in rig.texts() if "UNKNOWN" in t]
    assert "PARAM X_RG2_DIVISOR UNKNOWN" in texts and "PARAM NO_SUCH_PARAM UNKNOWN" in texts
    assert "PARAM_VALUE" not in rig.gcs.state.latest
    assert rig.fsw.params["executive.rg2_divisor"] == 5


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
