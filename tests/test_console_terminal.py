"""The ground console in a real terminal (tmux) against a real SIL run: it starts, shows the
vehicle, takes a command typed on its command line and shows the ACK; its .tlog, replayed
(`gse console --replay`, in the terminal too), shows the run's final bank and its events."""
from __future__ import annotations

import json
import math
import shutil
import time

import numpy as np
import pytest

from ellipsled.procs import ELLIPSLED
from ellipsled.sil.history import History
from gse.replay import TlogReplay
from interfaces.vocabulary import JetState

from tests.procs import Tmux, start_ground_sil, stop

pytestmark = [pytest.mark.slow,         # its SIL runs --no-rt: no FIFO process, it may run beside others
              pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux not installed (apt-get install tmux)")]
STATUSTEXT_LEN = 50


def _shown(line: str, screen: str) -> bool:
    """``line`` on the screen, whole or wrapped onto the next row of its panel."""
    head, _, tail = line.rpartition(" ")
    rows = screen.splitlines()
    return any(line in r or head in r and tail in r + (rows[i + 1] if i + 1 < len(rows) else "")
               for i, r in enumerate(rows))


def test_console_in_a_terminal_commands_a_run_and_its_replay_shows_the_runs_end(tmp_path):
    sil = start_ground_sil(tmp_path, "nominal", 25.0, rt=False)
    run, out = sil.run, sil.out
    tlog = out / "console.tlog"
    out.mkdir(parents=True, exist_ok=True)      # the console may open its .tlog before the run makes the folder
    console = Tmux("ellipsled-console", ELLIPSLED + ["gse", "console", "--signing-key", str(sil.key_file),
                                                     "--gcs-port", str(sil.gcs), "--tlog", str(tlog),
                                                     "--vehicle", f"udp:127.0.0.1:{sil.vehicle}"])
    replay = None
    try:
        console.wait_for(lambda s: "ENTRY" in s and "ARMED" in s, 120, "the vehicle on the console")
        console.keys(":")
        time.sleep(0.5)               # as a person would: the command line takes focus first
        console.keys("inject 17 failed_off", literal=True)
        console.keys("Enter")
        console.wait_for(lambda s: _shown("inject jet 17 failed_off: ACCEPTED", s), 20, "the ACK on the screen")
        console.keys("Escape")
        assert run.wait(120) == 0, sil.log()
        time.sleep(1.0)                               # the last telemetry in
        console.keys("q")
        console.wait_for(lambda s: "EXIT-0" in s, 20, "the console to quit")

        # the run's own records: the truth of what the replay must show
        fsw = json.loads((out / "fsw.json").read_text())
        h = History.load(out / "history.npz")
        run_events = [e["text"][:STATUSTEXT_LEN] for e in fsw["event_log"]]
        assert "GND INJECT JET 17 FAILED_OFF" in run_events

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
        replay = Tmux("ellipsled-replay", ELLIPSLED + ["gse", "console", "--replay", str(tlog), "--speed", "20"])
        screen = replay.wait_for(lambda s: "(END)" in s, 60, "the replay to end")
        assert "REPLAY OF CONSOLE.TLOG" in screen
        assert f"{math.degrees(final.bank):8.2f}°" in screen, screen
        # jet 17's health as the run's FSW last had it (F once FDIR has seen it fail; on a starved
        # host it may not have been commanded on after the injection, and stays N)
        health = JetState(int(h["health"][-1][16])).name[0]
        assert f"··{health}" in screen.split("13     14     15")[1].splitlines()[1].split("│")[1].split()[4], screen
        replay.keys("q")
        replay.wait_for(lambda s: "EXIT-0" in s, 20, "the replay console to quit")
    finally:
        console.kill()
        if replay is not None:
            replay.kill()
        stop(run)
