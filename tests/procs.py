"""The processes tests start: the ``ellipsled`` command (``ELLIPSLED``), free loopback UDP ports,
a real-time SIL started with a fresh signing key and its ground link on loopback, a
command in a real terminal (tmux), and stopping a process by its pid with a timeout
(ellipsled/procs.py)."""
from __future__ import annotations

import os
import shlex
import socket
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

from interfaces.mavlink.signing.keys import SigningKey

from ellipsled.procs import ELLIPSLED, stop_process


def free_udp() -> int:
    """A UDP port on 127.0.0.1 free right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(p: subprocess.Popen, timeout_s: float = 15.0) -> None:
    """SIGTERM, then SIGKILL after ``timeout_s``; nothing if it has ended."""
    stop_process(p, timeout_s)


@dataclass
class GroundSil:
    """A real-time SIL run (``ellipsled run``) with a ground link on loopback."""
    run: subprocess.Popen
    key: SigningKey
    key_file: Path
    vehicle: int            # the FSW's MAVLink port
    gcs: int                # where its telemetry goes
    out: Path               # the run's output folder
    log_path: Path

    def log(self) -> str:
        return self.log_path.read_text()


def start_ground_sil(tmp_path: Path, scenario: str = "nominal", duration_s: float = 40.0,
                     key: SigningKey | None = None, rt: bool = True) -> GroundSil:
    """``ellipsled run SCENARIO --realtime --rt`` (``rt=False``: ``--no-rt``, no SCHED_FIFO)
    with a signing key (``key``, or a new one) written to tmp_path/keys and the ground link
    on free loopback ports; output in tmp_path/run, log in tmp_path/run.log. The caller
    stops ``run`` (``stop``)."""
    key_file = tmp_path / "keys" / "signing.key"
    key_file.parent.mkdir()
    key = key if key is not None else SigningKey.generate()
    key.write_file(str(key_file))
    vehicle, gcs = free_udp(), free_udp()
    out, log_path = tmp_path / "run", tmp_path / "run.log"
    with open(log_path, "w") as log:            # the child keeps its own descriptor
        run = subprocess.Popen(
            ELLIPSLED + ["run", scenario, "--realtime", "--rt" if rt else "--no-rt", "--duration", f"{duration_s:g}",
                         "--out", str(out), "--rerun", "none", "--no-plots", "--signing-key", str(key_file),
                         "--mavlink-bind", f"udp:127.0.0.1:{vehicle}", "--gcs", f"udp:127.0.0.1:{gcs}"],
            stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    return GroundSil(run, key, key_file, vehicle, gcs, out, log_path)


class Tmux:
    """One detached tmux session running one command; killed at the end whatever happens."""

    def __init__(self, name: str, argv: list[str], size=(150, 45)):
        self.name = f"{name}-{int(time.time() * 1e3) % 10**9}"
        # a tmux server keeps the environment it started with: hand this one's over explicitly
        env = " ".join(f"{k}={shlex.quote(os.environ[k])}" for k in ("PYTHONPATH", "PATH") if k in os.environ)
        cmd = f"cd {shlex.quote(os.getcwd())} && env {env} {shlex.join(argv)}; echo EXIT-$?; sleep 120"
        subprocess.run(["tmux", "new-session", "-d", "-s", self.name, "-x", str(size[0]), "-y", str(size[1]), cmd],
                       check=True)

    def screen(self) -> str:
        return subprocess.run(["tmux", "capture-pane", "-p", "-t", self.name], capture_output=True,
                              text=True).stdout

    def keys(self, *keys: str, literal: bool = False) -> None:
        subprocess.run(["tmux", "send-keys", "-t", self.name] + (["-l"] if literal else []) + list(keys), check=True)

    def wait_for(self, cond, timeout_s: float, what: str) -> str:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            s = self.screen()
            if cond(s):
                return s
            time.sleep(0.3)
        raise AssertionError(f"timed out waiting for {what}; screen:\n{self.screen()}")

    def kill(self) -> None:
        subprocess.run(["tmux", "kill-session", "-t", self.name], capture_output=True)
