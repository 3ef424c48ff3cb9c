"""Child processes we start: the ``ellipsled`` command on this interpreter, children that die
with us, and stopping them by their own pid, politely first, with bounded waits."""
from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
from typing import Callable

PR_SET_PDEATHSIG = 1        # linux/prctl.h
ELLIPSLED = [sys.executable, "-m", "ellipsled.cli"]     # the ``ellipsled`` command, on this interpreter


def die_with_parent(sig: int = signal.SIGTERM) -> Callable[[], None] | None:
    """A ``preexec_fn`` for ``subprocess.Popen``: the child gets ``sig`` when the process
    starting it ends, however it ends (SIGKILL included), so no child outlives its launcher
    holding ports and real-time priority (Linux ``PR_SET_PDEATHSIG``; None elsewhere). A
    parent that died before the child armed it is caught too: the child signals itself."""
    if not sys.platform.startswith("linux"):
        return None
    prctl = ctypes.CDLL(None, use_errno=True).prctl      # resolved here, not in the forked child
    parent = os.getpid()

    def arm() -> None:
        prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
        if os.getppid() != parent:
            os.kill(os.getpid(), sig)
    return arm


def stop_process(p: subprocess.Popen, timeout_s: float, kill_wait_s: float = 5.0,
                 on_kill: Callable[[], None] | None = None, sig: int = signal.SIGTERM,
                 group: bool = False) -> int | None:
    """``sig`` (SIGTERM unless told), then SIGKILL if it has not ended within ``timeout_s``
    (``on_kill`` is called first, e.g. to say so); nothing if it has ended. ``group``: signal
    the process group it leads (a child started with ``start_new_session=True``, and whatever
    it started). Returns its exit code."""
    if p.poll() is None:
        _signal(p, sig, group)
        try:
            p.wait(timeout_s)
        except subprocess.TimeoutExpired:
            if on_kill is not None:
                on_kill()
            _signal(p, signal.SIGKILL, group)
            p.wait(kill_wait_s)
    return p.returncode


def _signal(p: subprocess.Popen, sig: int, group: bool) -> None:
    if not group:
        p.send_signal(sig)
        return
    try:
        os.killpg(p.pid, sig)
    except (ProcessLookupError, PermissionError):     # the group has gone meanwhile
        pass
