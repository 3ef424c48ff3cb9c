"""Navigation.update as one compiled call.

Independent truth: a body attitude built from chosen alpha, beta and bank
(C_BN = R2(alpha) R3(-beta) R1(bank) C_WN with the wind frame written out in NumPy), the
exponential density and dynamic pressure in closed form; and the shared common/frames,
common/mrp functions called directly (a stale compiled cache of the kernel would differ).
"""
import math

import numpy as np
import pytest

from common import atmosphere, frames, mrp
from common.frames import R1, R2, R3
from common.model import load_scenario
from fsw.navigation import Navigation, frame_vectors
from interfaces import records

SC = load_scenario("case1")
PL = SC.planet


def _wind(r, vrel):
    w1 = vrel / np.linalg.norm(vrel)
    h = np.cross(vrel, r)
    w2 = h / np.linalg.norm(h)
    return np.vstack((w1, w2, np.cross(w1, w2)))


def _case(alpha, beta, bank, h_m=60e3):
    rng = np.random.default_rng(7)
    r = rng.normal(size=3)
    r *= (PL.radius_m + h_m) / np.linalg.norm(r)
    v = np.cross([0.0, 0.0, 1.0], r) / PL.radius_m * 4000.0 + rng.normal(size=3) * 300.0
    vrel = v - np.cross([0.0, 0.0, PL.omega_radps], r)
    C_BN = R2(alpha) @ R3(-beta) @ R1(bank) @ _wind(r, vrel)
    return r, v, vrel, mrp.from_dcm(C_BN)


@pytest.mark.parametrize("alpha,beta,bank", [(-0.3, 0.01, 1.0), (0.2, -0.05, -2.5), (0.0, 0.0, 3.0)])
def test_angles_and_flight_condition_from_a_built_attitude(alpha, beta, bank):
    r, v, vrel, sigma = _case(alpha, beta, bank)
    nav = Navigation(PL, SC.vehicle)
    w = np.array([0.01, -0.02, 0.03])
    acc = np.array([1.0, 2.0, 3.0])
    n = nav.update(12.5, sigma, w, r, v, acc)
    assert n is nav.state and n.t_s == 12.5
    assert n.alpha_rad == pytest.approx(alpha, abs=1e-12)
    assert n.beta_rad == pytest.approx(beta, abs=1e-12)
    assert math.cos(n.bank_rad - bank) == pytest.approx(1.0, abs=1e-15)
    V = np.linalg.norm(vrel)
    h = np.linalg.norm(r) - PL.radius_m
    rho = PL.rho0_kgpm3 * math.exp(-h / PL.scale_height_m)
    assert n.V_rel_mps == pytest.approx(V, rel=1e-14)
    assert n.h_m == pytest.approx(h, rel=1e-12)
    assert n.rho_kgpm3 == pytest.approx(rho, rel=1e-12)
    assert n.qbar_pa == pytest.approx(0.5 * rho * V * V, rel=1e-12)
    assert n.mach == pytest.approx(V / atmosphere.speed_of_sound(h), rel=1e-14)
    assert np.allclose(n.vrel_N, vrel, rtol=1e-14, atol=1e-9)
    for name, val in (("sigma_BN", sigma), ("omega_BN_B", w), ("r_N", r), ("v_N", v), ("accel_B", acc)):
        got = getattr(n, name)
        assert np.array_equal(got, val) and got is not val, name
    assert all(type(getattr(n, k)) is float for k in ("V_rel_mps", "h_m", "alpha_rad", "bank_rad", "rho_kgpm3",
                                                       "qbar_pa", "mach"))


def test_kernel_agrees_exactly_with_the_shared_frame_functions():
    """Guards against a stale compiled cache: the kernel calls these same functions."""
    r, v, vrel, sigma = _case(0.1, 0.02, -0.7)
    n = Navigation(PL, SC.vehicle).update(0.0, sigma, np.zeros(3), r, v, np.zeros(3))
    vr = frames.v_rel_N(r, v, PL.omega_radps)
    assert np.array_equal(n.vrel_N, vr)
    assert np.array_equal(n.C_WN, frames.wind_dcm(r, vr))
    assert np.array_equal(n.C_BN, mrp.to_dcm(sigma))
    assert (n.alpha_rad, n.beta_rad, n.bank_rad) == frames.aero_angles(mrp.to_dcm(sigma), frames.wind_dcm(r, vr))
    assert n.rho_kgpm3 == nav_density(n.h_m)


