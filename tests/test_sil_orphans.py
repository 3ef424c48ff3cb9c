"""No SIL process outlives its reason to run: the children of `ellipsled run` die with the
launcher however it ends (SIGKILL included), freeing the ground link's UDP port; and an FSW
whose plant's liveliness has gone leaves instead of flying on alone. Every process is
started here and, whatever happens, killed by its pid."""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import time

import pytest

from ellipsled.procs import ELLIPSLED, stop_process
from ellipsled.sil.progress import ProgressFile
from interfaces import transport
from tests.procs import start_ground_sil

pytestmark = pytest.mark.slow

PREFIX = "ellipsled/orphans"
START_S = 120.0         # start-up on a loaded machine (imports, compiled kernels, warm-up)


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie nobody has reaped yet has ended)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _wait_gone(pids, timeout_s: float) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while any(_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    return [p for p in pids if _alive(p)]


@pytest.mark.realtime
def test_children_die_with_a_killed_launcher_and_free_the_ground_port(tmp_path):
    sil = start_ground_sil(tmp_path, duration_s=300.0)
    pids: dict[str, int] = {}
    try:
        deadline = time.monotonic() + START_S
        while True:
            m = re.search(r"pids (.*?); logs", sil.log())
            sim_log = sil.out / "sim.log"
            if m and sim_log.exists() and "first jet command" in sim_log.read_text():
                break
            assert sil.run.poll() is None and time.monotonic() < deadline, sil.log()
            time.sleep(0.2)
        pids = {role: int(pid) for role, pid in re.findall(r"(\w+) (\d+)", m.group(1))}
        assert {"fsw", "sim"} <= set(pids), m.group(0)
        assert not _port_free(sil.vehicle), "the FSW should hold the vehicle's MAVLink port"
        os.kill(sil.run.pid, signal.SIGKILL)
        sil.run.wait(10)
        left = _wait_gone(pids.values(), 30.0)
        assert not left, f"orphans still running: {[r for r, p in pids.items() if p in left]}"
        assert _port_free(sil.vehicle), "the vehicle's MAVLink port is still held"
    finally:
        for pid in pids.values():
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        _wait_gone(pids.values(), 10.0)
        stop_process(sil.run, 10)


def test_the_fsw_leaves_when_the_plants_liveliness_is_gone(tmp_path):
    e_sim = transport.loopback(transport.free_port())
    progress = tmp_path / "progress"
    common = ["nominal", "--lockstep", "--prefix", PREFIX, "--wait-peers", str(START_S)]
    procs = {}
    logs = {r: open(tmp_path / f"{r}.log", "w") for r in ("sim", "fsw")}
    try:
        procs["sim"] = subprocess.Popen(ELLIPSLED + ["sim", *common, "--listen", e_sim, "--out", str(tmp_path / "sim"),
                                                     "--progress-file", str(progress)],
                                        stdout=logs["sim"], stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        procs["fsw"] = subprocess.Popen(ELLIPSLED + ["fsw", *common, "--connect", e_sim, "--out", str(tmp_path / "fsw"),
                                                     "--plant-gone-s", "2"],
                                        stdout=logs["fsw"], stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        deadline = time.monotonic() + START_S
        while (ProgressFile.read(str(progress)) or 0.0) < 1.0:       # flying, FSW answering
            assert procs["sim"].poll() is None and time.monotonic() < deadline, \
                (tmp_path / "sim.log").read_text() + (tmp_path / "fsw.log").read_text()
            time.sleep(0.1)
        procs["sim"].kill()
        procs["sim"].wait(10)
        rc = procs["fsw"].wait(60)
        log = (tmp_path / "fsw.log").read_text()
        assert rc == 0 and "the plant has been gone" in log, log
        assert (tmp_path / "fsw" / "fsw.json").exists()                 # it left cleanly, records written
    finally:
        for p in procs.values():
            stop_process(p, 10)
        for f in logs.values():
            f.close()
