"""Stopping a child process we started: by its own pid, politely first, with bounded waits."""
from __future__ import annotations

import signal
import subprocess
from typing import Callable


def stop_process(p: subprocess.Popen, timeout_s: float, kill_wait_s: float = 5.0,
                 on_kill: Callable[[], None] | None = None) -> int | None:
    """SIGTERM, then SIGKILL if it has not ended within ``timeout_s`` (``on_kill`` is called
    first, e.g. to say so); nothing if it has ended. Returns its exit code."""
    if p.poll() is None:
        p.send_signal(signal.SIGTERM)
        try:
            p.wait(timeout_s)
        except subprocess.TimeoutExpired:
            if on_kill is not None:
                on_kill()
            p.kill()
            p.wait(kill_wait_s)
    return p.returncode
