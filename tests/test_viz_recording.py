"""gse/viz: recordings written from a History read back with rerun.chunk.RrdReader and
checked by `rerun rrd verify`; batching, 'none' mode, bad input, sinks."""
from __future__ import annotations

import math
import subprocess

import numpy as np
import pytest

from common.events import Event, Severity
from common.model import load_planet
from ellipsled.sil.history import History
from gse.viz import RerunLogger, open_sinks, record_history
from gse.viz.blueprint import VIEW_NAMES
from gse.viz.logger import SCALAR_CHANNELS, TRUTH
from gse.viz.record import r_N_from_history
from gse.viz.sinks import parse_mode
from interfaces.event_catalogue import EV
from interfaces.event_metadata import markdown
from interfaces.records import GUID_NPC, GUID_PREDICTION, GUID_TARGET
from interfaces.vocabulary import N_JETS

from tests.rrd import RERUN, column, read_recording

N = 240
DT = 0.02


def _history(n: int = N) -> History:
    h = History(n)
    for _ in range(n):
        h.row()
    t = np.arange(n) * DT
    a = h.a
    a["t_s"][:] = t
    a["bank_rad"][:] = 0.6 * np.sin(0.7 * t) + 0.3
    a["bank_ref_rad"][:] = 0.6 * np.sin(0.7 * t)
    a["bank_err_rad"][:] = 0.3             # the FSW's own: navigation exact here
    a["alpha_rad"][:] = np.deg2rad(20) + 0.01 * np.cos(t)
    a["omega_BN_B"][:] = np.stack([0.01 * t, -0.02 * t, 0.005 * np.ones(n)], axis=1)
    a["sigma_BN"][:] = np.stack([0.05 * np.sin(t), 0.1 * np.cos(t), 0.2 * t / t[-1]], axis=1)
    a["h_m"][:] = 125e3 - 500.0 * t
    a["lat_rad"][:] = 0.2 + 1e-4 * t
    a["lon_rad"][:] = -0.1 + 2e-4 * t
    a["V_rel_mps"][:] = 5500 - 10 * t
    a["theta_hat"][:] = np.arange(9)[None, :] + t[:, None]
    a["u_cal_B"][:] = np.stack([np.sin(t), np.cos(t), t], axis=1)
    a["jets_cmd"][:] = (np.arange(n)[:, None] + np.arange(N_JETS)[None, :]) % 4 == 0
    a["health"][n // 2:, 6] = 1            # jet 7 failed off halfway
    a["mode"][:] = 1
    a["compute_us"][:] = 300 + np.arange(n) % 7
    # guidance (mode npc): target known from the start, an answer every 50 steps from step 20
    a["guid_flags"][:] = GUID_TARGET | GUID_NPC
    a["guid_flags"][20:] |= GUID_PREDICTION
    a["target_lat_rad"][:], a["target_lon_rad"][:] = 0.2, 0.05
    a["guid_cycles"][:] = (np.arange(n) + 30) // 50
    a["pred_lat_rad"][:] = 0.2 + 0.01 * a["guid_cycles"]
    a["pred_lon_rad"][:] = 0.05 + 0.02 * a["guid_cycles"]
    return h


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    h = _history()
    events = [Event(1.0, Severity.WARNING, "fdir", "jet_failed_off", "jet 7 failed off"),
              Event(2.5, Severity.CRITICAL, "modes", "safe", "safe mode")]
    path = record_history(h, events, tmp_path_factory.mktemp("viz") / "batch.rrd")
    ents, reader = read_recording(path)
    return h, path, ents, reader


def test_recording_passes_rrd_verify(recorded):
    _, path, _, _ = recorded
    r = subprocess.run([RERUN, "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr + r.stdout


def test_recording_has_expected_entities_and_blueprint(recorded):
    _, _, ents, reader = recorded
    expected = {"/" + c.entity for c in SCALAR_CHANNELS if c.field not in ("jitter_us", "slips")}
    expected |= {"/jets/lanes", "/jets/n_firing", "/jets/health", "/jets/health_code", "/fsw/mode",
                 "/world/vehicle", "/world/trajectory", "/world/vehicle/body", "/attitude/body",
                 "/attitude/body/jets", "/attitude/reference", "/events"}
    assert expected <= set(ents), sorted(expected - set(ents))
    assert "/timing/jitter_us" not in ents      # never provided by a batch History: not invented
    bps = reader.blueprints()
    assert len(bps) == 1 and len(reader.recordings()) == 1
    text = "".join(str(c.to_record_batch().columns) for c in reader.stream(store=bps[0]))
    for name in ("Bank vs reference", "Trajectory", "Attitude", "Events", "Jets firing", "Loop timing"):
        assert name in text and name in VIEW_NAMES


def test_map_has_the_ground_track_the_target_and_one_predicted_point_per_guidance_answer(recorded):
    h, _, ents, reader = recorded
    steps, _, strips = column(ents["/map/track"], "LineStrips3D:strips")
    assert list(steps) == list(range(0, N, 10))                # decimated: every 10th step
    ends = np.array([s[0][-1] for s in strips])
    np.testing.assert_allclose(ends[:, 0], np.degrees(h["lon_rad"][::10]), rtol=1e-6)
    np.testing.assert_allclose(ends[:, 1], np.degrees(h["lat_rad"][::10]), rtol=1e-6)
    assert np.all(ends[:, 2] == 0.0)
    starts = np.array([s[0][0] for s in strips])
    np.testing.assert_allclose(starts[1:], ends[:-1])          # a connected track
    steps, _, tgt = column(ents["/map/target"], "Points3D:positions")
    assert len(steps) == 1 and np.allclose(tgt[0][0], [math.degrees(0.05), math.degrees(0.2), 0.0])
    # a predicted point at each new answer only (guidance rate, not the 50 Hz rows)
    steps, _, pts = column(ents["/map/predicted"], "Points3D:positions")
    assert list(steps) == [20, 70, 120, 170, 220]
    cyc = (np.array(steps) + 30) // 50
    np.testing.assert_allclose([p[0][:2] for p in pts],
                               np.degrees(np.stack([0.05 + 0.02 * cyc, 0.2 + 0.01 * cyc], axis=1)), rtol=1e-6)
    steps, _, miss = column(ents["/guidance/predicted_miss_km"], "Scalars:scalars")
    R = load_planet("mars").radius_m
    lat1, lon1 = 0.2 + 0.01 * cyc, 0.05 + 0.02 * cyc
    # independent: the spherical law of cosines
    want = R / 1e3 * np.arccos(np.sin(lat1) * math.sin(0.2) + np.cos(lat1) * math.cos(0.2) * np.cos(lon1 - 0.05))
    assert list(steps) == [20, 70, 120, 170, 220]
    np.testing.assert_allclose([m[0] for m in miss], want, rtol=1e-6)
    text = "".join(str(c.to_record_batch().columns) for c in reader.stream(store=reader.blueprints()[0]))
    assert "Ground track" in text and "Predicted miss" in text


def test_bank_series_equals_history_at_every_step(recorded):
    h, _, ents, _ = recorded
    steps, times, vals = column(ents["/bank/actual_deg"], "Scalars:scalars")
    assert list(steps) == list(range(N))
    got = np.array([v[0] for v in vals])
    np.testing.assert_allclose(got, np.degrees(h["bank_rad"]), rtol=0, atol=1e-12)
    # sim_time timeline is the History time, to the nanosecond
    t_ns = np.asarray(times, dtype=np.int64)
    np.testing.assert_array_equal(t_ns, np.rint(h["t_s"] * 1e9).astype(np.int64))
    # error = wrap(bank - ref) = 0.3 rad exactly here
    _, _, err = column(ents["/bank/error_deg"], "Scalars:scalars")
    np.testing.assert_allclose([e[0] for e in err], math.degrees(0.3), atol=1e-9)
    _, _, th = column(ents["/adapt/theta_hat"], "Scalars:scalars")
    np.testing.assert_allclose(np.array(th), h["theta_hat"], atol=1e-12)


def test_vehicle_pose_is_attitude_and_position(recorded):
    h, _, ents, _ = recorded
    steps, _, q = column(ents["/world/vehicle"], "Transform3D:quaternion")
    _, _, tr = column(ents["/world/vehicle"], "Transform3D:translation")
    for k in (0, 77, N - 1):
        x, y, z, w = q[k][0]
        # body x axis expressed in N by the quaternion (active rotation) ...
        R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                      [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                      [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
        # ... equals the first row of C_BN from the MRP closed form (Schaub & Junkins 3.153)
        s = h["sigma_BN"][k]
        s2 = s @ s
        S = np.array([[0, -s[2], s[1]], [s[2], 0, -s[0]], [-s[1], s[0], 0]])
        C_BN = np.eye(3) + (8 * S @ S - 4 * (1 - s2) * S) / (1 + s2) ** 2
        np.testing.assert_allclose(R, C_BN.T, atol=2e-6)
        # translation [km] on the sphere of radius R + h
        pl = load_planet("mars")
        np.testing.assert_allclose(np.linalg.norm(tr[k][0]), (pl.radius_m + h["h_m"][k]) / 1e3, rtol=1e-6)


def test_r_N_from_history_matches_spherical_position():
    pl = load_planet("mars")
    r = r_N_from_history(np.array([0.0]), np.array([0.0]), np.array([0.0]), np.array([0.0]), pl)
    np.testing.assert_allclose(r[0], [pl.radius_m, 0, 0])
    t = math.pi / 2 / pl.omega_radps       # a quarter turn later, lon 0 points along N2
    r = r_N_from_history(np.array([1000.0]), np.array([0.0]), np.array([0.0]), np.array([t]), pl)
    np.testing.assert_allclose(r[0], [0, pl.radius_m + 1000, 0], atol=1e-6)


def test_jets_health_mode_and_events(recorded):
    h, _, ents, _ = recorded
    _, _, lanes = column(ents["/jets/lanes"], "Scalars:scalars")
    on = np.array(lanes) - np.arange(1, 19)[None, :]
    np.testing.assert_allclose(on, 0.8 * h["jets_cmd"], atol=1e-12)
    steps, _, arrows = column(ents["/attitude/body/jets"], "Arrows3D:vectors")
    assert [len(a or []) for a in arrows] == list(h["jets_cmd"].sum(axis=1))
    steps, _, states = column(ents["/jets/health"], "StateChange:state")
    assert list(steps) == [0, N // 2]                   # logged on change only
    assert states[1][6] == "failed_off" and states[0][6] == "nominal"
    steps, _, modes = column(ents["/fsw/mode"], "StateChange:state")
    assert list(steps) == [0] and modes[0] == ["ENTRY"]
    steps, _, text = column(ents["/events"], "TextLog:text")
    _, _, level = column(ents["/events"], "TextLog:level")
    assert list(steps) == [50, 125] and "jet_failed_off" in text[0][0]
    assert level == [["WARN"], ["CRITICAL"]]
    # the events table: each event's catalogue fields (a code the catalogue does not know: id 0)
    table = [[column(ents["/events"], c)[2][i][0] for c in ("event_id", "event_name", "source", "severity")]
             for i in range(2)]
    assert table == [[EV.JET_FAILED_OFF.id, "jet_failed_off", "fdir", "WARNING"], [0, "safe", "modes", "CRITICAL"]]
    (doc,) = [d for d in ents["/event_catalogue"] if "TextDocument:text" in d]
    assert doc["TextDocument:text"] == [[markdown()]]               # the catalogue, as docs/events.md has it


class _CountingRec:
    """Stands in for a RecordingStream: counts calls, checks column lengths."""

    def __init__(self):
        self.send_columns_calls = 0
        self.log_calls = 0

    def send_columns(self, entity, indexes, columns):
        self.send_columns_calls += 1

    def log(self, entity, archetype, static=False):
        self.log_calls += 1

    def set_time(self, *a, **k):
        pass

    def flush(self, *a, **k):
        pass


def test_logging_is_batched_per_step():
    rec = _CountingRec()
    clock = [0.0]
    log = RerunLogger(rec, flush_rows=50, flush_s=1.0, clock=lambda: clock[0])
    static_logs = rec.log_calls
    h = _history(1000)
    row_t = {f: h.a[f] for f in ("bank_rad", "alpha_rad", "beta_rad", "omega_BN_B", "sigma_BN", "h_m")}
    row_f = {f: h.a[f] for f in ("bank_ref_rad", "u_cal_B", "theta_hat", "jets_cmd", "health", "mode")}
    for k in range(1000):
        clock[0] = k * 0.001                 # faster than real time: the row count triggers
        log.log_truth(k, k * DT, {f: v[k] for f, v in row_t.items()})
        log.log_fsw(k, k * DT, {f: v[k] for f, v in row_f.items()})
    log.flush()
    n_entities = len(SCALAR_CHANNELS) + 10
    assert log.stats["flushes"] == 2 * 1000 // 50
    assert rec.send_columns_calls <= (1000 // 50) * n_entities
    assert rec.send_columns_calls / 1000 < 1.0              # far fewer calls than steps x signals
    assert rec.log_calls - static_logs == 2                 # the two health bar charts only


def test_time_trigger_flushes_a_slow_stream():
    rec = _CountingRec()
    clock = [0.0]
    log = RerunLogger(rec, flush_rows=50, flush_s=1.0, clock=lambda: clock[0])
    for k in range(5):
        clock[0] = 0.3 * k
        log.log_truth(k, k * DT, {"bank_rad": 0.1})
    assert log.stats["flushes"] == 1          # at 1.2 s > 1.0 s, after 5 rows < 50


def test_none_mode_logs_nothing():
    s = open_sinks("none", None)
    assert s.rec is None and s.kinds == set()
    log = RerunLogger(s.rec)
    log.log_truth(0, 0.0, {"bank_rad": 1.0})
    log.log_event(Event(0.0, Severity.INFO, "x", "y", "z"))
    log.close()
    assert log.stats["rows_truth"] == 0 and log.stats["send_columns"] == 0 and not log.enabled


def test_bad_input_does_not_crash_and_is_not_passed_on(tmp_path):
    s = open_sinks("file", tmp_path, name="bad", display=False, say=lambda m: None)
    log = RerunLogger(s.rec, flush_rows=8)
    log.log_truth(0, 0.0, {"bank_rad": 0.1, "sigma_BN": [0, 0, 0], "r_N": [3.4e6, 0, 0]})
    log.log_truth(1, 0.02, {"bank_rad": float("nan"), "sigma_BN": [np.nan, 0, 0]})
    log.log_truth(2, 0.04, {"bank_rad": "abc", "sigma_BN": [1, 2], "omega_BN_B": None})
    log.log_truth(3, float("inf"), {"bank_rad": 0.2})
    log.log_truth("x", 0.08, {"bank_rad": 0.2})
    log.log_truth(4, 0.08, {})                             # nothing at all
    log.log_truth(5, 0.10, {"bank_rad": 0.3})
    log.log_fsw(5, 0.10, {"health": [9] * 18, "mode": 77, "jets_cmd": np.ones(18)})
    log.log_event(Event(float("nan"), Severity.INFO, "a", "b", "c"))
    log.log_event(Event(0.1, 99, "a", "b", "c"))            # unknown severity -> INFO
    log.log_block(TRUTH, [6, 7], [0.12, 0.14], {"bank_rad": [np.nan, 0.4], "sigma_BN": "bad"})
    with pytest.raises(ValueError, match="source"):
        log.log_block("plant", [0], [0.0], {})
    log.close()
    s.close()
    assert log.stats["bad_values"] >= 4 and log.stats["send_errors"] == 0
    ents, _ = read_recording(s.rrd_path)
    steps, _, vals = column(ents["/bank/actual_deg"], "Scalars:scalars")
    assert list(steps) == [0, 5, 7]                         # only the finite rows
    np.testing.assert_allclose([v[0] for v in vals], np.degrees([0.1, 0.3, 0.4]))
    steps, _, st = column(ents["/jets/health"], "StateChange:state")
    assert st[0][0] == "code9"
    r = subprocess.run([RERUN, "rrd", "verify", str(s.rrd_path)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr


def test_parse_mode():
    assert parse_mode("auto", display=False) == {"file"}
    assert parse_mode("auto", display=True) == {"viewer"}
    assert parse_mode("viewer", display=False) == {"file"}
    assert parse_mode("web+file", display=False) == {"web", "file"}
    assert parse_mode("none", display=True) == set()
    for bad in ("", "vieuwer", "none+file", None):
        with pytest.raises(ValueError, match="rerun mode"):
            parse_mode(bad, display=False)
    with pytest.raises(ValueError, match="out_dir"):
        open_sinks("file", None, display=False)
