"""Jets, faults and chamber pressures in the plant (docs/plant.md, jets and jet faults),
and jets given by geometry (T = r x F)."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from common import mrp
from common.model import load_scenario, load_vehicle
from sim.plant import DEGRADED, FAILED_OFF, NOMINAL, STUCK_ON, Plant

SC = load_scenario("nominal")
T = SC.vehicle.torque_matrix_Nm
DT = SC.dt_control_s


def quiet(sc):
    """No aero, no sensor noise: jet effects appear exactly."""
    return sc.with_(planet=replace(sc.planet, rho0_kgpm3=0.0),
                    sensors=replace(sc.sensors, chamber_noise=0.0, gyro_noise_radps=0.0, attitude_noise_rad=0.0))


def unit(j):
    u = np.zeros(18, np.uint8)
    u[j] = 1
    return u


def test_paper_torque_matrix_is_mirror_symmetric_and_T1_equals_T2():
    # independent restatement of the spec table
    a, b, c, d = 26.32, 41.72, 17.60, 283.10
    blk = lambda r, p: np.array([[-r, 0, r, r, 0, -r], [p, -p, -p, p, -p, -p], [-p, p, -p, p, -p, p]])
    assert np.array_equal(T, np.hstack((blk(a, b), blk(a, b), blk(c, d))))


def test_each_single_jet_produces_its_torque_column_and_chamber_pressure():
    plant = Plant(quiet(SC))
    for j in range(18):
        s = plant.step(unit(j))
        tr = plant.truth()
        assert np.array_equal(tr["tau_jets_B"], T[:, j])
        assert np.array_equal(tr["jet_thrust_frac"], unit(j).astype(float))
        assert np.array_equal(s["chamber"], unit(j).astype(float))


def test_random_patterns_produce_T_u_and_accept_bool_and_lists():
    plant = Plant(quiet(SC))
    rng = np.random.default_rng(3)
    for i in range(50):
        u = rng.integers(0, 2, 18).astype(np.uint8)
        arg = u if i % 3 == 0 else (u.astype(bool) if i % 3 == 1 else u.tolist())
        plant.step(arg)
        assert np.allclose(plant.truth()["tau_jets_B"], T @ u, rtol=0, atol=1e-12)


def test_jet_torque_changes_body_rate_by_inverse_inertia_times_torque():
    plant = Plant(quiet(SC))
    Iinv = np.linalg.inv(plant.inertia_truth_kgm2)
    for j in (0, 7, 14):
        plant.set_state(omega_BN_B=[0.0, 0.0, 0.0])
        plant.step(unit(j))
        expected = Iinv @ T[:, j] * DT
        assert np.allclose(plant.x[9:12], expected, rtol=1e-4, atol=1e-12)


@pytest.mark.parametrize("bad", [np.zeros(17, np.uint8), np.full(18, 2, np.uint8), [0.5] * 18,
                                 [float("nan")] * 18, np.zeros((2, 18), np.uint8), "x" * 18])
def test_bad_commands_are_rejected_without_changing_the_state(bad):
    plant = Plant(quiet(SC))
    x0, k0 = plant.x.copy(), plant.k
    with pytest.raises(ValueError):
        plant.step(bad)
    assert np.array_equal(plant.x, x0) and plant.k == k0


def test_fault_kinds_change_produced_torque_and_chamber_pressure_and_clear_restores():
    plant = Plant(quiet(SC))
    j = 13                               # jet 14
    one, zero = unit(j), np.zeros(18, np.uint8)
    cases = [("failed_off", 1.0, one, 0.0, FAILED_OFF), ("stuck_on", 1.0, zero, 1.0, STUCK_ON),
             ("degraded", 0.3, one, 0.3, DEGRADED), ("degraded", 0.3, zero, 0.0, DEGRADED),
             ("nominal", 1.0, one, 1.0, NOMINAL), ("nominal", 1.0, zero, 0.0, NOMINAL)]
    for kind, eta, u, produced, state in cases:
        plant.set_fault(j + 1, kind, eta)
        s = plant.step(u)
        tr = plant.truth()
        assert np.allclose(tr["tau_jets_B"], produced * T[:, j], atol=1e-12), kind
        assert s["chamber"][j] == pytest.approx(produced)
        assert tr["fault_state"][j] == state
        others = np.delete(np.arange(18), j)
        assert np.all(tr["fault_state"][others] == NOMINAL)


def test_stuck_jets_fire_whatever_the_command_and_jet_zero_means_all():
    plant = Plant(quiet(SC))
    plant.set_fault(0, "stuck_on")
    plant.step(np.zeros(18, np.uint8))
    assert np.allclose(plant.truth()["tau_jets_B"], T.sum(axis=1))
    plant.set_fault(0, "nominal")
    plant.set_fault(5, "failed_off")
    plant.step(np.ones(18, np.uint8))
    assert np.allclose(plant.truth()["tau_jets_B"], T.sum(axis=1) - T[:, 4])


@pytest.mark.parametrize("jet,kind,eta", [(19, "failed_off", 1.0), (-1, "failed_off", 1.0), (1.5, "failed_off", 1.0),
                                          (True, "failed_off", 1.0),
                                          (1, "broken", 1.0), (1, "degraded", 1.0), (1, "degraded", 0.0),
                                          (1, "degraded", float("nan")), (1, "failed_off", 0.5), (1, "degraded", "0.5")])
def test_bad_fault_requests_raise_value_error(jet, kind, eta):
    plant = Plant(quiet(SC))
    with pytest.raises(ValueError):
        plant.set_fault(jet, kind, eta)
    assert np.all(plant.fault_state == NOMINAL)


# (case, its faulted jets, their fault kind, the fraction of its thrust a faulted jet delivers)
@pytest.mark.parametrize("case,jets,kind,thrust_frac", [("case1", [1, 2, 17, 18], "failed_off", 0.0),
                                                        ("case2", [2, 3, 4, 5, 8, 9, 10], "stuck_on", 1.0),
                                                        ("case3", [3, 7, 14, 15], "degraded", 0.5)])
def test_scheduled_faults_apply_at_the_first_step_boundary_at_or_after_t_s(case, jets, kind, thrust_frac):
    sc = quiet(load_scenario(case))
    plant = Plant(sc)
    u = np.ones(18, np.uint8) if kind != "stuck_on" else np.zeros(18, np.uint8)
    k_fault = round(2.5 / DT)
    idx = np.array(jets) - 1
    for _ in range(k_fault):
        assert np.all(plant.fault_state == NOMINAL)
        plant.step(u)
        assert np.allclose(plant.truth()["tau_jets_B"], T @ u)   # not yet faulted over [t_k, t_k+1)
    assert plant.k == k_fault and np.all(plant.fault_state[idx] != NOMINAL)
    plant.step(u)
    frac = u.astype(float)
    frac[idx] = thrust_frac
    assert np.allclose(plant.truth()["tau_jets_B"], T @ frac)
    assert np.allclose(plant.sensors["chamber"], frac)


def test_chamber_noise_has_the_configured_sigma_and_zero_mean():
    plant = Plant(SC)
    u = np.zeros(18, np.uint8)
    u[::2] = 1
    ch = np.array([plant.step(u)["chamber"].copy() for _ in range(1500)])
    err = ch - u
    assert abs(err.std() - SC.sensors.chamber_noise) < 0.05 * SC.sensors.chamber_noise
    assert abs(err.mean()) < 4 * SC.sensors.chamber_noise / np.sqrt(err.size)


def test_propellant_bookkeeping_uses_produced_thrust_and_isp():
    plant = Plant(quiet(SC))
    plant.set_fault(13, "degraded", 0.5)
    for _ in range(10):
        plant.step(np.ones(18, np.uint8))
    thrust = SC.vehicle.thrust_N.copy()
    thrust[12] *= 0.5
    expected = thrust.sum() * 10 * DT / (SC.vehicle.isp_s * SC.planet.g0_mps2)
    assert plant.propellant_kg == pytest.approx(expected, rel=1e-12)


GEOMETRY_HEADER = """
[vehicle]
name = "geo"
mass_kg = 1200.0
inertia_kgm2 = { I11 = 2109.0, I22 = 5053.0, I33 = 5053.0, I12 = -21.0, I13 = 84.0, I23 = 12.0 }
S_ref_m2 = 11.04
l_ref_m = 3.75

