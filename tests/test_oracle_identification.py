"""Oracle identification (fdir.mode = "oracle", a test mode): the plant's fault log is FDIR's
identification, as the paper assumed (perfect and instantaneous). Truth: the scenario
file's fault time and delay, and the plant's own fault log; the same in batch and in the
lockstep SIL, where the log crosses the process boundary on sim/fault_log."""
from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from common.events import EventLog
from common.model import load_scenario
from ellipsled import batch, runlib
from ellipsled.procs import ELLIPSLED
from fsw.fdir import Fdir
from fsw.flightsoftware import all_params
from fsw.health import DEGRADED, FAILED_OFF
from fsw.params import load_params


def _fault(name: str):
    f = load_scenario(name).faults[0]
    return f.t_s, sorted(f.jets), load_scenario(name).fsw["fdir"]["delay_s"]


@pytest.mark.parametrize("case", ["case1", "case4"])
def test_batch_oracle_reconfigures_at_fault_time_plus_delay(case):
    t_fault, jets, delay = _fault(case)
    s, _, fsw = batch.run(case, duration_s=8.0, identification="oracle", reference=False)
    assert s["reconfig_t_s"] == pytest.approx(t_fault + delay, abs=1e-9)     # case1: 2.5, case4: 4.0
    assert sorted(d["jet"] for d in s["fdir"]["detections"]) == jets
    assert all(d["t_s"] == pytest.approx(t_fault, abs=1e-9) for d in s["fdir"]["detections"])
    assert s["fdir"]["false_alarms"] == 0 and not s["fdir"]["missed"]
    assert s["identification"] == "oracle" and "oracle" in s["test_mode"]
    assert "TEST MODE" in runlib.format_summary(s)
    assert any(e.code == "fdir_oracle" for e in fsw.events.history)


def test_detect_mode_is_the_default_and_finds_the_fault_after_the_fact():
    s, _, _ = batch.run("case1", duration_s=8.0, reference=False)
    assert s["identification"] == "detect" and "test_mode" not in s
    assert s["reconfig_t_s"] > 2.5


def test_oracle_declares_degraded_with_the_plants_eta_and_detect_mode_refuses_it():
    p = load_params(all_params(), {"fdir": {"mode": "oracle", "delay_s": 0.5}})
    f = Fdir(p, 0.02, EventLog())
    u, ch = np.zeros(18, np.uint8), np.zeros(18)
    f.identified(1.0, 3, "degraded", 0.4)
    f.identified(1.0, 7, "failed_off")
    assert not f.update(1.48, u, ch)                     # not yet: delay 0.5 s
    assert f.update(1.5, u, ch)
    assert f.health_active.state[2] == DEGRADED and f.health_active.eta[2] == pytest.approx(0.4)
    assert f.health_active.state[6] == FAILED_OFF
    u[:] = 1                                             # the jet monitor is off: no chamber, no finding
    for k in range(20):
        f.update(2.0 + 0.02 * k, u, ch)
    assert len(f.detections) == 2
    with pytest.raises(ValueError):
        f.identified(1.0, 3, "sideways")
    det = Fdir(load_params(all_params()), 0.02, EventLog())
    with pytest.raises(ValueError):
        det.identified(1.0, 3, "failed_off")


def test_lockstep_sil_oracle_reconfigures_at_fault_time_plus_delay_and_equals_batch(tmp_path):
    out = tmp_path / "sil"
    r = subprocess.run(ELLIPSLED + ["run", "case4", "--lockstep", "--identification", "oracle", "--duration", "6",
                                    "--out", str(out), "--rerun", "none", "--no-plots"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "TEST MODE" in r.stdout
    s = json.loads((out / "summary.json").read_text())
    assert s["reconfig_t_s"] == pytest.approx(4.0, abs=1e-9)
    assert s["identification"] == "oracle" and "oracle" in s["test_mode"]
    fsw_json = json.loads((out / "fsw.json").read_text())
    assert any(e["code"] == "fdir_oracle" for e in fsw_json["event_log"])
    s_bat, h_bat, _ = batch.run("case4", duration_s=6.0, identification="oracle", reference=False)
    h_sil = np.load(out / "history.npz")
    for name in ("bank_rad", "omega_BN_B", "jets_cmd", "health", "theta_hat"):
        assert np.array_equal(h_sil[name], h_bat[name]), name
