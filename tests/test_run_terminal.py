"""What ``ellipsled run`` tells a user on the terminal: the web viewer's URL (and it answers),
the signing key, the files written and how to open the recording; no progress bar when the
output is not a terminal (the bar itself is checked in a real terminal, under tmux)."""
from __future__ import annotations

import re
import shutil
import signal
import subprocess
import threading
import time
import urllib.request

import pytest

from ellipsled.procs import ELLIPSLED, stop_process
from ellipsled.sil.progress import ProgressFile
from ellipsled.terminal import RunProgress, files_written

from tests.procs import Tmux, free_udp

pytestmark = pytest.mark.slow
URL = re.compile(r"https?://127\.0\.0\.1:\d+/\S*")



class Lines:
    """A child's merged output, read by a thread (the pipe never fills)."""

    def __init__(self, proc):
        self.lines: list[str] = []
        self._t = threading.Thread(target=self._read, args=(proc.stdout,), daemon=True)
        self._t.start()

    def _read(self, f):
        for line in f:
            self.lines.append(line.rstrip("\n"))

    def text(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, pattern: re.Pattern, timeout_s: float, proc) -> re.Match:
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            m = pattern.search(self.text())
            if m:
                return m
            assert proc.poll() is None, f"run ended before {pattern.pattern}:\n{self.text()}"
            time.sleep(0.1)
        raise AssertionError(f"no {pattern.pattern} within {timeout_s} s:\n{self.text()}")


def _get(url: str, timeout_s: float) -> tuple[int, bytes]:
    """HTTP GET, retried until the server answers (it may still be binding)."""
    end = time.monotonic() + timeout_s
    while True:
        try:
            with urllib.request.urlopen(url, timeout=2) as r:
                return r.status, r.read()
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.2)


def test_run_with_the_web_viewer_prints_a_url_that_answers_and_names_its_files(tmp_path):
    out = tmp_path / "run"
    run = subprocess.Popen(ELLIPSLED + ["run", "nominal", "--duration", "600", "--rerun", "web+file", "--no-plots",
                                        "--out", str(out), "--mavlink-bind", f"udp:127.0.0.1:{free_udp()}",
                                        "--gcs", f"udp:127.0.0.1:{free_udp()}"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True)
    lines = Lines(run)
    try:
        url = lines.wait_for(URL, 90, run).group(0)
        status, body = _get(url, 30)
        assert status == 200 and b"<html" in body.lower(), body[:200]
        key = lines.wait_for(re.compile(r"signing key (\S+)"), 10, run).group(1)
        assert key.endswith("signing.key")
        run.send_signal(signal.SIGINT)                    # the user stops the run
        run.wait(60)
    finally:
        stop_process(run, 10.0)
    text = lines.text()
    assert "━" not in text, "no progress bar when the output is not a terminal"
    assert f"files in {out}" in text and "run.rrd" in text and "viz.log" in text, text
    assert f"rerun {out / 'run.rrd'}" in text or f"{out / 'run.rrd'}" in text
    assert (out / "run.rrd").exists()


def test_progress_file_carries_the_simulated_time_and_a_torn_read_is_none(tmp_path):
    p = tmp_path / "progress"
    pf = ProgressFile(p, every_s=10.0)
    assert ProgressFile.read(p) is None                 # nothing written yet
    pf.write(12.5)
    pf.write(99.0)                                      # within every_s: not written
    assert ProgressFile.read(p) == 12.5
    pf.write(600.25, force=True)
    assert ProgressFile.read(p) == 600.25
    pf.close()
    p.write_bytes(b"  1x.")                             # not a number: ignored, read again later
    assert ProgressFile.read(p) is None


def test_progress_without_a_terminal_prints_plain_lines(tmp_path):
    import io
    s = io.StringIO()
    with RunProgress("x", 100.0, stream=s) as bar:
        bar.update(10.0)
        bar.print("[sim] a line")
    assert s.getvalue() == "[sim] a line\n"


def test_files_written_lists_what_exists_and_how_to_open_the_recording(tmp_path):
    (tmp_path / "summary.json").write_text("{}")
    (tmp_path / "run.rrd").write_bytes(b"")
    (tmp_path / "bank.png").write_bytes(b"")
    text = files_written(tmp_path)
    assert "summary.json" in text and "bank.png" in text and "sil.json" not in text
    assert f"{tmp_path / 'run.rrd'}" in text.splitlines()[-1]


@pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux not installed (apt-get install tmux)")
def test_batch_shows_a_progress_bar_in_a_real_terminal(tmp_path):
    """A batch run inside tmux (a real pseudo-terminal): the bar shows simulated time and speed."""
    out = tmp_path / "b"
    term = Tmux("ellipsled-bar", ELLIPSLED + ["batch", "nominal", "--no-plots", "--out", str(out)], size=(150, 30))
    try:
        screen = term.wait_for(lambda s: "EXIT-" in s, 240, "the batch run to end")
        assert "EXIT-0" in screen, screen
        bar = [ln for ln in screen.splitlines() if "nominal batch" in ln]
        assert bar and "/ 700 s" in bar[-1] and "x real time" in bar[-1], screen
        assert f"files in {out}" in screen and "summary.json" in screen
    finally:
        term.kill()
