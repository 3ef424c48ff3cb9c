"""The background table builder of the real-time allocator (``Allocator(async_rebuild=True)``)."""
from __future__ import annotations

import threading
from collections import deque

from common import rt

from .tables import Workspace, build_tables


class Rebuilder:
    """Builds tables on a background daemon thread (the numba kernels release the GIL, so
    the control thread keeps running). Jobs: the newest reconfiguration request first, then
    the pre-build queue. Results wait in ``done`` (dict, key -> Tables) until the
    allocator takes them; the control thread never waits on this object's lock."""

    def __init__(self, build=build_tables) -> None:
        self._build = build                   # the table builder (tests wrap it to inject delays)
        self._cv = threading.Condition()
        self._request = None                  # (key, usable, cols, bias, c, w): newest wins
        self._queue: deque = deque()          # pre-builds, same tuples
        self._busy = False
        self._stop = False
        self._ws = Workspace()
        self._gate = threading.Event()        # cleared: jobs wait (deterministic tests)
        self._gate.set()
        self.done: dict = {}
        self._thread = threading.Thread(target=self._run, name="allocator-rebuild", daemon=True)
        self._thread.start()

    def submit(self, job) -> None:
        with self._cv:
            self._request = job
            self._cv.notify()

    def queue(self, jobs) -> None:
        with self._cv:
            self._queue.extend(jobs)
            self._cv.notify()

    def cancel_queue(self) -> None:
        with self._cv:
            self._queue.clear()
            self._request = None

    def hold(self) -> None:
        """Jobs not yet started wait until release() (tests: a deterministic interim)."""
        self._gate.clear()

    def release(self) -> None:
        self._gate.set()

    def idle(self) -> bool:
        return not self._busy and self._request is None and not self._queue

    def wait_idle(self, timeout_s: float) -> bool:
        with self._cv:
            return self._cv.wait_for(self.idle, timeout_s)

    def close(self, timeout_s: float = 5.0) -> None:
        with self._cv:
            self._stop = True
            self._request = None
            self._queue.clear()
            self._cv.notify_all()
        self._gate.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout_s)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        rt.run_below_loop()
        while True:
            with self._cv:
                while not self._stop and self._request is None and not self._queue:
                    self._cv.wait()
                if self._stop:
                    return
                if self._request is not None:
                    job, self._request = self._request, None
                else:
                    job = self._queue.popleft()
                self._busy = True
            self._gate.wait()
            if self._stop:
                return
            key, usable, cols, bias, c, w, spill = job
            try:
                tables = self._build(usable, cols, bias, c, w, spill, self._ws)
            except Exception as e:  # noqa: BLE001 - handed to the allocator, never lost
                tables = e
            with self._cv:
                self.done[key] = tables
                self._busy = False
                self._cv.notify_all()
