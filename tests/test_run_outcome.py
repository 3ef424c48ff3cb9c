"""How a run ends for the user, in ``ellipsled batch`` and ``ellipsled run`` alike: the same
request gets the same end reason and exit code from both (runlib.exit_code decides for both),
the exit codes are in both commands' --help, and a normal SIL run's terminal carries the
product's own lines, no library's warnings (Rerun's file-sink footer warning was one)."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from common.config import DATA_DIR
from ellipsled import cli
from ellipsled.procs import ELLIPSLED, stop_process
from ellipsled.runlib import COMPLETED_END_REASONS, exit_code


pytestmark = pytest.mark.timeout(300)

ROOT = Path(__file__).resolve().parents[1]
DURATION = "1"
SIL_TIMEOUT_S = 240.0
# a library's warning line: Rust's tracing/log format (" WARN "), Python's logging and warnings
LIBRARY_WARNING = re.compile(r"\bWARN\b|\bWARNING\b|Warning\b")


def _batch(tmp_path: Path, *args: str) -> tuple[int, dict, str]:
    out = tmp_path / "batch"
    rc = cli.main(["batch", *args, "--out", str(out), "--no-plots"])
    return rc, json.loads((out / "summary.json").read_text()), str(out)


@pytest.fixture(scope="module")
def sil(tmp_path_factory):
    """`ellipsled run case1 --duration 1` with its recording to a file, as a user runs it
    (RUST_LOG unset); stopped by its pid if it overruns. (exit code, summary, stdout, stderr)."""
    d = tmp_path_factory.mktemp("sil")
    env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    with open(d / "stdout", "w") as so, open(d / "stderr", "w") as se:
        p = subprocess.Popen(ELLIPSLED + ["run", "case1", "--duration", DURATION, "--rerun", "file", "--no-plots",
                                          "--out", str(d / "out")],
                             cwd=ROOT, env=env, stdin=subprocess.DEVNULL, stdout=so, stderr=se)
        try:
            p.wait(SIL_TIMEOUT_S)
        finally:
            stop_process(p, 10.0)
    summary = json.loads((d / "out" / "summary.json").read_text())
    return p.returncode, summary, (d / "stdout").read_text(), (d / "stderr").read_text()


def test_one_function_maps_end_reasons_to_exit_codes():
    assert COMPLETED_END_REASONS == ("mach", "speed", "deploy", "box_edge", "altitude", "duration")
    assert [exit_code(r) for r in COMPLETED_END_REASONS] == [0] * 6
    assert [exit_code(r) for r in ("timeout", "non_finite", "fsw_timeout", "no_fsw", "stopped")] == [1] * 5


def test_batch_with_a_duration_completes(tmp_path, capsys):
    rc, s, _ = _batch(tmp_path, "case1", "--duration", DURATION)
    assert (rc, s["end_reason"], s["completed"]) == (0, "duration", True)
    assert "completed (duration)" in capsys.readouterr().out


def test_batch_stopped_by_the_scenarios_own_time_cap_did_not_complete(tmp_path):
    text = (DATA_DIR / "scenarios" / "case1.toml").read_text()
    assert "max_duration_s = 700.0" in text
    f = tmp_path / "capped.toml"
    f.write_text(text.replace("max_duration_s = 700.0", "max_duration_s = 1.0"))
    rc, s, _ = _batch(tmp_path, str(f))
    assert (rc, s["end_reason"], s["completed"]) == (1, "timeout", False)


def test_run_and_batch_end_the_same_request_alike(sil, tmp_path):
    rc_run, s_run, out, _ = sil
    rc_batch, s_batch, _ = _batch(tmp_path, "case1", "--duration", DURATION)
    assert (rc_run, s_run["end_reason"], s_run["completed"]) == (rc_batch, s_batch["end_reason"], s_batch["completed"])
    assert (rc_run, s_run["end_reason"]) == (0, "duration")
    assert s_run["t_end_s"] == s_batch["t_end_s"] == float(DURATION)
    assert "completed (duration)" in out


@pytest.mark.parametrize("cmd", ["batch", "run"])
def test_help_documents_the_exit_codes(cmd, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main([cmd, "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert "exit codes" in text
    for code in ("0", "1", "2", "130"):
        assert re.search(rf"^  {code}\s", text, re.M), code


def test_a_run_shows_no_library_warnings(sil):
    _, _, out, err = sil
    noise = [line for line in (out + err).splitlines() if LIBRARY_WARNING.search(line)]
    assert noise == []
    assert "rerun: recording to" in err          # the product's own line about the footer-less stream


def test_rerun_loads_with_the_file_sink_target_filtered_and_rust_log_left_as_it_was():
    from gse.viz.rerun_log import FILE_SINK_TARGET, rerun_log_filter
    assert rerun_log_filter(None) == f"warn,{FILE_SINK_TARGET}=error"          # the SDK's default, less that line
    assert rerun_log_filter("debug") == f"debug,{FILE_SINK_TARGET}=error"      # the user's filter kept
    assert rerun_log_filter(f"info,{FILE_SINK_TARGET}=warn") == f"info,{FILE_SINK_TARGET}=warn"   # theirs wins
    code = "import os, gse.viz; print(os.environ.get('RUST_LOG', 'unset'))"
    for env, seen in (({}, "unset"), ({"RUST_LOG": "info"}, "info")):
        r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                           env={**{k: v for k, v in os.environ.items() if k != "RUST_LOG"}, **env})
        assert r.returncode == 0 and r.stdout.strip() == seen, r.stderr
