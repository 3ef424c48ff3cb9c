"""Where a recording goes: 'viewer' | 'web' | 'file' | 'none' | 'auto', or '+'-joined
combinations such as 'web+file' (docs/interfaces/index.md, Rerun sinks).

- viewer: a gRPC server hosted here on 127.0.0.1 plus a native viewer process connected to
  it (needs a display: DISPLAY or WAYLAND_DISPLAY); without a display it falls back to a
  file and prints how to open it;
- web: the same gRPC server plus Rerun's web viewer (``rerun --serve-web --bind 127.0.0.1``
  pointed at it), URL printed. The SDK's ``serve_*`` convenience functions bind 0.0.0.0:
  not used;
- file: ``<out_dir>/<name>.rrd``;
- none: no recording stream at all (a stream without sinks buffers everything in memory);
- auto: viewer when a display exists, else file.

Memory is bounded: live data only goes to the gRPC server hosted in this process, which
keeps at most ``server_memory_limit`` (oldest data dropped first) whether or not any
viewer is connected. A client sink (``GrpcSink``) to an unreachable viewer would buffer
without limit, so none is used.

The live .rrd is streamed without a footer: an SDK ``FileSink`` that writes one keeps the
footer's manifest entry of every chunk in memory until the file is closed (about 1.9 kB
per chunk; a full entry at 50 Hz sends ~15,500 chunks, so +28 MB growing linearly), with
no API to bound it. ``Sinks.close`` then adds the footer with ``rerun rrd optimize`` (a
separate process, after the run; it also compacts the chunks, ~40 MB -> ~17 MB for a full
entry). If that fails the streamed file is kept: valid, readable, without a footer. The SDK
warns of the missing footer on every such sink: that line is filtered where Rerun's logger is
configured (rerun_log.py), the user is told by the bridge's own line instead.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import urllib.parse
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import rerun as rr

from gse.viz.blueprint import default_blueprint

MODES = ("viewer", "web", "file", "none", "auto")
LOOPBACK = "127.0.0.1"
SERVER_MEMORY_LIMIT = "256MiB"   # a full entry at 50 Hz is ~40 MB of chunks
VIEWER_MEMORY_LIMIT = "25%"
FINALISE_TIMEOUT_S = 60.0        # a wide margin over `rerun rrd optimize` of a full entry (seconds)


def rerun_exe() -> str:
    """The Rerun CLI binary shipped with rerun-sdk (not the Python wrapper script, so the
    process we start is the one we stop)."""
    import rerun_cli
    return os.path.join(os.path.dirname(rerun_cli.__file__), "rerun")


def has_display(env: dict | None = None) -> bool:
    env = os.environ if env is None else env
    return bool(env.get("DISPLAY") or env.get("WAYLAND_DISPLAY"))


def parse_mode(mode: str, display: bool) -> set[str]:
    """The set of concrete sinks of a mode string (ValueError names the bad part)."""
    if not isinstance(mode, str) or not mode:
        raise ValueError(f"rerun mode: must be one of {MODES} or a '+' combination, got {mode!r}")
    parts = {p.strip() for p in mode.lower().split("+")}
    bad = parts - set(MODES)
    if bad:
        raise ValueError(f"rerun mode: unknown {sorted(bad)} in {mode!r}; choose from {MODES}")
    if "none" in parts:
        if len(parts) > 1:
            raise ValueError(f"rerun mode: 'none' cannot be combined ({mode!r})")
        return set()
    if "auto" in parts:
        parts.discard("auto")
        parts.add("viewer" if display else "file")
    if "viewer" in parts and not display:
        parts.discard("viewer")
        parts.add("file")
    return parts


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((LOOPBACK, 0))
        return s.getsockname()[1]


def web_viewer_url(web_port: int, grpc_uri: str) -> str:
    return f"http://{LOOPBACK}:{web_port}/?url={urllib.parse.quote(grpc_uri, safe='')}"


@dataclass
class Sinks:
    """An open recording (``rec`` None for 'none') and what was started for it."""
    rec: rr.RecordingStream | None
    kinds: set[str]
    rrd_path: Path | None = None
    grpc_uri: str | None = None
    web_url: str | None = None
    procs: list[subprocess.Popen] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)
    say: Callable[[str], None] | None = None

    def close(self, timeout_s: float = 5.0) -> None:
        """Flush the recording, finalise the file, stop the processes started here."""
        if self.rec is not None:
            try:
                self.rec.flush(timeout_sec=timeout_s)
                self.rec.disconnect()       # closes the file, stops the server
            except Exception:
                pass
            self.rec = None
            if self.rrd_path is not None:
                ok, why = add_rrd_footer(self.rrd_path)
                if not ok:
                    m = (f"rerun: {self.rrd_path} kept without a footer ({why}); "
                         f"add one with `{rerun_exe()} rrd optimize`")
                    self.messages.append(m)
                    if self.say is not None:
                        self.say(m)
        for p in self.procs:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                try:
                    p.wait(timeout=timeout_s)
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait(timeout=timeout_s)
        self.procs = []


def add_rrd_footer(path: Path, timeout_s: float = FINALISE_TIMEOUT_S) -> tuple[bool, str]:
    """Rewrite the footer-less .rrd ``path`` in place with a footer (``rerun rrd optimize``,
    live-viewer chunk sizes). Returns (done, reason if not); on failure ``path`` is untouched."""
    path = Path(path)
    if not path.exists():
        return False, "file missing"
    tmp = path.with_name(f".{path.stem}.footer.rrd")
    try:
        r = subprocess.run([rerun_exe(), "rrd", "optimize", "--profile", "live", str(path), "-o", str(tmp)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=timeout_s)
        if r.returncode != 0 or not tmp.exists():
            lines = (r.stderr or "").strip().splitlines()
            return False, f"rerun rrd optimize exit {r.returncode}: {lines[-1] if lines else ''}"
        os.replace(tmp, path)
        return True, ""
    except (OSError, subprocess.SubprocessError) as e:
        return False, f"rerun rrd optimize: {e}"
    finally:
        tmp.unlink(missing_ok=True)


def open_sinks(mode: str, out_dir: Path | str | None, *, name: str = "run",
               app_id: str = "ellipsled", blueprint: bool = True,
               grpc_port: int | None = None, web_port: int | None = None,
               server_memory_limit: str = SERVER_MEMORY_LIMIT,
               viewer_memory_limit: str = VIEWER_MEMORY_LIMIT,
               display: bool | None = None, say: Callable[[str], None] | None = None) -> Sinks:
    """Open a recording stream with the sinks of ``mode`` (see the module doc).

    ``out_dir``: folder of the .rrd (needed when a file sink results); ``name``: file stem
    and recording name. ``say``: where the URL / hint lines go (default: stderr).
    """
    say = say or (lambda s: print(s, file=sys.stderr))
    display = has_display() if display is None else display
    kinds = parse_mode(mode, display)
    out = Sinks(rec=None, kinds=kinds, say=say)
    if not kinds:
        return out
    rec = rr.RecordingStream(app_id, recording_id=uuid.uuid4())
    sinks = []
    try:
        if "file" in kinds:
            if out_dir is None:
                raise ValueError("rerun mode: a file sink needs an output folder (out_dir)")
            Path(out_dir).mkdir(parents=True, exist_ok=True)
            out.rrd_path = Path(out_dir) / f"{name}.rrd"
            sinks.append(rr.FileSink(out.rrd_path, write_footer=False))   # flat memory: module doc
        if kinds & {"viewer", "web"}:
            port = grpc_port or _free_port()
            server = rr.GrpcServerSink(LOOPBACK, port, server_memory_limit=server_memory_limit)
            out.grpc_uri = server.uri
            sinks.append(server)
        # set_sinks sends the default blueprint to every sink (once: a second send would store
        # a second blueprint in the recording)
        rec.set_sinks(*sinks, default_blueprint=default_blueprint() if blueprint else None)
        rec.send_recording_name(name)
        if "web" in kinds:
            wport = web_port or _free_port()
            out.procs.append(subprocess.Popen(
                [rerun_exe(), "--serve-web", "--bind", LOOPBACK, "--web-viewer-port", str(wport), out.grpc_uri],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
            out.web_url = web_viewer_url(wport, out.grpc_uri)
            out.messages.append(f"rerun: open the web viewer at {out.web_url}")
        if "viewer" in kinds:
            out.procs.append(subprocess.Popen(
                [rerun_exe(), "--connect", out.grpc_uri, "--bind", LOOPBACK, "--port", str(_free_port()),
                 "--memory-limit", viewer_memory_limit, "--expect-data-soon"],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
            out.messages.append(f"rerun: native viewer connected to {out.grpc_uri}")
        if out.rrd_path is not None:
            out.messages.append(f"rerun: recording to {out.rrd_path} (streamed without a footer, "
                                f"added when the bridge closes)")
            if not display:
                out.messages.append(
                    f"rerun: no display; open it later with `{rerun_exe()} {out.rrd_path}` on a machine "
                    f"with a display, or in a browser: `{rerun_exe()} --serve-web --bind {LOOPBACK} "
                    f"{out.rrd_path}` then http://{LOOPBACK}:9090")
    except Exception:
        out.rec = rec
        out.close()
        raise
    out.rec = rec
    for m in out.messages:
        say(m)
    return out
