"""Which sensor frame a real-time FSW release flies: the phase lock to the plant's schedule and
the frame due at each tick. Plain functions over step indices and nanoseconds; the FSW
process supplies the transport and the clock (tests supply scripted ones)."""
from __future__ import annotations

from typing import Callable, Iterable


def phase_origin_ns(frames: Iterable[tuple[int, int]], period_ns: int) -> int:
    """The plant's schedule from (step, publication time [ns]) pairs: step k is published at
    origin + k * period, never earlier and often later in its first steps (its own first-call
    costs), so the origin is the earliest the frames imply, not the first frame's."""
    return min(t_pub_ns - k * period_ns for k, t_pub_ns in frames)


def phase_steady(frames: list[tuple[int, int]], period_ns: int, n: int = 5) -> bool:
    """Whether the last ``n`` of (step, publication time [ns]) pairs keep one schedule: the
    origins they imply agree within a quarter period. A plant catching up after a stall
    publishes its backlog in a burst, each frame a period later on its schedule than the next;
    an origin taken from the burst alone would put every release up to a period late."""
    if len(frames) < n:
        return False
    origins = [t_pub_ns - k * period_ns for k, t_pub_ns in frames[-n:]]
    return max(origins) - min(origins) <= period_ns // 4


class PhaseLock:
    """The phase lock's decision, frame by frame (``offer``): the plant's origin once the last
    ``n_frames`` frames keep one schedule (``phase_steady``: not a catch-up burst), or -- a host
    that never lets them -- once ``wait_ns`` has passed on the caller's clock since the first
    frame. The wait is wall time, not a number of frames: a plant that stalled publishes its
    whole backlog at once when it resumes, read within milliseconds, and a lock on those frames
    alone puts every release of the run up to a period late (seen: a plant stalled 3.3 s at its
    start under load; its 166-frame backlog outlasted a wait of 110 frames, and every frame of
    that run reached the FSW 13.4 ms late)."""

    def __init__(self, period_ns: int, n_frames: int, wait_ns: int):
        self.period_ns, self.n_frames, self.wait_ns = int(period_ns), int(n_frames), int(wait_ns)
        self.frames: list[tuple[int, int]] = []
        self.t_give_up: int | None = None

    def offer(self, k: int, t_pub_ns: int, now_ns: int) -> int | None:
        """Frame ``k`` published at ``t_pub_ns``, seen at ``now_ns``: the origin to lock to, or None."""
        if self.t_give_up is None:
            self.t_give_up = now_ns + self.wait_ns
        f = self.frames
        f.append((int(k), int(t_pub_ns)))
        del f[:-self.n_frames]
        if len(f) < self.n_frames or not (phase_steady(f, self.period_ns) or now_ns >= self.t_give_up):
            return None
        return phase_origin_ns(f, self.period_ns)


def due_step(next_k: int, cycle_k: int, locked_plant: bool) -> int:
    """The plant step a release waits for. While the plant is the one the ticks are locked
    to, tick k flies step k: a frame that came after its tick's wait must not make every
    later tick take the previous period's frame. After the plant changed (a restart counts
    its steps anew) the step after the last one flown is due."""
    return max(next_k, cycle_k) if locked_plant else next_k


def take_due_frame(fetch: Callable[[], int | None], due: int, deadline_ns: int,
                   now_ns: Callable[[], int], pause: Callable[[], None]) -> int | None:
    """Take frames until step ``due`` or a later one has come, or the deadline has passed.
    ``fetch()``: the step of the newest frame accepted since the last call, or None.
    Returns the step of the newest frame taken (it may be older than ``due``), or None when
    no frame came at all."""
    got = None
    while True:
        k = fetch()
        if k is not None:
            got = k
            if k >= due:
                return got
        if now_ns() >= deadline_ns:
            return got
        pause()
