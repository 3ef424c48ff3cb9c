"""The ground console in a real terminal (tmux) against a real SIL run: it starts, shows the
vehicle, takes a command typed on its command line and shows the ACK; its .tlog, replayed
(`gse console --replay`, in the terminal too), shows the run's final bank and its events."""
from __future__ import annotations

import json
import math
import os
import shlex
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from ellipsled.sil.history import History
from gse.replay import TlogReplay
from interfaces.mavlink.signing.keys import SigningKey

from tests.ground_procs import free_udp, stop

pytestmark = [pytest.mark.slow,         # its SIL runs --no-rt: no FIFO process, it may run beside others
              pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux not installed (apt-get install tmux)")]
PY = [sys.executable, "-m", "ellipsled.cli"]
STATUSTEXT_LEN = 50



class Tmux:
    """One detached tmux session running one command; killed at the end whatever happens."""

    def __init__(self, name: str, argv: list[str], size=(150, 45)):
        self.name = f"{name}-{int(time.time() * 1e3) % 10**9}"
        # a tmux server keeps the environment it started with: hand this one's over explicitly
        env = " ".join(f"{k}={shlex.quote(os.environ[k])}" for k in ("PYTHONPATH", "PATH") if k in os.environ)
        cmd = f"cd {shlex.quote(os.getcwd())} && env {env} {shlex.join(argv)}; echo EXIT-$?; sleep 120"
        subprocess.run(["tmux", "new-session", "-d", "-s", self.name, "-x", str(size[0]), "-y", str(size[1]), cmd],
                       check=True)

    def screen(self) -> str:
        return subprocess.run(["tmux", "capture-pane", "-p", "-t", self.name], capture_output=True,
                              text=True).stdout

    def keys(self, *keys: str, literal: bool = False) -> None:
        subprocess.run(["tmux", "send-keys", "-t", self.name] + (["-l"] if literal else []) + list(keys), check=True)

    def wait_for(self, cond, timeout_s: float, what: str) -> str:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            s = self.screen()
            if cond(s):
                return s
            time.sleep(0.3)
        raise AssertionError(f"timed out waiting for {what}; screen:\n{self.screen()}")

    def kill(self) -> None:
        subprocess.run(["tmux", "kill-session", "-t", self.name], capture_output=True)


def test_console_in_a_terminal_commands_a_run_and_its_replay_shows_the_runs_end(tmp_path):
    key_file = tmp_path / "keys" / "signing.key"
    key_file.parent.mkdir()
    SigningKey.generate().write_file(str(key_file))
    vehicle, gcs = free_udp(), free_udp()
    out = tmp_path / "run"
    tlog = out / "console.tlog"
    out.mkdir()
    log = open(tmp_path / "run.log", "w")
    run = subprocess.Popen(PY + ["run", "nominal", "--realtime", "--no-rt", "--duration", "25", "--out", str(out),
                                 "--rerun", "none", "--no-plots", "--signing-key", str(key_file),
                                 "--mavlink-bind", f"udp:127.0.0.1:{vehicle}", "--gcs", f"udp:127.0.0.1:{gcs}"],
                           stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    console = Tmux("ellipsled-console", PY + ["gse", "console", "--signing-key", str(key_file), "--gcs-port", str(gcs),
                                              "--vehicle", f"udp:127.0.0.1:{vehicle}", "--tlog", str(tlog)])
    replay = None
    try:
        console.wait_for(lambda s: "ENTRY" in s and "ARMED" in s, 120, "the vehicle on the console")
        console.keys(":")
        time.sleep(0.5)               # as a person would: the command line takes focus first
        console.keys("inject 17 off", literal=True)
        console.keys("Enter")
        console.wait_for(lambda s: "inject jet 17 off: ACCEPTED" in s, 20, "the ACK on the screen")
        console.keys("Escape")
        assert run.wait(120) == 0, (tmp_path / "run.log").read_text()
        time.sleep(1.0)                               # the last telemetry in
        console.keys("q")
        console.wait_for(lambda s: "EXIT-0" in s, 20, "the console to quit")

        # the run's own records: the truth of what the replay must show
        fsw = json.loads((out / "fsw.json").read_text())
        h = History.load(out / "history.npz")
        run_events = [e["text"][:STATUSTEXT_LEN] for e in fsw["event_log"]]
        assert "GND INJECT JET 17 OFF" in run_events

        r = TlogReplay(tlog)
        r.play_all()
        assert [e.text for e in r.state.events] == run_events
        final = r.state.latest["ELLIPSLED_ENTRY_STATE"]        # what the replay ends on
        # the FSW outlives the plant by a moment (sensors stale: its navigation holds the
        # last frame), so its final telemetry shows the attitude at the plant's last step
        t_end = float(h["t_s"][-1])
        assert math.degrees(abs(math.remainder(final.bank - float(h["bank_rad"][-1]), 2 * math.pi))) < 0.5
        # and at the plant's last step the telemetry matches the run's records
        at_end, step = None, TlogReplay(tlog)
        for t_us, frame in step.records:
            step.feed(frame, None, t_us * 1e-6)
            es = step.state.latest.get("ELLIPSLED_ENTRY_STATE")
            if es is not None and es.time_boot_ms <= t_end * 1e3:
                at_end = es
        i = int(np.argmin(np.abs(h["t_s"] - at_end.time_boot_ms * 1e-3)))
        assert t_end - at_end.time_boot_ms * 1e-3 <= 0.5
        assert at_end.bank_ref == pytest.approx(float(h["bank_ref_rad"][i]), abs=1e-6)
        assert math.degrees(abs(math.remainder(at_end.bank - float(h["bank_rad"][i]), 2 * math.pi))) < 0.5

        # the same replay on the console's screens, in the terminal
        replay = Tmux("ellipsled-replay", PY + ["gse", "console", "--replay", str(tlog), "--speed", "20"])
        screen = replay.wait_for(lambda s: "(END)" in s, 60, "the replay to end")
        assert "REPLAY OF CONSOLE.TLOG" in screen
        assert f"{math.degrees(final.bank):8.2f}°" in screen, screen
        assert "··F" in screen.split("13     14     15")[1].splitlines()[1].split("│")[1].split()[4], screen  # jet 17
        replay.keys("q")
        replay.wait_for(lambda s: "EXIT-0" in s, 20, "the replay console to quit")
    finally:
        console.kill()
        if replay is not None:
            replay.kill()
        stop(run)
        log.close()
