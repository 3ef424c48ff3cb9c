"""What a run shows on the terminal: its progress: simulated time, speed (simulated seconds per wall
second) and the time left, as a rich progress bar on stderr; lines printed through it go
above the bar. When stderr is not a terminal (a pipe, a log file, CI) there is no bar and
lines are printed as they come, so logs stay plain text.

The simulated end is the scenario's time cap (or --duration): a run that reaches Mach 2
earlier ends before the bar fills, so the time left is an upper bound.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

REFRESH_HZ = 4

# What each file of a run's folder is (the end-of-run listing).
FILES = {
    "summary.json": "figures of merit (same as ellipsled batch)",
    "sil.json": "SIL speed, latency, jitter, slips",
    "history.npz": "every signal of the run (sim + fsw), numpy",
    "sim_history.npz": "the plant's records", "fsw_history.npz": "the flight software's records",
    "sim.json": "the plant process's report", "fsw.json": "the flight software process's report",
    "sim_latency.npz": "the plant's latency samples", "fsw_timing.npz": "the FSW's jitter and frame-age samples",
    "run.rrd": "Rerun recording", "console.tlog": "ground console telemetry log (MAVLink)",
    "sim.log": "plant log", "fsw.log": "flight software log", "viz.log": "Rerun bridge log",
}


class RunProgress:
    def __init__(self, label: str, t_end_s: float, *, stream=None, enabled: bool | None = None):
        self.stream = stream or sys.stderr
        self.t_end_s = float(t_end_s)
        self.enabled = self.stream.isatty() if enabled is None else bool(enabled)
        self._wall0 = time.monotonic()
        self._t0_s: float | None = None       # simulated time when the first update came
        self._bar = None
        if self.enabled:
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
            self._bar = Progress(TextColumn("{task.description}"), BarColumn(),
                                 TextColumn("t {task.completed:6.1f} / {task.total:.0f} s"),
                                 TextColumn("{task.fields[speed]}"), TextColumn("{task.fields[eta]}"),
                                 TimeElapsedColumn(),
                                 console=Console(file=self.stream), refresh_per_second=REFRESH_HZ,
                                 transient=False)
            self._task = self._bar.add_task(label, total=self.t_end_s, speed="", eta="")
            self._bar.start()

    def update(self, t_s: float) -> None:
        """The simulated time reached (s)."""
        if self._bar is None:
            return
        now = time.monotonic()
        if self._t0_s is None:
            self._t0_s, self._wall0 = t_s, now
        wall = now - self._wall0
        speed = (t_s - self._t0_s) / wall if wall > 0.5 else None
        fields = {"speed": "", "eta": ""}
        if speed:
            left = max(0.0, self.t_end_s - t_s) / speed
            fields = {"speed": f"{speed:5.1f}x real time", "eta": f"at most {_clock(left)} left"}
        self._bar.update(self._task, completed=min(t_s, self.t_end_s), **fields)

    def print(self, line: str) -> None:
        """A line above the bar (or plainly, without one)."""
        if self._bar is not None:
            self._bar.console.print(line, markup=False, highlight=False, soft_wrap=True)
        else:
            print(line, file=self.stream, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _clock(s: float) -> str:
    s = int(round(s))
    return f"{s // 60}:{s % 60:02d}"


def files_written(out: Path) -> str:
    """The run folder's files, what each is, and how to open the recording."""
    out = Path(out)
    lines = [f"files in {out}:"]
    for name, what in FILES.items():
        if (out / name).exists():
            lines.append(f"  {name:<16} {what}")
    plots = sorted(p.name for p in out.glob("*.png"))
    if plots:
        lines.append(f"  {'*.png':<16} plots: {', '.join(plots)}")
    rrd = out / "run.rrd"
    if rrd.exists():
        from gse.viz.sinks import rerun_exe
        lines.append(f"open the recording: {rerun_exe()} {rrd}   (no display: {rerun_exe()} --serve-web "
                     f"--bind 127.0.0.1 {rrd}, then the URL it prints)")
    return "\n".join(lines)

