"""Runtime helpers of every ellipsled process (plant, FSW, ground tools): real-time
hygiene (docs/fsw/index.md, Executive; docs/benchmarks.md) and absolute sleeps.

Call order in a process shell:

    from common import rt
    rt.single_threaded_numerics()      # first: before NumPy / numba are imported
    import numpy ...                   # then everything else
    ... build the FSW objects, open sessions, warm up (first calls compile / allocate)
    report = rt.apply(cpus=[1], priority=80)   # affinity, SCHED_FIFO, mlockall, timer slack
    rt.gc_out_of_cycle()               # collect once, freeze survivors, disable automatic GC
    executive.run(on_slack=rt.collect_in_slack())   # young-generation GC only in slack time

Each step falls back cleanly when not permitted and says so in the returned report;
``apply`` reads the state back from the kernel rather than assuming its calls worked.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import gc
import mmap
import os
import sys
import threading
import time
from typing import Callable

THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS",
              "VECLIB_MAXIMUM_THREADS", "BLIS_NUM_THREADS", "NUMBA_NUM_THREADS")

MCL_CURRENT, MCL_FUTURE, MCL_ONFAULT = 1, 2, 4      # Linux <sys/mman.h> (MCL_ONFAULT: Linux >= 4.4)
PR_SET_TIMERSLACK, PR_GET_TIMERSLACK = 29, 30


def _libc():
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    except OSError:
        return None


_LIBC = _libc()


# --------------------------------------------------------------------------- sleeping
class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


_CLOCK_MONOTONIC = 1      # Linux <time.h>
_TIMER_ABSTIME = 1
try:
    _clock_nanosleep = _LIBC.clock_nanosleep
    _clock_nanosleep.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Timespec), ctypes.c_void_p]
    _clock_nanosleep.restype = ctypes.c_int
except AttributeError:          # no libc, or not Linux/glibc: relative sleeps
    _clock_nanosleep = None


def sleep_until_ns(t_ns: int, now_ns: Callable[[], int] = time.monotonic_ns) -> None:
    """Sleep until the monotonic clock reads ``t_ns`` (absolute: no drift from the time
    spent computing the remaining interval). Interruptible: a signal (Ctrl-C) ends the
    sleep and its Python handler runs on return."""
    if _clock_nanosleep is not None:
        ts = _Timespec(t_ns // 1_000_000_000, t_ns % 1_000_000_000)
        _clock_nanosleep(_CLOCK_MONOTONIC, _TIMER_ABSTIME, ctypes.byref(ts), None)
    else:
        dt = t_ns - now_ns()
        if dt > 0:
            time.sleep(dt * 1e-9)


def _mlockall(flags: int) -> tuple[bool, str]:
    """(ok, reason); a seam the tests replace to exercise the failure path."""
    if _LIBC is None:
        return False, "libc not available"
    if _LIBC.mlockall(flags) != 0:
        err = ctypes.get_errno()
        return False, f"mlockall: {os.strerror(err)} (errno {err})"
    return True, ""


def lock_touched() -> tuple[str | None, list[str]]:
    """Lock the pages this process touches, now and from now on: (mode, messages).

    mode "onfault": mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT) -- resident pages are
    locked now and every page later when first touched, so mappings the loop never uses
    (thread stacks beyond their depth, malloc arenas' reserves, JIT and runtime
    reservations) stay unallocated: the process is as large as it would be unlocked. The
    pages the loop writes for the first time in flight are prefaulted (``prefault``).
    "all": kernels without MCL_ONFAULT (EINVAL): every mapping is populated and locked
    whole. None: not permitted (nothing locked; the message says why)."""
    ok, why = _mlockall(MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT)
    if ok:
        return "onfault", []
    if "errno 22" not in why:           # EINVAL: the kernel does not know MCL_ONFAULT
        return None, [f"memory not locked: {why}"]
    ok, why2 = _mlockall(MCL_CURRENT | MCL_FUTURE)
    if ok:
        return "all", [f"on-fault locking refused ({why}): the whole address space is locked"]
    return None, [f"memory not locked: {why2}"]


def prefault(*arrays) -> int:
    """Touch every page of each NumPy array (write one byte a page, its value unchanged), so a
    loop that fills them in flight takes no page fault (under ``lock_touched``'s on-fault
    mode the pages are locked from here on). Returns the bytes touched."""
    import numpy as np          # (not at the top: single_threaded_numerics runs before NumPy loads)
    page = mmap.PAGESIZE
    n = 0
    for a in arrays:
        if a is None or a.nbytes == 0:
            continue
        b = np.ascontiguousarray(a).reshape(-1).view(np.uint8)
        if not np.shares_memory(b, a):
            raise ValueError("prefault: the array is not contiguous (a copy would be touched)")
        touch = b[::page]
        touch |= 0          # a write (NumPy skips an assignment of a view to itself)
        n += b.nbytes
    return n


MEMORY_FIELDS = ("VmRSS", "VmHWM", "VmLck", "VmSize", "Threads")


def memory_status(pid: int | str = "self") -> dict:
    """A process's memory [kB] from /proc/<pid>/status and smaps_rollup: vm_rss_kb (resident),
    vm_hwm_kb (peak resident), vm_lck_kb (size of the locked mappings: under on-fault locking
    it counts pages never touched, so it is not memory in use), locked_kb (resident pages of
    the locked mappings: what locking holds in RAM), vm_size_kb, threads. {} when unreadable;
    locked_kb None when /proc/<pid>/smaps is (reading it walks the page tables: not for a cycle)."""
    out = {}
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                name, _, value = line.partition(":")
                if name in MEMORY_FIELDS:
                    key = "threads" if name == "Threads" else "vm_" + name[2:].lower() + "_kb"
                    out[key] = int(value.split()[0])
    except (OSError, ValueError):
        return {}
    out["locked_kb"] = _locked_resident_kb(pid)
    return out


def _locked_resident_kb(pid: int | str) -> int | None:
    """Resident kB of the mappings flagged locked ("lo" in VmFlags) in /proc/<pid>/smaps."""
    total, rss = 0, 0
    try:
        with open(f"/proc/{pid}/smaps") as f:
            for line in f:
                if line.startswith("Rss:"):
                    rss = int(line.split()[1])
                elif line.startswith("VmFlags:"):
                    if "lo" in line.split()[1:]:
                        total += rss
    except (OSError, ValueError, IndexError):
        return None
    return total


def single_threaded_numerics() -> dict:
    """Pin BLAS/OpenMP/numba pools to one thread. Must run before NumPy is imported: the
    BLAS reads its variable once, at load. Returns {env, numpy_was_imported, numba_threads,
    messages}."""
    messages = []
    for name in THREAD_ENV:
        os.environ[name] = "1"
    numpy_loaded = "numpy" in sys.modules
    if numpy_loaded:
        messages.append("numpy was imported before single_threaded_numerics(): "
                        "its BLAS may already have started a thread pool")
    numba_threads = None
    if "numba" in sys.modules:          # imported already: its pool may be larger
        import numba
        from numba.core import config as numba_config
        try:
            # numba re-reads the environment at every compile and refuses a NUMBA_NUM_THREADS
            # that differs from its launched pool: take the new value in before the pool starts.
            numba_config.reload_config()
        except RuntimeError as e:       # the pool is already running at another size: keep it
            os.environ["NUMBA_NUM_THREADS"] = str(numba_config.NUMBA_NUM_THREADS)
            messages.append(f"numba pool already launched: {e}")
        try:
            numba.set_num_threads(1)
            numba_threads = numba.get_num_threads()
        except Exception as e:          # e.g. NUMBA_NUM_THREADS fixed lower than requested
            messages.append(f"numba threads not set: {e}")
    return {"env": {n: os.environ[n] for n in THREAD_ENV}, "numpy_was_imported": numpy_loaded,
            "numba_threads": numba_threads, "messages": messages}


def gc_out_of_cycle() -> dict:
    """After initialisation: collect everything, move the survivors to the permanent
    generation (never scanned again), and disable automatic collection so that it cannot
    start in the middle of a cycle. Young garbage is then collected by ``collect_in_slack``."""
    collected = gc.collect()
    gc.freeze()
    gc.disable()
    return {"collected": collected, "frozen": gc.get_freeze_count(), "enabled": gc.isenabled()}


def collect_in_slack(min_slack_ns: int = 5_000_000, min_gen0: int = 200) -> Callable[[int], None]:
    """An ``Executive.run(on_slack=...)`` hook: ``gc.collect(0)`` (young objects only, tens
    of microseconds) when at least ``min_slack_ns`` remain before the next release and at
    least ``min_gen0`` allocations are pending. ``hook.collections`` counts its runs."""
    def hook(ns_left: int) -> None:
        if ns_left >= min_slack_ns and gc.get_count()[0] >= min_gen0:
            gc.collect(0)
            hook.collections += 1
    hook.collections = 0
    return hook


def throttle() -> dict:
    """The kernel's real-time throttle: SCHED_FIFO threads may run ``runtime_us`` of each
    ``period_us`` (runtime -1: never throttled). A real-time loop busy longer than that is
    stopped for the rest of the period (~50 ms a second by default): a loop that measures
    must sleep as the flight's does. None where the files cannot be read."""
    out = {}
    for key, name in (("runtime_us", "sched_rt_runtime_us"), ("period_us", "sched_rt_period_us")):
        try:
            with open(f"/proc/sys/kernel/{name}") as f:
                out[key] = int(f.read().strip())
        except (OSError, ValueError):
            out[key] = None
    return out


