"""MAVSDK, a stock ground station that cannot sign (no key API), against a real-time SIL on
loopback: it identifies the vehicle, watches it and its events, reads its parameters,
metadata and mission, and cannot change it. The MAVSDK side runs in its own process
(tests/mavsdk_station.py), stopped by its pid; the SIL is ``ellipsled run --realtime`` with
a ground link on free ports.

Checked against the run itself: the velocity MAVSDK showed against the plant's truth
history (within 1 %), the parameters against the FSW process's own report, the refused
parameter set and injection against the FSW's parameters and the plant's faults, the
vehicle's event log for refusal noise, and the events MAVSDK's events plugin showed against
that log and the event catalogue.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from common.model import load_scenario
from ellipsled.sil.history import History
from fsw.flightsoftware import declarations
from fsw.groundlink.link import REFUSAL_EVENT
from fsw.groundlink.services import PRODUCT_ID, VENDOR_ID
from fsw.params import ParamRegistry
from interfaces import event_metadata
from interfaces.event_catalogue import CATALOGUE, COMPONENT_ID, NAMESPACE
from interfaces.vocabulary import Mode
from tests.procs import start_ground_sil, stop

pytest.importorskip("mavsdk", reason="MAVSDK is not installed (requirements.lock pins it)")
pytestmark = [pytest.mark.slow, pytest.mark.realtime]

STATION = Path(__file__).with_name("mavsdk_station.py")
SET_ID, SET_NAME = "F_ALT_MAX_M", "fdir.alt_max_m"


def _ned_axes(lat: float, lon: float) -> np.ndarray:
    """Rows north, east, down at (lat, lon) on a sphere, in the planet-fixed frame."""
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    return np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])


@pytest.fixture(scope="module")
def contact(tmp_path_factory):
    """One keyless MAVSDK contact with a real-time SIL: (station result, run output folder)."""
    tmp = tmp_path_factory.mktemp("mavsdk")
    sil = start_ground_sil(tmp, duration_s=100.0)
    result = tmp / "mavsdk.json"
    home = tmp / "home"                       # MAVSDK caches metadata under ~/.cache: start empty
    home.mkdir()
    env = {"HOME": str(home), "XDG_CACHE_HOME": str(home / ".cache"), "PATH": "/usr/bin:/bin",
           "PYTHONPATH": str(STATION.parent.parent)}
    with open(tmp / "mavsdk.log", "w") as log:
        station = subprocess.Popen([sys.executable, str(STATION), "--url", f"udpin://127.0.0.1:{sil.gcs}",
                                    "--out", str(result), "--watch-s", "20"],
                                   stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                                   cwd=tmp)
    try:
        station.wait(300)
        assert sil.run.wait(200) == 0, sil.log()
    finally:
        stop(station, 10.0)
        stop(sil.run)
    assert result.exists(), (tmp / "mavsdk.log").read_text() + sil.log()
    res = json.loads(result.read_text())
    assert "crash" not in res, res["crash"]
    return res, sil.out


def test_mavsdk_connects_and_identifies_the_vehicle(contact):
    res, _ = contact
    assert res["connected"] is True, res
    ident = res["identity"].get("ok")
    assert ident is not None, res["identity"]
    assert (ident["vendor_id"], ident["product_id"]) == (VENDOR_ID, PRODUCT_ID)
    assert (ident["major"], ident["minor"], ident["patch"]) == (0, 1, 0)      # pyproject.toml
    assert ident["git_hash"].strip("0")                                 # flight_custom_version: the source digest


def test_mavsdk_velocity_is_within_one_percent_of_the_plants_truth(contact):
    """LOCAL_POSITION_NED as MAVSDK shows it (position_velocity_ned, no time stamp): each
    sample is dated by where it puts the vehicle on the truth trajectory (truth positions
    expressed in the origin's frame, the origin from GPS_GLOBAL_ORIGIN), then its velocity is
    compared with the truth velocity there, rotated into the same frame."""
    res, out = contact
    lat0, lon0 = (math.radians(x) for x in res["origin"]["ok"][:2])
    samples = np.array(res["velocity_samples"])
    assert len(samples) >= 20, res
    R = load_scenario("nominal").planet.radius_m
    h = History.load(out / "history.npz")
    lat, lon, alt = (np.asarray(h[k], dtype=float) for k in ("lat_rad", "lon_rad", "h_m"))
    V, gam, psi = (np.asarray(h[k], dtype=float) for k in ("V_rel_mps", "gamma_rad", "psi_rad"))
    up_P = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=1)
    C0 = _ned_axes(lat0, lon0)
    r0_P = R * np.array([math.cos(lat0) * math.cos(lon0), math.cos(lat0) * math.sin(lon0), math.sin(lat0)])
    x_truth = ((R + alt)[:, None] * up_P - r0_P) @ C0.T
    worst = 0.0
    for s in samples:
        x, v = s[1:4], s[4:7]
        i = int(np.argmin(np.linalg.norm(x_truth - x, axis=1)))
        assert np.linalg.norm(x_truth[i] - x) < 2_000.0, (x, x_truth[i])           # on the trajectory
        v_local = V[i] * np.array([math.cos(gam[i]) * math.cos(psi[i]), math.cos(gam[i]) * math.sin(psi[i]),
                                   -math.sin(gam[i])])
        v_truth = C0 @ (_ned_axes(lat[i], lon[i]).T @ v_local)
        err = float(np.linalg.norm(v - v_truth) / V[i])
        worst = max(worst, err)
        assert V[i] > 1000.0 and err < 0.01, (v, v_truth, err)
    print(f"MAVSDK velocity vs truth: {len(samples)} samples, worst {worst:.2%}, |v| {V.min():.0f}-{V.max():.0f} m/s")


def test_mavsdk_shows_the_modes_by_name(contact):
    res, _ = contact
    modes = res["modes"]["ok"]
    assert modes["modes"] == {str(int(m)): m.name for m in Mode}, modes
    assert modes["modes"][str(modes["current"])] in ("ENTRY", "STANDBY", "SAFE")
    assert modes["ack"] == 0                                                   # MAV_RESULT_ACCEPTED


def test_mavsdk_reads_parameters_metadata_and_the_mission(contact):
    res, out = contact
    report = json.loads((out / "fsw.json").read_text())["params"]
    ids = ParamRegistry(declarations()).ids
    shown = res["params"]["ok"]
    assert set(shown) == set(ids.values())
    for name, pid in ids.items():
        assert shown[pid] == pytest.approx(report[name], rel=1e-6), pid        # sent as float32
    assert res["ftp_list"]["ok"] == ["events.json", "general.json", "parameters.json"], res["ftp_list"]
    meta = res["metadata"]["ok"]
    assert {p["name"] for p in meta["parameters"]} == set(ids.values()), res["metadata"]
    assert res["mission"] == {"ok": 0}


def test_mavsdk_cannot_set_a_parameter_or_inject_a_fault(contact):
    res, out = contact
    assert "error" in res["param_set"] and "error" in res["inject"], (res["param_set"], res["inject"])
    assert "DENIED" in res["inject"]["error"].upper()
    fsw = json.loads((out / "fsw.json").read_text())
    assert fsw["params"][SET_NAME] == ParamRegistry(declarations()).defaults[SET_NAME]
    link = fsw["ground_link"]
    assert link["commands_accepted"] == 0 and link["params_set"] == 0 and link["peers_added"] == 0
    assert link["unsigned_writes"] >= 1                                   # the injection, refused by the link
    assert fsw["detections"] == []                                        # nominal: no jet ever failed


def test_the_vehicles_event_log_is_free_of_refusal_noise(contact):
    _, out = contact
    log = json.loads((out / "fsw.json").read_text())["event_log"]
    link = [e for e in log if e["source"] == "link"]
    assert len([e for e in link if e["code"] == REFUSAL_EVENT]) <= 2, link
    assert len(link) <= 2, link


def test_mavsdk_receives_events_with_their_severity(contact):
    """MAVSDK's events plugin read the events metadata the vehicle serves (the catalogue's,
    over FTP) and shows the EVENTs of the contact — at least the refusal of its own unsigned
    writes — by name, with the severity of the vehicle's own event log and the message the
    catalogue gives."""
    res, out = contact
    assert res["events_metadata"].get("ok") == event_metadata.events_metadata(), res["events_metadata"]
    forms = {event_metadata.form_name(e, f): (e, f) for e in CATALOGUE for f in e.forms}
    told = {(e["code"], e["severity"]) for e in json.loads((out / "fsw.json").read_text())["event_log"]}
    got = res["events"]
    assert got, res
    for ev in got:
        entry, form = forms[ev["name"]]
        assert (ev["namespace"], ev["compid"]) == (NAMESPACE, COMPONENT_ID)
        assert (entry.name, ev["log_level"]) in told, (ev, sorted(told))
        assert ev["message"] and ev["description"].startswith(entry.doc)
        if not entry.wire_args(form):                 # no values: the message is the metadata's own
            assert ev["message"] == event_metadata.ground_message(entry, form)
    assert any(ev["name"] == REFUSAL_EVENT and ev["log_level"] == "WARNING" for ev in got), got
