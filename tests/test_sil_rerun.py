"""The live dashboard of a real SIL: `ellipsled run --rerun file` records through the bridge
process what the plant and the FSW published over Zenoh; the recording verifies, carries
the blueprint, and its values are the run's own (the bank angle at every step equals the
run's history, the reference equals the FSW's)."""
from __future__ import annotations

import subprocess

import numpy as np
import pytest

from ellipsled.procs import ELLIPSLED

from tests.rrd import RERUN, column, read_recording

pytestmark = pytest.mark.slow


def test_sil_recording_matches_the_run(tmp_path):
    out = tmp_path / "sil"
    r = subprocess.run(ELLIPSLED + ["run", "case1", "--lockstep", "--duration", "20", "--out", str(out),
                                    "--rerun", "file", "--no-plots"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    rrd = out / "run.rrd"
    v = subprocess.run([RERUN, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=60)
    assert v.returncode == 0, v.stdout + v.stderr
    ents, reader = read_recording(rrd)
    assert len(reader.blueprints()) == 1
    for e in ("/bank/actual_deg", "/bank/reference_deg", "/bank/error_deg", "/adapt/theta_hat",
              "/world/vehicle", "/jets/lanes", "/events", "/timing/compute_us"):
        assert e in ents, e
    h = np.load(out / "history.npz")
    n = len(h["k"])
    steps, _, bank = column(ents["/bank/actual_deg"], "Scalars:scalars")
    assert list(steps) == list(range(n))                 # every step of the run, none lost
    np.testing.assert_allclose([b[0] for b in bank], np.degrees(h["bank_rad"]), rtol=0, atol=1e-9)
    steps, _, ref = column(ents["/bank/reference_deg"], "Scalars:scalars")
    np.testing.assert_allclose([x[0] for x in ref], np.degrees(h["bank_ref_rad"][steps]), rtol=0, atol=1e-9)
    # the FDIR events reached the recording as text-log entries
    _, _, texts = column(ents["/events"], "TextLog:text")
    assert any("JET 17 FAILED_OFF" in str(t) for t in texts), texts[:10]


def test_sil_guided_map_shows_each_guidance_answer_once_with_the_fsws_predicted_point(tmp_path):
    """The Map tab of a guided SIL: the predicted deploy points reach the bridge in the FSW
    state record (Zenoh), one per answer, equal to the FSW's own history of them (written by
    the FSW process, not through Zenoh); the target once; the ground track every 10th step."""
    import math
    from interfaces.records import GUID_PREDICTION
    out = tmp_path / "sil"
    r = subprocess.run(ELLIPSLED + ["run", "guided-nominal", "--lockstep", "--duration", "6", "--out", str(out),
                                    "--rerun", "file", "--no-plots"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    ents, _ = read_recording(out / "run.rrd")
    h = np.load(out / "history.npz")
    has = (h["guid_flags"] & GUID_PREDICTION) != 0
    cyc = np.where(has, h["guid_cycles"], -1)
    first = np.nonzero(has & (np.diff(np.concatenate(([-1], cyc))) != 0))[0]      # rows of a new answer
    assert len(first) >= 5                                                       # ~1 Hz over 6 s
    steps, _, pts = column(ents["/map/predicted"], "Points3D:positions")
    assert list(steps) == [int(k) for k in h["k"][first]]
    np.testing.assert_allclose([p[0][0] for p in pts], np.degrees(h["pred_lon_rad"][first]), rtol=1e-6)
    np.testing.assert_allclose([p[0][1] for p in pts], np.degrees(h["pred_lat_rad"][first]), rtol=1e-6)
    _, _, tgt = column(ents["/map/target"], "Points3D:positions")
    assert len(tgt) == 1 and tgt[0][0][0] == pytest.approx(math.degrees(float(h["target_lon_rad"][0])))
    steps, _, _ = column(ents["/map/track"], "LineStrips3D:strips")
    assert list(steps) == [int(k) for k in h["k"] if k % 10 == 0]