def nav_density(h):
    return atmosphere.density_exponential(h, PL.rho0_kgpm3, PL.scale_height_m)


def test_frame_views_lists_and_float32_give_the_same_state():
    r, v, vrel, sigma = _case(0.05, 0.0, 0.4)
    fr = records.new(records.SENSORS)
    fr["sigma_BN"], fr["r_N"], fr["v_N"], fr["omega_BN_B"], fr["accel_B"] = sigma, r, v, [0.1, 0.2, 0.3], [1, 2, 3]
    a = Navigation(PL, SC.vehicle).update(1.0, fr["sigma_BN"], fr["omega_BN_B"], fr["r_N"], fr["v_N"], fr["accel_B"])
    b = Navigation(PL, SC.vehicle).update(1.0, list(sigma), (0.1, 0.2, 0.3), r.tolist(), v, np.array([1, 2, 3]))
    for k in ("sigma_BN", "omega_BN_B", "r_N", "v_N", "accel_B", "vrel_N", "C_WN", "C_BN"):
        assert np.array_equal(getattr(a, k), getattr(b, k)), k
    for k in ("V_rel_mps", "h_m", "alpha_rad", "beta_rad", "bank_rad", "rho_kgpm3", "qbar_pa", "mach"):
        assert getattr(a, k) == getattr(b, k), k
    c = Navigation(PL, SC.vehicle).update(1.0, sigma.astype(np.float32), fr["omega_BN_B"], r, v, fr["accel_B"])
    assert np.array_equal(c.sigma_BN, sigma.astype(np.float32).astype(float))


def test_bad_shape_raises_and_non_finite_propagates():
    nav = Navigation(PL, SC.vehicle)
    with pytest.raises(ValueError):
        nav.update(0.0, np.zeros(4), np.zeros(3), np.ones(3), np.ones(3), np.zeros(3))
    r, v, vrel, sigma = _case(0.0, 0.0, 0.0)
    n = nav.update(0.0, sigma, np.zeros(3), r, np.zeros(3) * np.nan, np.zeros(3))
    assert math.isnan(n.V_rel_mps) and math.isnan(n.alpha_rad) and math.isnan(n.qbar_pa)


def test_a_sensors_records_packed_vectors_give_the_update_of_its_fields():
    r, v, vrel, sigma = _case(-0.2, 0.03, 2.0)
    rec = records.new(records.SENSORS)
    rec["sigma_BN"], rec["omega_BN_B"], rec["r_N"], rec["v_N"], rec["accel_B"] = sigma, [0.1, -0.2, 0.3], r, v, [4.0, 5.0, 6.0]
    x = frame_vectors(rec)
    assert np.shares_memory(x, rec)                       # a view: made once, read every cycle
    packed = Navigation(PL, SC.vehicle).update_packed(3.0, x)
    ref = Navigation(PL, SC.vehicle).update(3.0, sigma, [0.1, -0.2, 0.3], r, v, [4.0, 5.0, 6.0])
    for name in ("sigma_BN", "omega_BN_B", "r_N", "v_N", "accel_B", "vrel_N", "C_WN", "C_BN"):
        assert np.array_equal(getattr(packed, name), getattr(ref, name)) and not np.shares_memory(getattr(packed, name), x)
    for name in ("V_rel_mps", "h_m", "alpha_rad", "beta_rad", "bank_rad", "rho_kgpm3", "qbar_pa", "mach"):
        assert getattr(packed, name) == getattr(ref, name), name
    assert packed.accel_B.tolist() == [4.0, 5.0, 6.0] and packed.omega_BN_B.tolist() == [0.1, -0.2, 0.3]
