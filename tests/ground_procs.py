"""What the tests that run the SIL with a ground station share: free loopback UDP ports
and stopping a process by its pid with a timeout."""
from __future__ import annotations

import socket
import subprocess

from ellipsled.procs import stop_process


def free_udp() -> int:
    """A UDP port on 127.0.0.1 free right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(p: subprocess.Popen, timeout_s: float = 15.0) -> None:
    """SIGTERM, then SIGKILL after ``timeout_s``; nothing if it has ended."""
    stop_process(p, timeout_s)
