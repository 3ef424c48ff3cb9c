"""The background table builder of the real-time allocator (``Allocator(async_rebuild=True)``)."""
from __future__ import annotations

from ..jobs import EVERY, BackgroundJob
from .tables import Workspace, build_tables


class Rebuilder:
    """``build_tables`` as a background job (fsw/jobs.py) on a workspace of its own; the
    numba kernels release the GIL, so the control thread keeps running. The allocator's jobs
    are tuples (key, usable, cols, bias, c, w, spill): the newest reconfiguration first, then
    the pre-build backlog. Every finished build (Tables, or the exception it raised) is kept
    by its key until the allocator takes it; the control thread never waits on a build.
    ``job.fn`` is the builder (tests wrap it to inject delays)."""

    def __init__(self, build=build_tables) -> None:
        self._ws = Workspace()
        self.job = BackgroundJob(build, "allocator-rebuild", keep=EVERY)

    def submit(self, job) -> None:
        self.job.submit(*job[1:], self._ws, tag=job[0])

    def queue(self, jobs) -> None:
        self.job.queue((job[0], (*job[1:], self._ws)) for job in jobs)

    def cancel_queue(self) -> None:
        self.job.cancel()

    def take(self, key):
        """The finished build for ``key`` (Tables, or the exception it raised), None if none."""
        ans = self.job.pop(key)
        return None if ans is None else _outcome(ans)

    def finished(self) -> list[tuple]:
        """(key, Tables or exception) of every finished build not yet taken."""
        return [(ans.tag, _outcome(ans)) for ans in self.job.pop_all()]

    def wait_idle(self, timeout_s: float) -> bool:
        return self.job.wait_idle(timeout_s)

    def close(self, timeout_s: float = 5.0) -> None:
        self.job.close(timeout_s)

    @property
    def alive(self) -> bool:
        return self.job.alive


def _outcome(ans):
    return ans.value if ans.error is None else ans.error
