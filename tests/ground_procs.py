"""What the tests that run the SIL with a ground station share: free loopback UDP ports,
a real-time SIL started with a fresh signing key and its ground link on loopback, and
stopping a process by its pid with a timeout."""
from __future__ import annotations

import socket
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from interfaces.mavlink.signing.keys import SigningKey

from ellipsled.procs import stop_process


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
                     key: SigningKey | None = None) -> GroundSil:
    """``ellipsled run SCENARIO --realtime --rt`` with a signing key (``key``, or a new one)
    written to tmp_path/keys and the ground link on free loopback ports; output in
    tmp_path/run, log in tmp_path/run.log. The caller stops ``run`` (``stop``)."""
    key_file = tmp_path / "keys" / "signing.key"
    key_file.parent.mkdir()
    key = key if key is not None else SigningKey.generate()
    key.write_file(str(key_file))
    vehicle, gcs = free_udp(), free_udp()
    out, log_path = tmp_path / "run", tmp_path / "run.log"
    with open(log_path, "w") as log:            # the child keeps its own descriptor
        run = subprocess.Popen(
            [sys.executable, "-m", "ellipsled.cli", "run", scenario, "--realtime", "--rt", "--duration", f"{duration_s:g}",
             "--out", str(out), "--rerun", "none", "--no-plots", "--signing-key", str(key_file),
             "--mavlink-bind", f"udp:127.0.0.1:{vehicle}", "--gcs", f"udp:127.0.0.1:{gcs}"],
            stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    return GroundSil(run, key, key_file, vehicle, gcs, out, log_path)
