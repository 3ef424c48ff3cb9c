"""How long the calling thread was blocked, told apart from how long it ran or waited for a CPU.

Wall time alone judges the host: an iteration the kernel preempted for another process, or
that waited on the run queue of a loaded machine, is not the code's. Linux keeps, per thread,
the CPU time and the run-queue wait (/proc/thread-self/schedstat: ``sum_exec_runtime``,
``run_delay``, in ns). What remains of the wall time is time the thread slept: for a loop
that does no I/O and takes no lock, time spent waiting for the GIL, i.e. waiting on another
thread of its process. That is a property of the code, the same on a quiet or a loaded host.
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading
import time

import pytest

SCHEDSTAT = "/proc/thread-self/schedstat"


def available() -> bool:
    return os.path.exists(SCHEDSTAT)


LOOP_PRIORITY = 20          # SCHED_FIFO priority of a measured loop (background jobs: one below)


def can_run_as_the_loop() -> bool:
    """Whether this process may make a thread SCHED_FIFO (root or CAP_SYS_NICE)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(LOOP_PRIORITY))
    except (OSError, AttributeError):
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


def loop_timing(test):
    """Marks of a test that judges a loop's waits on the wall clock (``timing``: run alone),
    with the loop SCHED_FIFO (``as_the_realtime_loop``): it needs root and schedstat."""
    test = pytest.mark.skipif(not can_run_as_the_loop(), reason="needs root (SCHED_FIFO)")(test)
    test = pytest.mark.skipif(not available(), reason="needs Linux per-thread schedstat")(test)
    return pytest.mark.timing(test)


@contextlib.contextmanager
def as_the_realtime_loop():
    """The calling thread runs SCHED_FIFO, as the real-time FSW's loop does: threads it starts
    meanwhile inherit that and background jobs step one priority below it
    (common.rt.run_below_loop). Other load on the machine (SCHED_OTHER) then never takes the
    loop's CPU, so the loop's waits are its own: waits for the GIL on a job of its process.
    Back to SCHED_OTHER afterwards."""
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(LOOP_PRIORITY))
    try:
        yield
    finally:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


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


def gil_keeping_burn(cpu_ns: float):
    """One C call that keeps the GIL for at least ``cpu_ns`` of this host's CPU: a big-integer
    power, its exponent doubled until it takes that long (in this thread's CPU time)."""
    e = 1 << 12
    while True:
        t0 = time.thread_time_ns()
        pow(3, e)
        if time.thread_time_ns() - t0 >= cpu_ns:
            return lambda: pow(3, e)
        e *= 2


_usleep_keeping_the_gil = ctypes.PyDLL(None).usleep      # PyDLL: the call keeps the GIL


def holding_the_gil_first(job, hold_s: float):
    """``job`` that first keeps the GIL ``hold_s`` while it sleeps (a C call that does not
    give it up, the fault the blocked-time tests exist to catch); ``job`` itself for 0."""
    if hold_s <= 0.0:
        return job

    def held(*args):
        _usleep_keeping_the_gil(int(hold_s * 1e6))
        return job(*args)
    return held
