"""Plant.truth() / fill_truth(rec) through the compiled truth kernel.

Independent truth: the flight-condition formulas written out with NumPy from the state
vector (local north/east/up axes, v_rel = v - Omega x r), and the TRUTH record filled
field by field from the dict (the slow path).
"""
import math

import numpy as np
import pytest

from common.model import load_scenario
from interfaces import records
from sim.plant import Plant

SC = load_scenario("case1")


def _flown(n=40):
    p = Plant(SC, seed=5)
    rng = np.random.default_rng(1)
    for _ in range(n):
        p.step((rng.random(18) < 0.3).astype(np.uint8))
    return p


def test_truth_matches_numpy_formulas():
    p = _flown()
    d = p.truth()
    x = p.x
    r, v = x[0:3], x[3:6]
    om = SC.planet.omega_radps
    u = v - np.cross([0.0, 0.0, om], r)
    up = r / np.linalg.norm(r)
    east = np.array([-r[1], r[0], 0.0]) / math.hypot(r[0], r[1])
    north = np.cross(up, east)
    assert math.isclose(d["V_rel_mps"], np.linalg.norm(u), rel_tol=1e-15)
    assert math.isclose(d["gamma_rad"], math.asin(u @ up / np.linalg.norm(u)), abs_tol=1e-14)
    assert math.isclose(d["psi_rad"], math.atan2(u @ east, u @ north), abs_tol=1e-14)
    assert math.isclose(d["lat_rad"], math.asin(r[2] / np.linalg.norm(r)), abs_tol=1e-15)
    lon = math.atan2(r[1], r[0]) - om * p.t_s
    assert math.isclose(math.cos(d["lon_rad"]), math.cos(lon), abs_tol=1e-14)
    assert -math.pi <= d["lon_rad"] < math.pi
    assert d["k"] == p.k and d["t_ns"] == p.t_ns and d["t_s"] == p.t_s
    assert np.array_equal(d["r_N"], r) and np.array_equal(d["sigma_BN"], x[6:9])
    assert d["fault_state"].dtype == np.int8 and np.array_equal(d["fault_state"], p.fault_state)
    assert math.isclose(d["propellant_kg"], p.propellant_kg, rel_tol=0, abs_tol=0)
    assert all(type(d[k]) is float for k in ("h_m", "gamma_rad", "decel_g", "propellant_kg", "bank_rad"))


def test_truth_dict_arrays_are_independent_of_the_plant():
    p = _flown(5)
    d = p.truth()
    r0 = d["r_N"].copy()
    p.step(np.ones(18, np.uint8))
    assert np.array_equal(d["r_N"], r0)
    d["fault_state"][:] = 3
    assert not np.any(p.fault_state == 3)


def test_fill_truth_in_place_equals_the_dict_and_the_slow_path():
    p = _flown()
    rec = records.new(records.TRUTH)
    assert p.fill_truth(rec) is rec
    slow = np.zeros(2, records.TRUTH)        # slow[0] is a np.void: filled field by field
    p.fill_truth(slow[0])
    assert rec.tobytes() == slow[0].tobytes()
    for name, val in p.truth().items():
        assert np.array_equal(rec[name], val), name
    # the same record again after a step (cached views) and a second record
    p.step(np.zeros(18, np.uint8))
    other = records.new(records.TRUTH)
    p.fill_truth(other)
    p.fill_truth(rec)
    assert rec.tobytes() == other.tobytes() and int(rec["k"]) == p.k


def test_fill_truth_raises_on_a_readonly_record():
    p = _flown(3)
    ro = records.new(records.TRUTH)
    ro.flags.writeable = False
    with pytest.raises(ValueError):
        p.fill_truth(ro)
    assert ro.tobytes() == bytes(records.TRUTH.itemsize)
