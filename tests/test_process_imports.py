"""What each process loads, seen in a fresh interpreter: the plant process and its shell
helpers load nothing from fsw/, so a change inside fsw/ cannot reach the plant process; a
SIL process started through the ``ellipsled`` command loads its shell, not the launcher's
judging; and the launcher starts without the flight software (it flies a fault-free twin,
if it must, after the run). The static rule behind it: tests/test_vocabulary.py."""
from __future__ import annotations

import json
import subprocess
import sys

PROBE = """
import json, sys
{code}
print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in ('fsw', 'ellipsled'))))
"""
# The harness's judging: figures of merit, summaries, fault-free twins, and the launcher.
JUDGING = {"ellipsled.runlib", "ellipsled.metrics", "ellipsled.reference", "ellipsled.batch", "ellipsled.lockstep",
           "ellipsled.node_reports", "ellipsled.controllable", "ellipsled.sil.launcher"}


def _loaded_by(code: str) -> list[str]:
    r = subprocess.run([sys.executable, "-c", PROBE.format(code=code)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def _fsw_modules_loaded_by(module: str) -> list[str]:
    return [m for m in _loaded_by(f"import {module}") if m.split(".")[0] == "fsw"]


def test_the_plant_process_imports_nothing_from_fsw():
    assert _fsw_modules_loaded_by("ellipsled.sil.sim_node") == []


def test_runtime_helpers_and_the_plants_shell_helpers_import_nothing_from_fsw():
    for module in ("common.rt", "ellipsled.sil.common", "ellipsled.sil.variant", "ellipsled.sil.history",
                   "ellipsled.sil.progress"):
        assert _fsw_modules_loaded_by(module) == [], module


def test_the_launcher_starts_without_the_flight_software():
    assert _fsw_modules_loaded_by("ellipsled.sil.launcher") == []


def test_a_sil_process_started_by_the_command_loads_no_judging():
    for role in ("sim", "fsw"):
        loaded = _loaded_by(f"from ellipsled import cli; cli.build_parser([{role!r}])")
        assert f"ellipsled.sil.{role}_node" in loaded and JUDGING.isdisjoint(loaded), (role, loaded)


def test_the_probe_sees_an_fsw_import_and_judging():      # the checks above can fail
    assert "fsw.executive" in _fsw_modules_loaded_by("fsw.executive")
    assert "ellipsled.runlib" in _loaded_by("from ellipsled import cli; cli.build_parser(['run'])")