def set_timer_slack(ns: int = 1) -> bool:
    """Timer slack of this thread (default 50 us on Linux delays every timed wake-up of a
    SCHED_OTHER thread; recent kernels give SCHED_FIFO threads none, and read back 0).
    True if the kernel accepted the request."""
    if _LIBC is None:
        return False
    return _LIBC.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(ns), 0, 0, 0) == 0


def get_timer_slack_ns() -> int | None:
    """The timer slack in force for this thread [ns] (None if unknown)."""
    if _LIBC is None:
        return None
    v = _LIBC.prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0)
    return v if v >= 0 else None


def apply(cpus: list[int] | None = None, priority: int | None = None,
          lock_memory: bool = True, timer_slack_ns: int | None = 1) -> dict:
    """Apply what is permitted; report what is in force (read back from the kernel).

    cpus: CPU set for this process (None: leave). priority: SCHED_FIFO priority 1..99
    (None: stay SCHED_OTHER). lock_memory: lock the pages touched (``lock_touched``).
    Under SCHED_FIFO the GIL switch interval becomes GIL_SWITCH_S (see run_below_loop).
    Returns {affinity, sched_fifo, priority, mlockall, mlock_mode ("onfault", "all" or None),
    memory (``memory_status`` right after locking), timer_slack_ns (read back: 0 for a
    SCHED_FIFO thread), gil_switch_us, messages}; every
    refused step leaves the process as it was and adds a message (the warning to log).
    """
    messages: list[str] = []
    # before SCHED_FIFO: the kernel ignores slack requests of real-time threads
    if timer_slack_ns is not None and not set_timer_slack(timer_slack_ns):
        messages.append("timer slack not set")
    if cpus is not None:
        try:
            os.sched_setaffinity(0, set(int(c) for c in cpus))
        except (OSError, ValueError, TypeError) as e:
            messages.append(f"affinity {cpus} not set: {type(e).__name__}: {e}")
    if priority is not None:
        try:
            lo, hi = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
            if not lo <= int(priority) <= hi:
                raise ValueError(f"priority {priority} outside {lo}..{hi}")
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
        except (OSError, ValueError, AttributeError) as e:
            messages.append(f"SCHED_FIFO not set, staying SCHED_OTHER: {type(e).__name__}: {e}")
    mode = None
    if lock_memory:
        mode, why = lock_touched()
        messages += why
    try:
        affinity = sorted(os.sched_getaffinity(0))
    except OSError:
        affinity = None
    try:
        fifo = os.sched_getscheduler(0) == os.SCHED_FIFO
        prio = os.sched_getparam(0).sched_priority if fifo else None
    except OSError:
        fifo, prio = False, None
    if fifo:            # background threads (run_below_loop) hand the GIL back this soon
        sys.setswitchinterval(GIL_SWITCH_S)
    return {"affinity": affinity, "sched_fifo": fifo, "priority": prio, "mlockall": mode is not None,
            "mlock_mode": mode, "memory": memory_status(), "timer_slack_ns": get_timer_slack_ns(), "gil_switch_us": sys.getswitchinterval() * 1e6,
            "messages": messages}


