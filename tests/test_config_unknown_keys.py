"""A misspelt key in any table of a data file (scenario, its [fsw.*] overrides, vehicle,
planet) is refused with the file, the dotted key and the nearest valid name, never
ignored: `[fsw.fdir] dealy_s = 1.5` would otherwise fly case 4 without its 1.5 s delay."""
from __future__ import annotations

import subprocess

import pytest

from common.config import DATA_DIR, ConfigError
from common.model import load_scenario, load_vehicle
from ellipsled.procs import ELLIPSLED


CASE4 = DATA_DIR / "scenarios" / "case4.toml"


def _copy(tmp_path, src, old, new, name="x.toml"):
    text = src.read_text()
    assert old in text
    dst = tmp_path / name
    dst.write_text(text.replace(old, new, 1))
    return dst


@pytest.mark.parametrize("old,new,field,hint", [
    ("delay_s = 1.5", "dealy_s = 1.5", "fsw.fdir.dealy_s", "did you mean delay_s?"),
    ("[fsw.fdir]", "[fsw.fdri]", "fsw.fdri", "did you mean fdir?"),
    ("fault_tolerance = 1", "fault_tolerence = 1", "fsw.allocator.fault_tolerence", "did you mean fault_tolerance?"),
    ("[fsw.fdir]\ndelay_s = 1.5", "[fsw.fdir]\ndelay_s = 1.5\nqqq = 2", "fsw.fdir.qqq", "valid: .*delay_s"),
    ("C_nbeta_scale = 1.20", "C_nbeta_scale = 1.20\nC_nbetta_scale = 1.0", "truth.C_nbetta_scale",
     "did you mean C_nbeta_scale?"),
    ("rate_limit_dps = 8.0", "rate_limt_dps = 8.0\nrate_limit_dps = 8.0", "guidance.rate_limt_dps",
     "did you mean rate_limit_dps?"),
])
def test_a_misspelt_scenario_key_is_refused_with_file_key_and_nearest_name(tmp_path, old, new, field, hint):
    path = _copy(tmp_path, CASE4, old, new)
    with pytest.raises(ConfigError) as e:
        load_scenario(path)
    assert e.value.file == str(path) and e.value.field == field, str(e.value)
    assert "unknown key" in str(e.value)
    assert __import__("re").search(hint, str(e.value)), str(e.value)


def test_a_misspelt_vehicle_key_names_the_nearest_valid_one(tmp_path):
    path = _copy(tmp_path, DATA_DIR / "vehicles" / "ellipsled.toml", "l_ref_m = 3.75", "l_ref_m = 3.75\nlref_m = 3.75")
    with pytest.raises(ConfigError, match=r"vehicle\.lref_m: unknown key \(did you mean l_ref_m\?\)"):
        load_vehicle(path)


def test_the_parameter_registry_refuses_an_override_nobody_declares():
    from fsw.flightsoftware import declarations
    from fsw.params import ParamRegistry
    with pytest.raises(ConfigError, match=r"fdir\.dealy_s: unknown key \(did you mean fdir\.delay_s\?\)"):
        ParamRegistry(declarations(), {"fdir": {"dealy_s": 1.5}})
    assert ParamRegistry(declarations(), {"fdir": {"delay_s": 1.5}}).values["fdir.delay_s"] == 1.5


def test_batch_refuses_the_misspelt_override_with_exit_status_2(tmp_path):
    path = _copy(tmp_path, CASE4, "delay_s = 1.5", "dealy_s = 1.5")
    r = subprocess.run(ELLIPSLED + ["batch", str(path), "--out", str(tmp_path / "out"), "--duration", "0.1",
                                    "--no-plots"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stdout + r.stderr
    assert f"{path}: fsw.fdir.dealy_s: unknown key (did you mean delay_s?)" in r.stderr
    assert "Traceback" not in r.stderr
