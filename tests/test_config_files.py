"""Data files: the shipped ones load and match the spec; bad copies are rejected with a
message naming the file and the field (common/config.py, common/model.py)."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from common.config import DATA_DIR, ConfigError
from common.model import load_planet, load_scenario, load_vehicle

VEHICLE = DATA_DIR / "vehicles" / "ellipsled.toml"
SCENARIO = DATA_DIR / "scenarios" / "nominal.toml"
PLANET = DATA_DIR / "planets" / "mars.toml"


def test_all_shipped_data_files_load():
    for f in sorted((DATA_DIR / "scenarios").glob("*.toml")):
        sc = load_scenario(f.stem)
        assert sc.substeps == 4
    v = load_vehicle("ellipsled")
    assert v.mass_kg == 1200.0 and v.torque_matrix_Nm.shape == (3, 18)
    assert np.allclose(np.diag(v.inertia_kgm2), [2109.0, 5053.0, 5053.0])
    p = load_planet("mars")
    assert p.mu_m3ps2 == 4.2828e13 and p.radius_m == 3396.2e3
    sc = load_scenario("nominal")
    assert sc.altitude_m == 125e3 and sc.speed_rel_mps == 7300.0
    assert sc.flight_path_rad == pytest.approx(math.radians(-12.0))
    assert sc.bank0_rad == pytest.approx(math.radians(90.0))


def mutate(tmp_path: Path, src: Path, old: str, new: str) -> Path:
    text = src.read_text()
    assert old in text, old
    dst = tmp_path / src.name
    dst.write_text(text.replace(old, new, 1))
    return dst


def expect(loader, path, field, reason):
    with pytest.raises(ConfigError) as ei:
        loader(path)
    msg = str(ei.value)
    assert str(path) in msg, msg
    assert ei.value.field == field, msg
    assert re.search(reason, msg), msg


VEHICLE_CASES = [
    ("mass_kg = 1200.0", "mass_kg = -3.0", "vehicle.mass_kg", "must be > 0"),
    ("mass_kg = 1200.0", "mass_kg = \"heavy\"", "vehicle.mass_kg", "must be a number"),
    ("mass_kg = 1200.0", "mass_kg = nan", "vehicle.mass_kg", "finite"),
    ("S_ref_m2 = 11.04\n", "", "vehicle.S_ref_m2", "missing"),
    ("mass_kg = 1200.0", "mass_kgg = 1200.0", "vehicle.mass_kg", "missing"),
    ("l_ref_m = 3.75", "l_ref_m = 3.75\nlref_m = 3.75", "vehicle.lref_m", "unknown key"),
    ("I12 = -21.0", "I12 = -6000.0", "vehicle.inertia_kgm2", "positive definite"),
    ("I11 = 2109.0", "I11 = 20000.0", "vehicle.inertia_kgm2", "triangle inequality"),
    ("I22 = 5053.0", "I22 = 0.0", "vehicle.inertia_kgm2.I22", "must be > 0"),
    ("C_D = 1.20", "C_D = 0.0", "aero.C_D", "must be > 0"),
    ("alpha_trim_deg = 20.0", "alpha_trim_deg = 120.0", "aero.alpha_trim_deg", "<= 90"),
    ("thrust_N = [14, 14,", "thrust_N = [14,", "jets.thrust_N", "18 elements"),
    ("torque_matrix_Nm = [\n", "torque_matrix_Nm = [\n  [1.0, 2.0],\n", "jets.torque_matrix_Nm", "list of 3 rows"),
    ("[-26.32,   0.00,  26.32,  26.32,", "[-26.32,  26.32,  26.32,", "jets.torque_matrix_Nm", "row 1 must be a list of 18"),
    ('model = "matrix"', 'model = "matrx"', "jets.model", "must be one of"),
    ('model = "matrix"', 'model = "geometry"', "jets.jet", "must list 18 jets"),
]


@pytest.mark.parametrize("old,new,field,reason", VEHICLE_CASES, ids=[c[2] + ":" + c[3] for c in VEHICLE_CASES])
def test_bad_vehicle_file_is_rejected_naming_file_and_field(tmp_path, old, new, field, reason):
    expect(load_vehicle, mutate(tmp_path, VEHICLE, old, new), field, reason)


def test_bad_geometry_jet_is_rejected(tmp_path):
    text = VEHICLE.read_text().replace('model = "matrix"', 'model = "geometry"')
    text = text.split("thrust_N =")[0]
    for k in range(18):
        d = "[0.0, 0.0, 0.0]" if k == 4 else "[0.0, 1.0, 0.0]"
        text += f"\n[[jets.jet]]\nposition_m = [1.0, 0.0, 0.0]\ndirection = {d}\nthrust_N = 14.0\n"
    p = tmp_path / "geo.toml"
    p.write_text(text)
    expect(load_vehicle, p, "jets.jet[4].direction", "non-zero")


SCENARIO_CASES = [
    ("altitude_m = 125000.0", "altitude_m = -5.0", "initial.altitude_m", "must be > 0"),
    ("flight_path_deg = -12.0", "flight_path_deg = -90.0", "initial.flight_path_deg", "> -90"),
    ("dt_integrator_s = 0.005", "dt_integrator_s = 0.003", "scenario.dt_integrator_s", "whole number"),
    ("seed = 1", "seed = 1.5", "scenario.seed", "integer"),
    ("[60.0, -85.0], [130.0, 60.0]", "[160.0, -85.0], [130.0, 60.0]", "guidance.bank_schedule", "times must increase"),
    ("[60.0, -85.0]", "[60.0, -185.0]", "guidance.bank_schedule", r"within \[-180, 180\]"),
    ("rate_limit_dps = 8.0", "rate_limit_dps = 0.0", "guidance.rate_limit_dps", "must be > 0"),
    ("I11 = 1.20,", "I11 = 1.20, I14 = 1.0,", "truth.inertia_scale.I14", "unknown key"),
    ("I12 = 1.30,", "I12 = 300.0,", "truth.inertia_scale.I11", "not positive definite"),
    ("density_scale = 1.20", "density_scale = -1.0", "truth.density_scale", "must be > 0"),
    ("flight_path_deg = -12.0", "flight_path_deg = -12.0\nflight_path_rad = -0.2", "initial.flight_path_rad",
     "not both"),
    ("flight_path_deg = -12.0", "flight_path_rad = -1.6", "initial.flight_path_rad", "> -1.57"),
    ("density_scale = 1.20", "density_scale = 1.20\ndensity_waves = [[0.6, 7000.0, 0.0], [0.5, 15000.0, 1.0]]",
     "truth.density_waves", "sum below 1"),
    ("density_scale = 1.20", "density_scale = 1.20\ndensity_waves = [[0.1, 0.0, 0.0]]", "truth.density_waves",
     "wavelength must be > 0"),
    ("density_scale = 1.20", "density_scale = 1.20\ndensity_waves = [[0.1, 7000.0]]", "truth.density_waves",
     "entry 1 must be"),
    ("density_scale = 1.20", "density_scale = 1.20\ndensity_waves = [[0.01, 1e3, 0.0]" + ", [0.01, 1e3, 0.0]" * 4 + "]",
     "truth.density_waves", "at most 4"),
    ("gyro_bias_radps = [0.0, 0.0, 0.0]", "gyro_bias_radps = [0.0, 0.0]", "sensors.gyro_bias_radps", "3 elements"),
    ("chamber_noise = 0.02", "chamber_noise = 2.0", "sensors.chamber_noise", "<= 1"),
    ("[end]", "[ends]", "ends", "unknown key"),
    ('vehicle = "ellipsled"', 'vehicle = "elipsled"', "<file>", "no vehicle named"),
]


@pytest.mark.parametrize("old,new,field,reason", SCENARIO_CASES, ids=[c[2] + ":" + c[3] for c in SCENARIO_CASES])
def test_bad_scenario_file_is_rejected_naming_file_and_field(tmp_path, old, new, field, reason):
    path = mutate(tmp_path, SCENARIO, old, new)
    with pytest.raises(ConfigError) as ei:
        load_scenario(path)
    msg = str(ei.value)
    assert ei.value.field == field, msg
    assert re.search(reason, msg), msg
    if field != "<file>":
        assert str(path) in msg


FAULT_CASES = [
    ("jets = [19]\nkind = \"failed_off\"", "faults[0].jets", "jet numbers 1..18"),
    ("jets = []\nkind = \"failed_off\"", "faults[0].jets", "non-empty"),
    ("jets = [1, 1]\nkind = \"failed_off\"", "faults[0].jets", "more than once"),
    ("jets = [true]\nkind = \"failed_off\"", "faults[0].jets", "jet numbers"),
    ("jets = [1]\nkind = \"broken\"", "faults[0].kind", "must be one of"),
    ("jets = [1]\nkind = \"degraded\"", "faults[0].eta", "required"),
    ("jets = [1]\nkind = \"degraded\"\neta = 1.0", "faults[0].eta", "< 1"),
    ("jets = [1]\nkind = \"degraded\"\neta = 0.0", "faults[0].eta", "> 0"),
    ("jets = [1]\nkind = \"failed_off\"\neta = 0.5", "faults[0].eta", "degraded\" only"),
    ("jets = [1]\nkind = \"failed_off\"\nwhen = 3.0", "faults[0].when", "unknown key"),
]


GUIDED = DATA_DIR / "scenarios" / "guided-nominal.toml"
GUIDED_CASES = [
    ('mode = "npc"', 'mode = "fnpeg"', "guidance.mode", "must be one of profile, npc"),
    ("[target]\nlatitude_deg = 0.0\n", "[nottarget]\nlatitude_deg = 0.0\n", "target", "needs a \\[target\\]"),
    ("latitude_deg = 0.0\nlongitude_deg = 16.5", "latitude_deg = 95.0\nlongitude_deg = 16.5", "target.latitude_deg",
     "<= 90"),
    ("longitude_deg = 16.5", "longitude_deg = 16.5\nheight_m = 0.0", "target.height_m", "unknown key"),
    ("mach = 2.0", "mach = 2.0\nspeed_mps = 450.0", "end.speed_mps", "not both"),
    ("mach = 2.0", "speed_mps = -4.0", "end.speed_mps", "must be > 0"),
]


@pytest.mark.parametrize("old,new,field,reason", GUIDED_CASES, ids=[c[2] + ":" + c[3] for c in GUIDED_CASES])
def test_bad_guided_scenario_is_rejected_naming_file_and_field(tmp_path, old, new, field, reason):
    path = mutate(tmp_path, GUIDED, old, new)
    with pytest.raises(ConfigError) as ei:
        load_scenario(path)
    msg = str(ei.value)
    assert ei.value.field == field, msg
    assert re.search(reason, msg), msg
    assert str(path) in msg


def test_guided_scenario_fields_and_vehicle_limits_load():
    sc = load_scenario("guided-nominal")
    assert sc.guidance_mode == "npc" and sc.heading_rad == pytest.approx(math.radians(90.0))
    assert sc.target_lon_rad == pytest.approx(math.radians(16.5)) and sc.end_mach == 2.0
    assert sc.bank_schedule == ((0.0, math.radians(65.0)),)      # the reference starts at the initial bank
    assert load_scenario("nominal").guidance_mode == "profile"
    v = sc.vehicle
    assert v.nose_radius_m == 1.875 and v.max_load_g > 0 and v.max_heat_rate_wcm2 > 0


@pytest.mark.parametrize("body,field,reason", FAULT_CASES, ids=[c[1] + ":" + c[2] for c in FAULT_CASES])
def test_bad_fault_entries_are_rejected(tmp_path, body, field, reason):
    path = tmp_path / "f.toml"
    path.write_text(SCENARIO.read_text() + f"\n[[faults]]\nt_s = 2.5\n{body}\n")
    expect(load_scenario, path, field, reason)


def test_negative_fault_time_rejected(tmp_path):
    path = tmp_path / "f.toml"
    path.write_text(SCENARIO.read_text() + '\n[[faults]]\nt_s = -1.0\njets = [2]\nkind = "stuck_on"\n')
    expect(load_scenario, path, "faults[0].t_s", ">= 0")


@pytest.mark.parametrize("old,new,field,reason", [
    ("mu_m3ps2 = 4.2828e13", "mu_m3ps2 = 0.0", "planet.mu_m3ps2", "must be > 0"),
    ('model = "exponential"', 'model = "isothermal"', "atmosphere.model", "must be one of"),
    ("use_j2 = false", "use_j2 = 0", "planet.use_j2", "true or false"),
    ("scale_height_m = 9354.5", "scale_hieght_m = 9354.5", "atmosphere.scale_height_m", "missing"),
])
def test_bad_planet_file_is_rejected(tmp_path, old, new, field, reason):
    expect(load_planet, mutate(tmp_path, PLANET, old, new), field, reason)


def test_not_toml_and_missing_file_are_config_errors(tmp_path):
    p = tmp_path / "x.toml"
    p.write_text("[vehicle\nname = 1")
    expect(load_vehicle, p, "<file>", "not valid TOML")
    expect(load_vehicle, tmp_path / "absent.toml", "<file>", "file not found")
