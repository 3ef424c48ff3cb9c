"""The live dashboard of a real SIL: `ellipsled run --rerun file` records through the bridge
process what the plant and the FSW published over Zenoh; the recording verifies, carries
the blueprint, and its values are the run's own (the bank angle at every step equals the
run's history, the reference equals the FSW's)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from tests.test_viz_recording import RERUN, _column, _read

pytestmark = pytest.mark.slow


def test_sil_recording_matches_the_run(tmp_path):
    out = tmp_path / "sil"
    r = subprocess.run([sys.executable, "-m", "ellipsled.cli", "run", "case1", "--lockstep", "--duration", "20",
                        "--out", str(out), "--rerun", "file", "--no-plots"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    rrd = out / "run.rrd"
    v = subprocess.run([RERUN, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=60)
    assert v.returncode == 0, v.stdout + v.stderr
    ents, reader = _read(rrd)
    assert len(reader.blueprints()) == 1
    for e in ("/bank/actual_deg", "/bank/reference_deg", "/bank/error_deg", "/adapt/theta_hat",
              "/world/vehicle", "/jets/lanes", "/events", "/timing/compute_us"):
        assert e in ents, e
    h = np.load(out / "history.npz")
    n = len(h["k"])
    steps, _, bank = _column(ents["/bank/actual_deg"], "Scalars:scalars")
    assert list(steps) == list(range(n))                 # every step of the run, none lost
    np.testing.assert_allclose([b[0] for b in bank], np.degrees(h["bank_rad"]), rtol=0, atol=1e-9)
    steps, _, ref = _column(ents["/bank/reference_deg"], "Scalars:scalars")
    np.testing.assert_allclose([x[0] for x in ref], np.degrees(h["bank_ref_rad"][steps]), rtol=0, atol=1e-9)
    # the FDIR events reached the recording as text-log entries
    _, _, texts = _column(ents["/events"], "TextLog:text")
    assert any("JET 17 FAILED OFF" in str(t) for t in texts), texts[:10]
