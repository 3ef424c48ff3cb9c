"""``ellipsled run``: the whole SIL on one machine with one command.

Starts the plant (listening on a free loopback port), the flight software, the Rerun
bridge and optionally the ground console, all on an embedded Zenoh configuration (peer
mode, no scouting, explicit 127.0.0.1 endpoints: no router to install). When the plant
finishes, or on Ctrl-C / SIGTERM, every child is stopped by its pid (SIGTERM, then SIGKILL
after a timeout). The run writes the same summary.json as the batch runner, plus sil.json
(speed, latency, jitter) and the per-process records. Across machines: pass
--zenoh-config FILE (router or peers, TLS, access control) — configuration, not code.

The terminal shows what a user needs to find: the children's lines (their logs, relayed:
the viewer's URL, the recording's path, faults applied), the signing key, a progress bar
of simulated time (when the terminal is one), and at the end the summary and every file
written with how to open the recording.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from common import argtypes
from ellipsled.node_reports import by_tenth, lp_split, read_fsw, read_sim
from ellipsled.procs import ELLIPSLED, die_with_parent, stop_process
from ellipsled.runlib import EXIT_NOT_COMPLETED, exit_code, format_summary, judge
from ellipsled.terminal import RunProgress, files_written
from interfaces import transport
from interfaces.vocabulary import DEFAULT_GCS, DEFAULT_VEHICLE

from .common import DEFAULT_PREFIX, rt_arguments, say
from .history import History, merge
from .progress import ProgressFile
from .variant import add_variant_arguments, prepare_args, variant_argv

ROLE = "run"
STOP_TIMEOUT_S = 5.0
ROLES = ("viz", "fsw", "sim")


def add_arguments(p) -> None:
    p.add_argument("scenario", nargs="?", default="nominal", help="scenario name (data/scenarios) or .toml path")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="mode", action="store_const", const="lockstep",
                      help="deterministic, as fast as the CPU allows (default)")
    mode.add_argument("--realtime", dest="mode", action="store_const", const="realtime",
                      help="the plant on its own clock at --speed, the FSW on absolute deadlines")
    p.set_defaults(mode="lockstep")
    p.add_argument("--duration", type=argtypes.duration_s, default=None, help="stop after S seconds of simulated time")
    add_variant_arguments(p)
    p.add_argument("--out", default="runs/sil", help="output folder")
    p.add_argument("--seed", type=argtypes.seed, default=None)
    p.add_argument("--ft-off", action="store_true")
    p.add_argument("--speed", type=argtypes.speed, default=1.0, help="real time: simulated seconds per wall second")
    p.add_argument("--rerun", default="auto",
                   help="viewer | web | file | none | auto (viewer with a display, else file); '+' joins")
    p.add_argument("--console", action="store_true", help="open the ground console beside the SIL")
    p.add_argument("--signing-key", default=None,
                   help="MAVLink signing key file; default: a fresh key for this run in a private temp folder")
    p.add_argument("--mavlink-bind", default=DEFAULT_VEHICLE, help="the vehicle's MAVLink address")
    p.add_argument("--gcs", default=DEFAULT_GCS, help="where the vehicle sends its telemetry")
    p.add_argument("--zenoh-config", default=None, metavar="FILE", help="Zenoh JSON5 configuration for every node")
    p.add_argument("--zenoh-lowlatency", action=argparse.BooleanOptionalAction, default=True,
                   help="Zenoh's low-latency transport for every node (default on): ~30-60 us less per "
                        "hop; --no-zenoh-lowlatency for the standard transport")
    p.add_argument("--endpoint", default=None, help="the plant's listen endpoint (default tcp/127.0.0.1:<free>)")
    p.add_argument("--prefix", default=DEFAULT_PREFIX)
    p.add_argument("--rt", action=argparse.BooleanOptionalAction, default=None,
                   help="real-time hygiene, SCHED_FIFO/affinity/mlockall for sim (CPU 0) and fsw (CPU 1) "
                        "when permitted (default: on with --realtime, off in lockstep)")
    p.add_argument("--fsw-timeout", type=argtypes.timeout_s, default=10.0)
    p.add_argument("--rt-offset-us", type=argtypes.offset_us, default=None,
                   help="real time: the FSW releases this long after the plant publishes a step "
                        "(default: ellipsled fsw's)")
    p.add_argument("--rehearse", action=argparse.BooleanOptionalAction, default=True,
                   help="real time: each node rehearses while it waits, so that what it runs is warm "
                        "when the frame or command comes -- the FSW its control cycle on a spare "
                        "(executive.rehearse_us) and its receiving path, the plant its command's "
                        "decode (default on)")
    p.add_argument("--no-plots", action="store_true")


def control_task_us(out: Path) -> dict | None:
    """The FSW's control task over the whole run, p50 / p99 / max [us] and its runs, from the
    per-tick times the FSW node saved (fsw_timing.npz); None when it saved none (the
    executive's own statistics cover only its recent cycles). With the node's per-tick flag
    of the duty-cycle LP's cycles: their count (``lp_cycles``) and the p99 without them
    (``p99_without_lp``), the rest of the control task. ``p50_by_tenth``: the p50 of each
    tenth of the run, lowest / median / highest (node_reports.by_tenth), so that a p99 set by a
    slow spell of the host can be told from a control task slower throughout."""
    import numpy as np
    try:
        with np.load(Path(out) / "fsw_timing.npz") as z:
            if "control_ns" not in z.files:
                return None
            c = z["control_ns"]
            lp = z["lp_cycle"] if "lp_cycle" in z.files else None
    except (OSError, ValueError):
        return None
    ran = c >= 0
    c = c[ran] / 1e3
    if not len(c):
        return None
    f = {"p50": float(np.percentile(c, 50)), "p99": float(np.percentile(c, 99)), "max": float(c.max()),
         "runs": int(len(c)), "p50_by_tenth": by_tenth(c)}
    if lp is not None and len(lp) == len(ran):
        f.update(lp_split(c, lp[ran]))
    return f


class LogRelay:
    """Follows the children's log files and hands each complete new line to ``emit``."""

    def __init__(self, emit):
        self.emit = emit
        self.files = []

    def follow(self, path: Path) -> None:
        self.files.append([open(path, "rb"), b""])

    def pump(self) -> None:
        for entry in self.files:
            data = entry[0].read()
            if not data:
                continue
            *lines, entry[1] = (entry[1] + data).split(b"\n")
            for line in lines:
                self.emit(line.decode("utf-8", "replace").rstrip())

    def close(self) -> None:
        for f, rest in self.files:
            if rest:
                self.emit(rest.decode("utf-8", "replace").rstrip())
            f.close()
        self.files = []


class Launcher:
    def __init__(self, args):
        self.args = args
        self.out = Path(args.out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.children: dict[str, subprocess.Popen] = {}
        self.logs = []
        self.stop = False
        self.tmpdir = None
        self.progress = None
        self.relay = None

    def _on_signal(self, signum, frame):
        self.stop = True

    def _key_file(self) -> str:
        if self.args.signing_key:
            return self.args.signing_key
        if os.environ.get("ELLIPSLED_SIGNING_KEY_FILE"):
            return os.environ["ELLIPSLED_SIGNING_KEY_FILE"]
        from interfaces.mavlink.signing.keys import SigningKey
        self.tmpdir = tempfile.mkdtemp(prefix="ellipsled-key-")
        path = os.path.join(self.tmpdir, "signing.key")
        SigningKey.generate().write_file(path)
        return path

    def say(self, text: str) -> None:
        if self.progress is not None:
            self.progress.print(f"[{ROLE}] {text}")
        else:
            say(ROLE, text)

    def spawn(self, role: str, argv: list[str]) -> None:
        """A child with its output in ROLE.log (relayed to the terminal unless the console has it)."""
        cmd = ELLIPSLED + argv
        path = self.out / f"{role}.log"
        log = open(path, "w")
        self.logs.append(log)
        # a launcher killed outright takes its children with it (the kernel signals them)
        self.children[role] = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                               preexec_fn=die_with_parent())
        if self.relay is not None:
            self.relay.follow(path)

    def terminate(self, role: str) -> int | None:
        p = self.children.get(role)
        if p is None:
            return None
        return stop_process(p, STOP_TIMEOUT_S, kill_wait_s=STOP_TIMEOUT_S, on_kill=lambda: self.say(
            f"{role} (pid {p.pid}) did not stop within {STOP_TIMEOUT_S:g} s: killing it"))

    def run(self) -> int:
        old = {s: signal.signal(s, self._on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            return self._run()
        finally:
            for role in ("sim", "fsw", "viz"):
                self.terminate(role)
            self._end_terminal()
            for log in self.logs:
                log.close()
            if self.tmpdir:
                shutil.rmtree(self.tmpdir, ignore_errors=True)
            for s, h in old.items():
                signal.signal(s, h)

    def _run(self) -> int:
        a = self.args
        scn = prepare_args(a)           # a scenario the nodes would refuse is refused before they start
        self.rt = a.rt if a.rt is not None else a.mode == "realtime"
        # peers route nothing for each other (no router, no gossip): every viewer connects to
        # both data sources, the plant and the FSW, each listening on its own loopback port
        endpoint = a.endpoint or transport.loopback(transport.free_port())
        fsw_endpoint = transport.loopback(transport.free_port())
        common = ["--prefix", a.prefix] + (["--zenoh-config", a.zenoh_config] if a.zenoh_config else []) \
            + ([] if a.zenoh_lowlatency else ["--no-zenoh-lowlatency"])
        scen = [a.scenario] + (["--seed", str(a.seed)] if a.seed is not None else []) \
            + (["--ft-off"] if a.ft_off else []) + (["--duration", str(a.duration)] if a.duration is not None else []) \
            + variant_argv(a)
        mode = ["--realtime" if a.mode == "realtime" else "--lockstep"] + ([] if a.rehearse else ["--no-rehearse"])
        key = self._key_file()
        if not a.console:               # the console owns the terminal otherwise
            self.relay = LogRelay(self.say_child)
            self.progress = RunProgress(f"{scn.name} {a.mode}", scn.max_duration_s)
        fd, self.progress_path = tempfile.mkstemp(prefix="ellipsled-progress-")
        os.close(fd)
        viz = a.rerun != "none"
        if viz:
            self.spawn("viz", ["viz", "--connect", endpoint, "--connect", fsw_endpoint, "--rerun", a.rerun, "--out", str(self.out),
                               "--name", "run"] + common)
        self.spawn("fsw", ["fsw"] + scen + mode + common + ["--connect", endpoint, "--listen", fsw_endpoint,
                                                           "--out", str(self.out), "--signing-key", key,
                                                           "--mavlink-bind", a.mavlink_bind, "--gcs", a.gcs]
                   + (rt_arguments("fsw") if self.rt else [])
                   + (["--rt-offset-us", f"{a.rt_offset_us:g}"] if a.rt_offset_us is not None else []))
        self.spawn("sim", ["sim"] + scen + mode + common + ["--listen", endpoint, "--out", str(self.out),
                                                           "--speed", str(a.speed), "--fsw-timeout", str(a.fsw_timeout),
                                                           "--progress-file", self.progress_path]
                   + (["--wait-bridge"] if viz else []) + (rt_arguments("sim") if self.rt else []))
        self.say(f"SIL {a.mode}: plant on {endpoint}; pids " +
                 ", ".join(f"{r} {p.pid}" for r, p in self.children.items()) + f"; logs in {self.out}")
        self.say(f"ground link: vehicle {a.mavlink_bind}, telemetry to {a.gcs}; signing key {key} "
                 f"(e.g. ELLIPSLED_SIGNING_KEY_FILE={key} ellipsled gse console)")
        if a.console:
            self._console(key)
        sim = self.children["sim"]
        while not self.stop and sim.poll() is None:
            time.sleep(0.05)
            self._pump_terminal()
            for role in ("fsw", "viz"):
                p = self.children.get(role)
                if p is not None and p.poll() is not None and not getattr(p, "_reported", False):
                    p._reported = True
                    self.say(f"{role} (pid {p.pid}) exited with {p.returncode}")
        if self.stop:
            self.say("stopping (signal)")
        rc_sim = self.terminate("sim")
        self.terminate("fsw")
        self.terminate("viz")
        self._end_terminal()
        return self.summarize(rc_sim)

    def say_child(self, line: str) -> None:
        if self.progress is not None:
            self.progress.print(line)

    def _pump_terminal(self) -> None:
        if self.relay is not None:
            self.relay.pump()
        if self.progress is not None:
            t = ProgressFile.read(self.progress_path)
            if t is not None:
                self.progress.update(t)

    def _end_terminal(self) -> None:
        """The children's last lines, then the bar goes (the summary prints below it)."""
        self._pump_terminal()
        if self.relay is not None:
            self.relay.close()
            self.relay = None
        if self.progress is not None:
            self.progress.close()
        if getattr(self, "progress_path", None):
            Path(self.progress_path).unlink(missing_ok=True)

    def _console(self, key: str) -> None:
        """The ground console in the foreground; the run goes on until the user quits it."""
        from gse.cli import main as gse_main
        gse_main(["gse", "console", "--signing-key", key, "--tlog", str(self.out / "console.tlog")])

    def summarize(self, rc_sim) -> int:
        a = self.args
        try:
            sim_info = read_sim(self.out)
            fsw_info = read_fsw(self.out)
            h = merge(History.load(self.out / "sim_history.npz"), History.load(self.out / "fsw_history.npz"))
        except (OSError, ValueError, KeyError) as e:
            self.say(f"no complete records to summarize ({e}); see the logs")
            print(files_written(self.out))
            return EXIT_NOT_COMPLETED
        scn = prepare_args(a)
        seed = scn.seed if a.seed is None else a.seed
        faults = [tuple(x) for x in sim_info["faults_applied"]]
        from ellipsled.reference import fault_free_reference    # it flies twins: the FSW loads after the run
        ref = fault_free_reference(h, scn, seed, faults)
        summary = judge(h, scn, seed, sim_info["end_reason"], fsw_info, faults, fsw_info["params"], ref,
                        deploy=sim_info.get("deploy"))
        summary["mode"] = f"sil-{a.mode}"
        summary["wall_s"] = sim_info["wall_s"]
        summary["realtime_factor"] = sim_info["realtime_factor"]
        sil = {"mode": a.mode, "realtime_factor": sim_info["realtime_factor"], "wall_s": sim_info["wall_s"],
               "latency_p50_us": sim_info["latency_p50_us"], "latency_p99_us": sim_info["latency_p99_us"],
               "latency_max_us": sim_info["latency_max_us"], "latency_samples": sim_info["latency_samples"],
               "latency_split_us": sim_info.get("latency_split_us"),
               # the FSW's share of it: its frame's age when taken, and its control task
               "fsw_frame_age_p50_us": fsw_info.get("frame_age_p50_us"),
               "fsw_frame_age_p99_us": fsw_info.get("frame_age_p99_us"),
               "fsw_control_us": control_task_us(self.out) or (fsw_info.get("tasks_us") or {}).get("control"),
               "jitter_p50_us": fsw_info["jitter_p50_us"], "jitter_p99_us": fsw_info["jitter_p99_us"],
               "jitter_max_us": fsw_info["jitter_max_us"], "slips": fsw_info["cycle_slips"],
               # the slips the FSW's own work explains (fsw.executive.own_slips) among those recorded
               **own_slip_counts(fsw_info, scn.dt_control_s, sim_info.get("steps")),
               # releases later than 200 us by cause, the loop's own or the host's
               # (fsw.executive.explain_late_release; the records are in fsw.json)
               "late_releases": (fsw_info.get("executive") or {}).get("late_releases"),
               "sim_counts": sim_info["counts"], "sim_rejects": sim_info["rejects"],
               "fsw_sensor_rejects": fsw_info["sensor_rejects"], "end_reason": sim_info["end_reason"],
               "message": sim_info["message"], "rt": fsw_info.get("rt"), "sim_rt": sim_info.get("rt"),
               # each process's memory at the end of its flight (VmRSS resident, VmLck locked, VmHWM
               # peak), with how it was locked: compare with the same run under --no-rt (unlocked)
               "memory": {"fsw": _memory(fsw_info), "sim": _memory(sim_info)}}
        (self.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
        (self.out / "sil.json").write_text(json.dumps(sil, indent=2) + "\n")
        h.save(self.out / "history.npz")
        if not a.no_plots:
            from ellipsled.plots import plot_run
            plot_run(h, self.out, summary["scenario"])
        print(format_summary(summary))
        if a.mode == "realtime":
            f = lambda x: "n/a" if x is None else f"{x:.0f}"  # noqa: E731
            print(f"  real time: latency p50 {f(sil['latency_p50_us'])} us p99 {f(sil['latency_p99_us'])} us;"
                  f" release jitter p50 {f(sil['jitter_p50_us'])} us p99 {f(sil['jitter_p99_us'])} us"
                  f" max {f(sil['jitter_max_us'])} us; slips {sil['slips']}")
            mem = sil["memory"]
            print("  memory: " + "; ".join(
                f"{role} resident {m['vm_rss_kb'] / 1024:.0f} MB (peak {m['vm_hwm_kb'] / 1024:.0f}), "
                f"locked {(m['locked_kb'] or 0) / 1024:.0f} MB ({m['mlock_mode'] or 'not locked'})"
                for role, m in mem.items() if m))
        print(files_written(self.out))
        return exit_code(summary["end_reason"])


def own_slip_counts(fsw_info: dict, dt_s: float, plant_steps: int | None) -> dict:
    """{own_slips, slips_recorded}: of the cycle slips the FSW recorded (the first
    Executive.SLIP_RECORDS), those its own work explains (fsw.executive.own_slips: not the
    host's preemption, a late release or a late frame, nor after the plant's last step)."""
    from fsw.executive import own_slips
    recs = (fsw_info.get("executive") or {}).get("slip_records") or []
    last_k = plant_steps - 1 if plant_steps else None
    return {"own_slips": len(own_slips(recs, dt_s * 1e6, last_k)), "slips_recorded": len(recs)}


def _memory(info: dict) -> dict | None:
    """A node report's memory figures (rt.memory_status) with its locking mode."""
    mem = info.get("memory")
    if mem is None:
        return None
    rt_rep = info.get("rt") or {}
    return {**mem, "mlock_mode": rt_rep.get("mlock_mode")}


def main(args) -> int:
    return Launcher(args).run()
