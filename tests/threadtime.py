"""How long the calling thread was blocked, told apart from how long it ran or waited for a CPU.

Wall time alone judges the host: an iteration the kernel preempted for another process, or
that waited on the run queue of a loaded machine, is not the code's. Linux keeps, per thread,
the CPU time and the run-queue wait (/proc/thread-self/schedstat: ``sum_exec_runtime``,
``run_delay``, in ns). What remains of the wall time is time the thread slept: for a loop
that does no I/O and takes no lock, time spent waiting for the GIL, i.e. waiting on another
thread of its process. That is a property of the code, the same on a quiet or a loaded host.
"""
from __future__ import annotations

import os
import sys
import threading
import time

SCHEDSTAT = "/proc/thread-self/schedstat"


def available() -> bool:
    return os.path.exists(SCHEDSTAT)


class BlockedMeter:
    """Per-interval blocked time of the thread that created it: ``lap()`` returns the ns this
    thread slept since the previous ``lap()`` (wall - on CPU - waiting for a CPU)."""

    def __init__(self) -> None:
        self._tid = threading.get_native_id()
        self._fd = os.open(f"/proc/self/task/{self._tid}/schedstat", os.O_RDONLY)
        self._last = self._read()

    def _read(self) -> tuple[int, int, int]:
        cpu, delay, _ = os.pread(self._fd, 128, 0).split()
        return time.perf_counter_ns(), int(cpu), int(delay)

    def lap(self) -> int:
        assert threading.get_native_id() == self._tid, "a meter measures the thread that made it"
        now = self._read()
        (w0, c0, d0), (w1, c1, d1) = self._last, now
        self._last = now
        return max(0, (w1 - w0) - (c1 - c0) - (d1 - d0))

    def close(self) -> None:
        os.close(self._fd)


class LongestCCall:
    """The longest single C call a job made, in its own thread's CPU time [ns]. Python bytecode
    gives the GIL up every switch interval; only a C call can keep it longer, so this bounds
    from above any stretch of CPU work in which the job kept the GIL from the loop. CPU time
    is the thread's own: the same on a quiet or a loaded host. Blind to a C call that keeps
    the GIL while it sleeps or blocks (no CPU): the blocked-time tests see those.

    ``wrap(job)`` profiles each call of ``job`` in the thread that makes it."""

    def __init__(self) -> None:
        self.worst_ns = 0
        self.worst_name = ""
        self._starts: list[int] = []

    def _hook(self, frame, event, arg) -> None:
        if event == "c_call":
            self._starts.append(time.thread_time_ns())
        elif event in ("c_return", "c_exception") and self._starts:
            took = time.thread_time_ns() - self._starts.pop()
            if took > self.worst_ns:
                self.worst_ns, self.worst_name = took, getattr(arg, "__qualname__", repr(arg))

    def wrap(self, job):
        def profiled(*args):
            sys.setprofile(self._hook)
            try:
                return job(*args)
            finally:
                sys.setprofile(None)
                self._starts.clear()
        return profiled
