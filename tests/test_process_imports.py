"""The plant process and the runtime helpers load without the flight software: the plant
node takes its real-time hygiene and absolute sleeps from common/rt.py and its run
functions from ellipsled/runlib.py, so a change inside fsw/ cannot reach the plant process."""
from __future__ import annotations

import json
import subprocess
import sys

PROBE = """
import json, sys
import {module}
print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] == 'fsw')))
"""


def _fsw_modules_loaded_by(module: str) -> list[str]:
    r = subprocess.run([sys.executable, "-c", PROBE.format(module=module)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_the_plant_process_imports_nothing_from_fsw():
    assert _fsw_modules_loaded_by("ellipsled.sil.sim_node") == []


def test_runtime_helpers_and_run_functions_import_nothing_from_fsw():
    assert _fsw_modules_loaded_by("common.rt") == []
    assert _fsw_modules_loaded_by("ellipsled.runlib") == []


def test_the_probe_sees_an_fsw_import():      # the check above can fail
    assert "fsw.executive" in _fsw_modules_loaded_by("fsw.executive")
