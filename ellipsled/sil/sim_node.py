"""``ellipsled sim``: the plant process.

Lockstep: publish the sensor frame of step k, wait for the jet command that answers k,
integrate [t_k, t_k+1). If the FSW stops answering, end the run after --fsw-timeout with a
clear message. Real time: step k is released at t0 + k·period/speed on the monotonic
clock; the newest jet command received by the deadline is applied and its latency
recorded; with no fresh command for --miss-periods periods the jets are held off.
Fault injections arrive on sim/faults and are applied at the next step boundary.
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from common import argtypes, rt
from common.rt import sleep_until_ns
from interfaces import records, transport
from interfaces.codec import Codec, SequenceGuard
from interfaces.vocabulary import FAULT_KINDS
from sim.plant import Plant

from .common import DecodeRehearsal, Stop, add_common_arguments, apply_rt, now_ns, open_node, rt_in_force, say
from .history import History, record_truth
from .progress import ProgressFile
from .variant import end_reason_of, prepare_args

ROLE = "sim"


def add_arguments(p) -> None:
    add_common_arguments(p)
    p.add_argument("--speed", type=argtypes.speed, default=1.0, help="real time: simulated seconds per wall second")
    p.add_argument("--fsw-timeout", type=argtypes.timeout_s, default=10.0,
                   help="lockstep: end the run when the FSW has not answered for this long [s]")
    p.add_argument("--wait-peers", type=argtypes.timeout_s, default=30.0, help="how long to wait for the FSW at start [s]")
    p.add_argument("--resend-s", type=argtypes.timeout_s, default=0.5,
                   help="lockstep: publish the sensor frame again after this long without its answer (the "
                        "frame or the answer was lost, e.g. while a router restarts) [s]")
    p.add_argument("--wait-bridge", action="store_true", help="also wait for the Rerun bridge before step 0")
    p.add_argument("--miss-periods", type=argtypes.int_range(1, 1000), default=3,
                   help="real time: hold jets off after this many periods without a fresh command")
    p.add_argument("--rehearse", action=argparse.BooleanOptionalAction, default=True,
                   help="real time: while the command is on its way, run its decode once on a scratch "
                        "copy of the last one, so that it is warm when the command comes")
    p.add_argument("--progress-file", default=None, metavar="PATH",
                   help="keep the simulated time reached in this file (ellipsled run's progress bar)")


def command_refusal(rec, k: int) -> str | None:
    """Why the plant at step ``k`` refuses a decoded jet command it cannot have been sent: an
    answer to a step it has not published yet (one far ahead would make every genuine answer
    look stale), a negative step, or a valve state other than 0 (closed) or 1 (open). None
    when the command may fly."""
    kc = int(rec["k"])
    if kc > k:
        return "future_step"
    if kc < 0:
        return "negative_step"
    if int(rec["u"].max()) > 1:
        return "u_range"
    if int(rec["deploy"]) > 1:
        return "deploy_range"
    return None


class SimNode:
    def __init__(self, args):
        self.args = args
        self.stop = Stop()
        self.rt_report = apply_rt(ROLE, args)   # before the Zenoh session opens
        self.scn = prepare_args(args)
        self.seed = self.scn.seed if args.seed is None else args.seed
        self.plant = Plant(self.scn, self.seed)
        self.session, self.K = open_node(ROLE, args, self.rt_report)
        # with SCHED_FIFO Zenoh's threads run one priority above this loop: spin-wait for the
        # command (a few hundred us a period) instead of 20-us sleeps
        self.spin_s = 0.003 if rt_in_force(self.rt_report) else 0.0
        # real time: a frozen FSW or viewer must never stall the plant's clock (samples dropped
        # when the peer cannot take them); lockstep: loss-free, the run waits
        rt_drop = args.mode == "realtime"
        self.pub_sensors = transport.publisher(self.session, self.K.sensors, drop=rt_drop)
        self.pub_truth = transport.publisher(self.session, self.K.truth, drop=rt_drop)
        self.sub_jets = transport.subscriber(self.session, self.K.jets, newest_only=args.mode == "realtime")
        self.sub_faults = transport.subscriber(self.session, self.K.faults)
        # the fault log, for an FSW in oracle identification (a test mode); loss-free in both modes
        self.pub_fault_log = transport.publisher(self.session, self.K.fault_log)
        self.enc_fault_log = Codec.for_schema("FAULT_APPLIED")
        self.fault_applied = records.new(records.FAULT_APPLIED)
        self.faults_published = 0
        self.token = transport.declare_alive(self.session, self.K, ROLE)
        self.enc_sensors = Codec.for_schema("SENSORS")
        self.enc_truth = Codec.for_schema("TRUTH")
        # the FSW owns the jets key; another publisher takes over only after 1 s of silence
        self.dec_jets = Codec.for_schema("JETS", guard=SequenceGuard(takeover_after_s=1.0), on_reject=self._rejected)
        self.dec_faults = Codec.for_schema("FAULT", on_reject=self._rejected)
        self._warm_command = DecodeRehearsal("JETS", copy=False)    # real time, while the command is on its way
        self.truth_rec = records.new(records.TRUTH)
        self.u = np.zeros(records.N_JETS, dtype=np.uint8)
        self.u_k = -1                  # JETS.k of the command held (-1: none, jets off)
        self.history = History(int(math.ceil(self.scn.max_duration_s / self.scn.dt_control_s)) + 2)
        self.sensor_seq = 0     # per publication: a frame sent again is a new sample, not a replay
        # real time: a step without its command by the deadline is missed once the FSW has
        # answered once; before that (the FSW phase-locks its clock on the first frames of the
        # running plant, ellipsled/sil/fsw_node.py) it is unanswered at start; a step the plant
        # itself reached past its deadline (the host held it: no wait for the command at all)
        # is missed_plant_late, not the flight software's miss
        self.counts = {"stale_commands": 0, "late_commands": 0, "missed_commands": 0, "missed_plant_late": 0,
                       "unanswered_at_start": 0,
                       "fault_rejected": 0, "resent_frames": 0, "warmup_frames": 0,
                       "faults_applied": 0}
        self.rejects: dict[str, int] = {}
        # one latency per step at most: preallocated, nothing grows during the run
        self.latency_ns = np.zeros(len(self.history.a["k"]), dtype=np.int64)
        # the command leg of each latency sample: FSW publication -> plant has it (one host's
        # monotonic clock: meaningful only when both processes share the machine)
        self.latency_cmd_ns = np.zeros_like(self.latency_ns)
        self.n_latency = 0
        self.end_reason = ""
        self.message = ""
        self.progress = ProgressFile(args.progress_file) if args.progress_file else None

    def _rejected(self, reason: str, detail: str) -> None:
        self.rejects[reason] = self.rejects.get(reason, 0) + 1
        if self.rejects[reason] in (1, 10, 100, 1000):
            say(ROLE, f"rejected payload ({reason}): {detail} [{self.rejects[reason]} so far]")

    def _refused(self, rec, k: int) -> bool:
        """A decoded jet command the plant at step k refuses (``command_refusal``): counted
        in ``rejects`` with the decoder's refusals, never flown."""
        why = command_refusal(rec, k)
        if why is not None:
            self._rejected(why, f"JETS k={int(rec['k'])} u max {int(rec['u'].max())} at plant step {k}")
        return why is not None

    # ------------------------------------------------------------------ faults
    def apply_faults(self) -> None:
        while True:
            s = self.sub_faults.try_recv()
            if s is None:
                return
            rec = self.dec_faults.decode(s.payload.to_bytes())
            if rec is None:
                continue
            jet, eta = int(rec["jet"]), float(rec["eta"])
            kind = records.FAULT_NAMES.get(int(rec["kind"]))
            try:
                if kind is None:
                    raise ValueError(f"unknown fault kind code {int(rec['kind'])}")
                if kind != "degraded":
                    eta = 1.0
                self.plant.set_fault(jet, kind, eta)
            except ValueError as e:
                self.counts["fault_rejected"] += 1
                say(ROLE, f"fault request refused: {e}")
                continue
            self.counts["faults_applied"] += 1
            say(ROLE, f"t={self.plant.t_s:.2f}s fault applied: jet {jet or 'all'} {kind}"
                      + (f" eta={eta:g}" if kind == "degraded" else ""))

    def publish_fault_log(self) -> None:
        """Every fault the plant applied since the last call, before the frame of the step it
        acts from (the same session and link: it reaches the FSW first)."""
        log = self.plant.fault_log
        f = self.fault_applied
        while self.faults_published < len(log):
            t, jet, kind = log[self.faults_published]
            f["k"], f["t_ns"] = self.plant.k, int(round(t * 1e9))
            f["jet"], f["kind"], f["eta"] = jet, FAULT_KINDS[kind], float(self.plant.fault_eta[jet - 1])
            self.pub_fault_log.put(self.enc_fault_log.encode(f, self.faults_published, now_ns()))
            self.faults_published += 1

    # ------------------------------------------------------------------ I/O
    def publish_sensors(self) -> int:
        t = now_ns()
        self.pub_sensors.put(self.enc_sensors.encode(self.plant.sensors, self.sensor_seq, t))
        self.sensor_seq += 1
        return t

    def record_and_publish_truth(self) -> None:
        self.plant.fill_truth(self.truth_rec)
        record_truth(self.history, self.history.row(), self.truth_rec)
        self.pub_truth.put(self.enc_truth.encode(self.truth_rec, self.plant.k, now_ns()))

    def finish_step(self) -> bool:
        """Record and publish the truth of step k; then either end the run (True) or
        integrate [t_k, t_k+1) with the command now held."""
        self.record_and_publish_truth()
        if self.progress is not None:
            self.progress.write(self.plant.t_s)
        done, reason = self.plant.done()
        if done:
            self.end_reason = reason
            return True
        self.plant.step(self.u, u_k=self.u_k)
        return False

    def _take_command(self, rec) -> int:
        self.u[:] = rec["u"]
        self.u_k = int(rec["k"])
        if self.plant.deploy_box is not None:
            self.plant.command_deploy(int(rec["deploy"]))
        return self.u_k

    # ------------------------------------------------------------------ lockstep
    def wait_command(self, k: int) -> bool:
        """Lockstep: block (interruptibly) until the command answering k arrives; the frame
        is published again every --resend-s meanwhile (the FSW answers a frame it has
        already flown with the same command, so nothing is computed twice)."""
        t_last = t_sent = time.monotonic()
        while not self.stop:
            s = transport.recv(self.sub_jets, 0.05)
            if s is None:
                now = time.monotonic()
                if now - t_sent >= self.args.resend_s:
                    self.publish_sensors()
                    self.counts["resent_frames"] += 1
                    t_sent = now
                if now - t_last > self.args.fsw_timeout:
                    self.end_reason = "fsw_timeout"
                    self.message = (f"the FSW has not answered sensor frame k={k} (t={self.plant.t_s:.2f} s) "
                                    f"for {self.args.fsw_timeout:g} s: ending the run")
                    return False
                continue
            rec = self.dec_jets.decode(s.payload.to_bytes())
            if rec is None or self._refused(rec, k):
                continue
            kc = int(rec["k"])
            if kc == k:
                self._take_command(rec)
                return True
            self.counts["stale_commands"] += 1    # an answer to an older frame (or a replay)
        self.end_reason = "stopped"
        return False

    def run_lockstep(self) -> None:
        while not self.stop:
            self.apply_faults()
            self.publish_fault_log()
            self.publish_sensors()
            if not self.wait_command(self.plant.k):
                return
            if self.finish_step():
                return
        self.end_reason = self.end_reason or "stopped"

    # ------------------------------------------------------------------ real time
    def run_realtime(self) -> None:
        period = int(round(self.scn.dt_control_s * 1e9 / self.args.speed))
        margin = min(2_000_000, period // 4)
        t0 = now_ns() + 50_000_000
        last_cmd_k = -10**9
        holding = False
        while not self.stop:
            k = self.plant.k
            release = t0 + k * period
            sleep_until_ns(release)
            if now_ns() > release + period:      # fell a whole period behind: re-phase, count it
                self.counts["late_commands"] += 1
            self.apply_faults()
            self.publish_fault_log()
            t_pub = self.publish_sensors()
            if self.args.rehearse:
                self._warm_command.run()   # its decode warm when the command comes (DecodeRehearsal)
            deadline = release + period - margin
            got = False
            waited = now_ns() < deadline          # False: the plant came past its own deadline
            while now_ns() < deadline and not self.stop:
                s = transport.recv(self.sub_jets, max(0.0, (deadline - now_ns()) * 1e-9), poll_s=20e-6,
                                   spin_s=self.spin_s)
                if s is None:
                    break
                raw = s.payload.to_bytes()
                rec = self.dec_jets.decode(raw)
                if rec is None or self._refused(rec, k):
                    continue
                self._warm_command.last = raw
                kc = int(rec["k"])
                if kc < last_cmd_k:
                    self.counts["stale_commands"] += 1
                    continue
                if last_cmd_k < 0:
                    say(ROLE, f"t={self.plant.t_s:.2f}s first jet command")
                last_cmd_k = self._take_command(rec)
                if kc == k:
                    if self.n_latency < len(self.latency_ns):
                        t_now = now_ns()
                        self.latency_ns[self.n_latency] = t_now - t_pub
                        self.latency_cmd_ns[self.n_latency] = t_now - int(rec["t_publish_ns"])
                        self.n_latency += 1
                    got = True
                    break
            if not got:
                self.counts["unanswered_at_start" if last_cmd_k < 0
                            else "missed_commands" if waited else "missed_plant_late"] += 1
            if k - last_cmd_k >= self.args.miss_periods:
                self.u[:] = 0
                self.u_k = -1
                if not holding and last_cmd_k >= 0:
                    holding = True
                    say(ROLE, f"t={self.plant.t_s:.2f}s no jet command for {k - last_cmd_k} periods: jets held off")
            elif holding:
                holding = False
                say(ROLE, f"t={self.plant.t_s:.2f}s jet commands back: resuming")
            if self.finish_step():
                return
        self.end_reason = self.end_reason or "stopped"

    def _await_ready(self) -> None:
        """Real time: the clock starts when the FSW has warmed up (its ``ready`` token), not
        before — the warm-up runs on a sensor frame, so frame k=0 is offered every 20 ms
        meanwhile (counted: warmup_frames): an FSW warming up on the frames of a plant already
        flying would miss the first commands' deadlines. An FSW that never says ready costs
        wait_peers, then the run starts anyway, said in the log."""
        def offer() -> None:
            self.publish_sensors()
            self.counts["warmup_frames"] += 1
        if not transport.wait_for_alive(self.session, self.K.ready_fsw, self.args.wait_peers, every=offer):
            say(ROLE, f"the FSW has not said it is ready within {self.args.wait_peers:g} s: starting anyway")

    # ------------------------------------------------------------------ main
    def run(self) -> int:
        a = self.args
        say(ROLE, f"{self.scn.name} seed {self.seed}, {a.mode}; waiting for the FSW")
        if not (transport.wait_for_alive(self.session, self.K.alive_fsw, a.wait_peers)
                and transport.wait_for_subscriber(self.pub_sensors, a.wait_peers)
                and (not a.wait_bridge or (transport.wait_for_alive(self.session, self.K.alive_bridge, a.wait_peers)
                                           and transport.wait_for_subscriber(self.pub_truth, a.wait_peers)))):
            self.end_reason = "no_fsw"
            self.message = f"no FSW{' or bridge' if a.wait_bridge else ''} joined within {a.wait_peers:g} s"
        else:
            if a.mode == "realtime":
                self._await_ready()
            if a.mode == "realtime":    # the arrays the loop fills: no first-touch page fault in flight
                rt.prefault(self.history.truth_rows, self.latency_ns, self.latency_cmd_ns)
            wall0 = time.perf_counter()
            (self.run_realtime if a.mode == "realtime" else self.run_lockstep)()
            self.wall_s = time.perf_counter() - wall0
            self.memory = rt.memory_status()    # at the end of the flight, before writing the records
        if self.message:
            say(ROLE, self.message)
        self.write()
        say(ROLE, f"end: {end_reason_of(self.end_reason, self.args.duration)} at t={self.plant.t_s:.2f} s")
        return 0 if self.end_reason in ("mach", "speed", "deploy", "box_edge", "altitude", "timeout") else 3

    def write(self) -> None:
        if not self.args.out:
            return
        out = Path(self.args.out)
        out.mkdir(parents=True, exist_ok=True)
        self.history.save(out / "sim_history.npz")
        # every sensor-to-actuator latency and its command leg, raw (ellipsled/node_reports.py sums them up)
        np.savez_compressed(out / "sim_latency.npz", latency_ns=self.latency_ns[: self.n_latency],
                            latency_cmd_ns=self.latency_cmd_ns[: self.n_latency])
        info = {
            "scenario": self.scn.name, "seed": self.seed, "mode": self.args.mode,
            "end_reason": end_reason_of(self.end_reason, self.args.duration), "message": self.message,
            "t_end_s": self.plant.t_s, "steps": self.history.n, "wall_s": getattr(self, "wall_s", None),
            "faults_applied": self.plant.fault_log, "deploy": self.plant.deploy_report(), "counts": self.counts,
            "rejects": self.rejects, "rt": self.rt_report, "memory": getattr(self, "memory", None),
        }
        (out / "sim.json").write_text(json.dumps(info, indent=2) + "\n")

    def close(self) -> None:
        if self.progress is not None:
            self.progress.write(self.plant.t_s, force=True)
            self.progress.close()
        transport.close(self.token, self.sub_jets, self.sub_faults, self.pub_sensors, self.pub_truth,
                        self.pub_fault_log, self.session)


def main(args) -> int:
    node = SimNode(args)
    try:
        return node.run()
    finally:
        node.close()