[aero]
alpha_trim_deg = 20.0
C_L = 0.48
C_D = 1.20
C_Lalpha = 0.9
C_Ybeta = -0.3
C_malpha = -0.12
C_nbeta = 0.10
C_lbeta = -0.01
C_lp = -0.05
C_mq = -0.20
C_nr = -0.20

[jets]
model = "geometry"
isp_s = 220.0
"""


def geometry_file(tmp_path: Path, rng) -> tuple[Path, np.ndarray, np.ndarray]:
    pos = rng.uniform(-3, 3, (18, 3))
    dirs = rng.normal(size=(18, 3))
    thrust = rng.uniform(5, 100, 18)
    text = GEOMETRY_HEADER
    for p, d, f in zip(pos, dirs, thrust):
        text += (f"\n[[jets.jet]]\nposition_m = {[float(c) for c in p]}\n"
                 f"direction = {[float(c) for c in d]}\nthrust_N = {float(f)!r}\n")
    path = tmp_path / "geo.toml"
    path.write_text(text)
    F = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)) * thrust[:, None]
    return path, pos, F


def test_jets_by_geometry_reproduce_r_cross_F_and_add_their_force(tmp_path):
    rng = np.random.default_rng(11)
    path, pos, F = geometry_file(tmp_path, rng)
    veh = load_vehicle(path)
    assert np.allclose(veh.torque_matrix_Nm.T, np.cross(pos, F), rtol=1e-12, atol=1e-12)
    assert np.allclose(veh.jet_force_B_N.T, F)
    plant = Plant(quiet(SC.with_(vehicle=veh)))
    for j in (0, 9, 17):
        s = plant.step(unit(j))
        tr = plant.truth()
        assert np.allclose(tr["tau_jets_B"], np.cross(pos[j], F[j]))
        # aero off: the sensed acceleration is the jet force alone
        assert np.allclose(s["accel_B"], F[j] / veh.mass_kg, rtol=1e-12, atol=1e-15)
        # and the force reaches the trajectory: dv - gravity dv = C_NB F/m dt
        plant2 = Plant(quiet(SC.with_(vehicle=veh)))
        plant2.set_state(r_N=tr["r_N"], v_N=tr["v_N"], sigma_BN=tr["sigma_BN"],
                         omega_BN_B=np.zeros(3))
        plant.set_state(omega_BN_B=np.zeros(3))
        plant.step(unit(j))
        plant2.step(np.zeros(18, np.uint8))
        dv = plant.x[3:6] - plant2.x[3:6]
        C = mrp.to_dcm(tr["sigma_BN"])
        assert np.allclose(dv, C.T @ F[j] / veh.mass_kg * DT, rtol=1e-3, atol=1e-9)


def test_faults_scheduled_by_call_apply_at_their_time_in_order_and_bad_ones_are_refused():
    plant = Plant(quiet(SC))
    plant.schedule_fault(0.1, 3, "stuck_on")
    plant.schedule_fault(0.1, 3, "degraded", 0.4)       # same boundary: applied after, wins
    plant.schedule_fault(0.05, 0, "failed_off")         # 0.05 s -> boundary k = 3 (t = 0.06)
    for bad in [(float("nan"), 3, "failed_off", 1.0), (1.0, 30, "failed_off", 1.0), (1.0, 3, "degraded", 1.5)]:
        with pytest.raises(ValueError):
            plant.schedule_fault(*bad)
    zero = np.zeros(18, np.uint8)
    states = []
    for _ in range(6):
        plant.step(np.ones(18, np.uint8))
        states.append((plant.k, plant.fault_state[2], plant.fault_eta[2], plant.fault_state[0]))
    assert states[1] == (2, NOMINAL, 1.0, NOMINAL)
    assert states[2] == (3, FAILED_OFF, 1.0, FAILED_OFF)
    assert states[4] == (5, DEGRADED, 0.4, FAILED_OFF)
    plant.step(zero)
    assert plant.truth()["tau_jets_B"] == pytest.approx(np.zeros(3))
    plant.schedule_fault(0.0, 0, "nominal")               # in the past: next boundary
    plant.step(np.ones(18, np.uint8))
    assert np.all(plant.fault_state == NOMINAL)
    plant.step(np.ones(18, np.uint8))
    assert np.allclose(plant.truth()["tau_jets_B"], T.sum(axis=1))