GIL_SWITCH_S = 250e-6     # longest wait of the loop for the GIL held by a background thread


def run_below_loop() -> dict:
    """Call first in a background thread (allocator rebuild, controllability, guidance).
    When the process's main thread -- the control loop -- runs SCHED_FIFO, this thread gets
    one priority below it: a thread of the loop's own priority is never preempted by it
    (SCHED_FIFO has no time slices), so a background job of tens of milliseconds would hold
    the loop's release back by that long. One below, the loop preempts it at each release,
    and takes the GIL over within ``sys.getswitchinterval()`` (``apply`` shortens it). Under
    SCHED_OTHER nothing changes. Returns {policy, priority} of this thread, read back."""
    main = threading.main_thread().native_id
    try:
        if os.sched_getscheduler(main) == os.SCHED_FIFO:
            p = os.sched_getparam(main).sched_priority
            if p > 1:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(p - 1))
            else:
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        fifo = os.sched_getscheduler(0) == os.SCHED_FIFO
        return {"policy": "fifo" if fifo else "other", "priority": os.sched_getparam(0).sched_priority}
    except (OSError, AttributeError) as e:      # not Linux, or not permitted: stay as created
        return {"policy": None, "priority": None, "message": str(e)}


def other_threads(cpus: list[int] | None, priority: int | None, python_priority: int | None = None,
                  python_cpus: list[int] | None = None) -> dict:
    """Give every thread of this process but the calling one the CPU set ``cpus`` and
    SCHED_FIFO ``priority`` (None: leave that setting); Python threads (they take the GIL)
    get ``python_priority`` and ``python_cpus`` instead when given. For threads that libraries started before
    ``apply`` ran (Zenoh's and its Python binding's runtimes start some at import, and
    those do not inherit later changes). Returns {threads: [(tid, name, priority, cpus)],
    messages} read back from the kernel."""
    me = threading.get_native_id()
    pythons = {t.native_id for t in threading.enumerate()}
    threads, messages = [], []
    try:
        tids = sorted(int(t) for t in os.listdir("/proc/self/task"))
    except OSError as e:
        return {"threads": [], "messages": [f"threads not listed: {e}"]}
    for tid in tids:
        if tid == me:
            continue
        try:
            with open(f"/proc/self/task/{tid}/comm") as f:
                name = f.read().strip()
        except OSError:
            continue                        # ended meanwhile
        try:
            mine = python_cpus if tid in pythons and python_cpus is not None else cpus
            if mine is not None:
                os.sched_setaffinity(tid, set(int(c) for c in mine))
            prio = python_priority if tid in pythons and python_priority is not None else priority
            if prio is not None:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(int(prio)))
            fifo = os.sched_getscheduler(tid) == os.SCHED_FIFO
            threads.append((tid, name, os.sched_getparam(tid).sched_priority if fifo else None,
                            sorted(os.sched_getaffinity(tid))))
        except (OSError, ValueError) as e:
            messages.append(f"thread {tid} ({name}): {type(e).__name__}: {e}")
    return {"threads": threads, "messages": messages}


def restore() -> None:
    """Back to SCHED_OTHER, all CPUs, memory unlocked, GC enabled, the default GIL switch
    interval (for tests and teardown)."""
    sys.setswitchinterval(0.005)
    try:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except OSError:
        pass
    try:
        os.sched_setaffinity(0, range(os.cpu_count() or 1))
    except OSError:
        pass
    if _LIBC is not None:
        _LIBC.munlockall()
    gc.unfreeze()
    gc.enable()
