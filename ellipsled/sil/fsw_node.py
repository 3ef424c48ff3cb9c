"""``ellipsled fsw``: the flight-software process.

The same FlightSoftware and Topology (rate groups) as the batch runner. Lockstep: each
sensor frame that arrives is a tick. Real time: releases at absolute times on the
monotonic clock, phase-locked to the plant's schedule (the earliest of its first publications
once it runs, plus --rt-offset-us): tick k is step k, and each release takes the newest
sensor frame (waiting up to --frame-wait-us for step k's).
Out: the jet command (fsw/jets), the FSW state for viewers (fsw/state), events
(fsw/events), ground injections forwarded to the plant (sim/faults), and the MAVLink
ground link when a signing key is given.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import resource
import time
from pathlib import Path

from common import rt

import numpy as np  # noqa: E402   (threads pinned by ellipsled.cli before any import)

from common import argtypes  # noqa: E402
from common.events import EventLog, Severity  # noqa: E402
from fsw.executive import LockstepClock, RealTimeClock  # noqa: E402
from fsw.flightsoftware import FlightSoftware  # noqa: E402
from fsw.topology import Topology  # noqa: E402
from interfaces import records, transport  # noqa: E402
from interfaces.codec import Codec, SequenceGuard, event_record  # noqa: E402
from interfaces.vocabulary import DEFAULT_GCS, DEFAULT_VEHICLE, FAULT_KINDS, HEALTH_NAMES, NOMINAL  # noqa: E402

from .common import DecodeRehearsal, Stop, add_common_arguments, apply_rt, now_ns, open_node, rt_in_force, say  # noqa: E402
from .frame_timing import PhaseLock, due_step, take_due_frame  # noqa: E402
from .fsw_report import alloc_sample, fsw_report  # noqa: E402
from .history import History, record_fsw  # noqa: E402
from .variant import prepare_args  # noqa: E402

ROLE = "fsw"
RUSAGE_THREAD = getattr(resource, "RUSAGE_THREAD", resource.RUSAGE_SELF)     # Linux: this thread's own


def add_arguments(p) -> None:
    add_common_arguments(p)
    p.add_argument("--rt-offset-us", type=argtypes.offset_us, default=-100.0,
                   help="real time: release this long after the plant publishes a step (negative: "
                        "before; the input task then waits for the frame, whose arrival, handled by "
                        "Zenoh's threads one priority up, cannot delay the release)")
    p.add_argument("--frame-wait-us", type=argtypes.wait_us, default=3000.0,
                   help="real time: at a release, wait this long at most for the frame due")
    p.add_argument("--rehearse", action=argparse.BooleanOptionalAction, default=True,
                   help="real time: rehearse before each release -- a spare flight software runs the "
                        "control cycle on the last frame (executive.rehearse_us before it), the "
                        "frame's decode and the answer's encode run once on scratch copies at it, and "
                        "(with --rt) the flying FSW's own kernels between the polls for the frame -- "
                        "so that they are warm when the frame comes; --no-rehearse: none of them")
    p.add_argument("--gcs", default=DEFAULT_GCS, help="ground station address (MAVLink)")
    p.add_argument("--mavlink-bind", default=DEFAULT_VEHICLE, help="the vehicle's MAVLink address")
    p.add_argument("--signing-key", default=None,
                   help="MAVLink signing key file (or $ELLIPSLED_SIGNING_KEY_FILE); no key = no ground link")
    p.add_argument("--wait-peers", type=argtypes.timeout_s, default=30.0)
    p.add_argument("--plant-gone-s", type=argtypes.timeout_s, default=15.0,
                   help="leave when the plant's liveliness has been gone this long (a restarted plant "
                        "that is back sooner is flown on) [s]")


class FswNode:
    def __init__(self, args):
        self.args = args
        self.stop = Stop()
        self.rt_report = apply_rt(ROLE, args)   # before the Zenoh session opens
        self.scn = prepare_args(args)
        self.events = EventLog()
        # --no-rehearse: no rehearsal at either layer (the executive's control cycle before
        # the release, this shell's receiving path at it)
        self.fsw = FlightSoftware(self.scn, self.events, realtime=args.mode == "realtime",
                                  param_overrides=None if args.rehearse else {"executive.rehearse_us": 0.0})
        self.session, self.K = open_node(ROLE, args, self.rt_report)
        self.spin = rt_in_force(self.rt_report)
        self.sub_sensors = transport.subscriber(self.session, self.K.sensors,
                                                newest_only=args.mode == "realtime")
        # real time: a frozen plant or viewer must never stall the loop (samples dropped when
        # the peer cannot take them); lockstep: loss-free, the run waits
        rt_drop = args.mode == "realtime"
        self.pub_jets = transport.publisher(self.session, self.K.jets, drop=rt_drop)
        self.pub_state = transport.publisher(self.session, self.K.state, express=False, drop=rt_drop)
        self.pub_events = transport.publisher(self.session, self.K.events, express=False, drop=rt_drop)
        self.pub_faults = transport.publisher(self.session, self.K.faults)
        # oracle identification (a test mode): the plant's fault log is FDIR's identification
        self.sub_fault_log = transport.subscriber(self.session, self.K.fault_log) if self.fsw.fdir.oracle else None
        self.dec_fault_log = Codec.for_schema("FAULT_APPLIED", on_reject=self._rejected)
        self.token = transport.declare_alive(self.session, self.K, ROLE)
        self.plant_presence = transport.Presence(self.session, self.K.alive_sim)
        self.ready = None       # real time: a second token once warmed up (the plant starts on it)
        # a restarted plant takes over the sensor key after 1 s of silence, not before
        self.dec_sensors = Codec.for_schema("SENSORS", guard=SequenceGuard(takeover_after_s=1.0),
                                            on_reject=self._rejected)
        self.enc_jets = Codec.for_schema("JETS")
        self.enc_state = Codec.for_schema("FSW_STATE")
        self.enc_events = Codec.for_schema("EVENT")
        self.enc_faults = Codec.for_schema("FAULT")
        self.frame = records.new(records.SENSORS)        # our own copy of the newest frame
        # real time: the frame's decode and the answer's encode rehearsed before each frame (_rehearse)
        self._warm_frame = DecodeRehearsal("SENSORS", copy=True)
        self._warm_enc = Codec.for_schema("JETS")
        self.jets = records.new(records.JETS)
        self.fault = records.new(records.FAULT)
        self.history = History(int(math.ceil(self.scn.max_duration_s / self.scn.dt_control_s)) + 2)
        self.samples: list[dict] = []
        self.events_sent = 0
        self.fault_seq = 0
        self.source_id = None
        self.jets_seq = 0       # per publication: an answer sent again is a new sample, not a replay
        self.answered_k = -1    # the step of the last jet command published
        self.answers_repeated = 0
        self.last_frame_wall = 0.0
        self.next_k = 0
        self.lock_source = None     # the plant whose steps the real-time ticks are locked to
        self.jitter_ns = np.zeros(len(self.history.a["k"]), dtype=np.int64)   # every tick, whole run
        # every tick's control task time (-1: not run), whole run: the executive's statistics
        # keep only its recent cycles, and the latency it is a share of covers the whole run
        self.control_ns = np.full(len(self.history.a["k"]), -1, dtype=np.int64)
        # every tick: its control cycle flew the duty-cycle LP's answer (a HiGHS solve: the
        # control task's dearest cycles, all near the entry's start in the nominal flight)
        self.lp_cycle = np.zeros(len(self.history.a["k"]), dtype=bool)
        # real time: how long after the plant published it each frame reached this loop
        self.frame_age_ns = np.zeros(len(self.history.a["k"]), dtype=np.int64)
        self.n_frames = 0
        self.ticks = 0
        self._taken_wall_ns, self._taken_ru = 0, None     # real time: when the input task took its frame
        self._input_wall_ns, self._input_ru = 0, None     # ... and when it began
        clock = LockstepClock() if args.mode == "lockstep" else RealTimeClock(
            int(round(self.scn.dt_control_s * 1e9)), spin_ns=int(self.fsw.params["executive.spin_us"] * 1e3))
        # lockstep: the frame comes with each tick; real time: the input task fetches the newest
        self.topo = Topology(self.fsw, clock,
                             frame_source=self._newest_frame if args.mode == "realtime" else None)
        self.topo.add(1, "publish", self._publish)
        self._control_col = self.topo.executive._names.index("control")   # its column in the statistics
        self.topo.add(2, "events", self._publish_events)
        self.link = self._ground_link()
        if self.link is not None:
            # real time: the link's receiving stops short of the cycle's deadline (lockstep
            # keeps only the link's own budget: its cycles have no wall-clock deadline)
            ex, realtime = self.topo.executive, args.mode == "realtime"
            rg2 = ex.divisors[1]
            # the cycles between the link's ticks it listens (GroundLink.listen): the socket
            # is read every control period, after the command is out
            self.topo.add(1, "groundlink_rx", lambda c: c.k % rg2 and self.link.listen(
                c.t_release_ns + ex.deadline_ns if realtime else None))
            self.topo.add(2, "groundlink", lambda c: self.link.tick(
                self.frame, c.t_release_ns + ex.deadline_ns if realtime else None))

    # ------------------------------------------------------------------ inputs
    def _rejected(self, reason: str, detail: str) -> None:
        from interfaces.event_catalogue import BY_NAME     # (not at the top: see the module's imports)
        self.events.emit(self.fsw.t_s, BY_NAME[f"rx_{reason}"])

    def _accept(self, sample) -> bool:
        """Decode a sensor sample into our frame copy; note a new plant (restart)."""
        raw = sample.payload.to_bytes()
        rec = self.dec_sensors.decode(raw, out=self.frame)
        if rec is None:
            return False
        self._warm_frame.last = raw
        pid = self.dec_sensors.last_publisher_id
        if self.source_id is not None and pid != self.source_id:
            self.fsw.monitor.restart_sequence()
            from interfaces.event_catalogue import EV
            self.events.emit(self.fsw.t_s, EV.NEW_SENSOR_SOURCE)
        self.source_id = pid
        self.last_frame_wall = time.monotonic()
        if self.n_frames < len(self.frame_age_ns):
            self.frame_age_ns[self.n_frames] = now_ns() - self.dec_sensors.last_t_pub_ns
            self.n_frames += 1
        return True

    def _take_fault_log(self) -> None:
        """Oracle mode: hand FDIR every fault-log entry that has arrived, each at its fault time."""
        while True:
            s = self.sub_fault_log.try_recv()
            if s is None:
                return
            rec = self.dec_fault_log.decode(s.payload.to_bytes())
            if rec is None:
                continue
            kind = records.FAULT_NAMES.get(int(rec["kind"]), HEALTH_NAMES[NOMINAL])     # a fault kind is a health word
            try:
                self.fsw.fdir.identified(int(rec["t_ns"]) * 1e-9, int(rec["jet"]), kind, float(rec["eta"]))
            except ValueError as e:      # a bad record is refused, never passed on
                self._rejected("fault_log", str(e))

    def _fetch_frame(self) -> int | None:
        """The step of the newest sensor frame that decodes, or None: the samples waiting are
        judged newest first, so garbage published after a genuine frame cannot hide it."""
        for s in reversed(transport.drain(self.sub_sensors)):
            if self._accept(s):
                return int(self.frame["k"])
        return None

    def _running(self) -> bool:
        """Neither stopped (signal) nor left alone: a plant whose liveliness has been gone for
        --plant-gone-s is not coming back, and an FSW without one must not linger holding its
        ground link."""
        if self.stop:
            return False
        gone_s = self.plant_presence.gone_for_s()
        if gone_s < self.args.plant_gone_s:
            return True
        say(ROLE, f"the plant has been gone for {gone_s:.1f} s: leaving")
        self.stop.requested = True
        return False

    def _pause(self) -> None:
        """Between two polls for the frame due. With --rt the wait spins (Zenoh's threads, one
        priority up, preempt it) and the flying FSW rehearses its own kernels meanwhile: the wait
        and the transport's work cool what the rehearsal before the release warmed (control task
        p50 60.3 -> 48.2 us, p99 without the duty-cycle LP's cycles 106 -> 78 us, six alternated
        10-s runs: docs/changelog.md). Without --rt it sleeps, leaving the CPU to those threads."""
        if self.spin:
            self.topo.rehearse_waiting()
        else:
            time.sleep(20e-6)

    def _rehearse(self) -> None:
        """Real time, at the release, before the frame due comes: the path the frame takes in
        (its decode) and the answer takes out (the JETS encode) run once on scratch copies,
        so that what they need is in the caches when the frame comes: idle for a period, with
        other work in between, those paths run an order of magnitude slower (docs/changelog.md);
        the wait for the frame is spent spinning anyway. Guard-less scratch codecs: nothing
        counted, nothing kept."""
        self._warm_frame.run()
        self._warm_enc.encode_view(self.jets, 0, 0)

    def _newest_frame(self):
        """Real time: the newest fresh frame (waiting briefly for the one due), or None."""
        self._input_wall_ns, self._input_ru = now_ns(), resource.getrusage(RUSAGE_THREAD)
        if self.args.rehearse:
            self._rehearse()
        due = due_step(self.next_k, self.topo.executive.cycle.k, self.source_id == self.lock_source)
        k = take_due_frame(self._fetch_frame, due, now_ns() + int(self.args.frame_wait_us * 1e3), now_ns,
                           self._pause)
        # the rest of the cycle from here: wall time and the thread's resource use, so that a
        # cycle slip can say how long the thread was off its CPU (fsw.executive.own_slips)
        self._taken_wall_ns, self._taken_ru = now_ns(), resource.getrusage(RUSAGE_THREAD)
        if k is None:
            return None
        self.next_k = k + 1
        return self.frame

    # ------------------------------------------------------------------ outputs
    def _publish(self, cyc) -> None:
        fsw, topo = self.fsw, self.topo
        if not topo.got_frame:
            return
        j = self.jets
        j["k"] = fsw.k
        j["t_release_ns"] = cyc.t_release_ns
        j["u"] = topo.u
        j["deploy"] = fsw.deploy.command if fsw.deploy is not None else 0
        t = now_ns()
        j["t_publish_ns"] = t
        self.pub_jets.put(self.enc_jets.encode(j, self.jets_seq, t))
        self.jets_seq += 1
        self.answered_k = fsw.k
        # the FSW's output record as it is (the rate-group driver has stamped this cycle's
        # release, jitter and slips; its compute time is the last finished cycle's)
        self.pub_state.put(self.enc_state.encode(fsw.output, fsw.k, t))

    def _publish_events(self, cyc) -> None:
        first, new = self.events.since(self.events_sent)
        for seq, e in enumerate(new, first):
            rec = event_record(int(round(e.t_s * 1e9)), int(e.severity), e.source, e.code, e.text)
            self.pub_events.put(self.enc_events.encode(rec, seq, now_ns()))
        self.events_sent = first + len(new)

    def inject(self, jet: int, kind: str, eta: float) -> bool:
        """Ground fault injection: forwarded to the plant. ValueError when the plant could
        not apply it; False when no plant is there to take it."""
        records.check_fault_request(jet, kind, eta)
        if time.monotonic() - self.last_frame_wall > 1.0:
            return False
        f = self.fault
        f["jet"], f["kind"], f["eta"] = jet, FAULT_KINDS[kind], eta
        f["t_apply_ns"], f["request_id"] = 0, self.fault_seq
        self.pub_faults.put(self.enc_faults.encode(f, self.fault_seq, now_ns()))
        self.fault_seq += 1
        return True

    def _ground_link(self):
        path = self.args.signing_key or os.environ.get("ELLIPSLED_SIGNING_KEY_FILE")
        if not path:
            say(ROLE, "no signing key (--signing-key or ELLIPSLED_SIGNING_KEY_FILE): MAVLink ground link off")
            return None
        from fsw.groundlink import GroundLink
        from interfaces.event_catalogue import EV
        from interfaces.mavlink.signing.keys import SigningKey
        key = SigningKey.from_file(path)
        try:
            gl = GroundLink(self.fsw, key, gcs=self.args.gcs, bind=self.args.mavlink_bind, inject=self.inject)
        except OSError as e:   # e.g. the port is taken by another run: fly on without a ground link
            say(ROLE, f"MAVLink ground link off: cannot bind {self.args.mavlink_bind}: {e}")
            self.events.emit(0.0, EV.MAVLINK_BIND)
            return None
        say(ROLE, f"MAVLink ground link on {self.args.mavlink_bind}, ground station {self.args.gcs}")
        return gl

    # ------------------------------------------------------------------ loops
    def _record(self) -> None:
        cyc = self.topo.executive.cycle
        ex = self.topo.executive
        if (self.args.mode == "realtime" and ex.slip_records and ex.slip_records[-1]["k"] == cyc.k
                and "off_cpu_us" not in ex.slip_records[-1]):
            # the time the thread was off its CPU since it took the frame (preempted: the
            # host's or a higher-priority thread's time, not this cycle's work), and what it
            # spent on its CPU in the kernel, page faults and involuntary switches meanwhile
            wall, ru0, ru = now_ns() - self._taken_wall_ns, self._taken_ru, resource.getrusage(RUSAGE_THREAD)
            ex.slip_records[-1].update(
                off_cpu_us=_off_cpu_us(wall, ru0, ru), sys_us=(ru.ru_stime - ru0.ru_stime) * 1e6,
                minor_faults=ru.ru_minflt - ru0.ru_minflt, major_faults=ru.ru_majflt - ru0.ru_majflt,
                involuntary_switches=ru.ru_nivcsw - ru0.ru_nivcsw,
                # the same over the input task (its wait for the frame): off its CPU there too?
                input_off_cpu_us=_off_cpu_us(self._taken_wall_ns - self._input_wall_ns, self._input_ru, ru0))
        if self.ticks >= len(self.jitter_ns):
            self.jitter_ns = np.concatenate((self.jitter_ns, np.zeros_like(self.jitter_ns)))
            self.control_ns = np.concatenate((self.control_ns, np.full_like(self.control_ns, -1)))
            self.lp_cycle = np.concatenate((self.lp_cycle, np.zeros_like(self.lp_cycle)))
        self.jitter_ns[self.ticks] = cyc.t_start_ns - cyc.t_release_ns
        st = ex.stats
        if st is not None and st.n:
            self.control_ns[self.ticks] = st.task_ns[(st.n - 1) % st.capacity, self._control_col]
        self.lp_cycle[self.ticks] = self.topo.got_frame and self.fsw.dutycycle.modulated
        self.ticks += 1
        if not self.topo.got_frame:
            return
        record_fsw(self.history, self.history.row(), self.fsw.output)
        if self.fsw.k % 1000 == 0:
            self.samples.append(alloc_sample(self.fsw))

    def _warm_up(self) -> None:
        """Before the first cycle: every kernel loaded (topology) and every ground-link
        message type encoded once (first encodes cost milliseconds)."""
        spare = self.topo.warm_up(self.frame)
        if self.link is not None:
            self.link.warm_up(spare, self.frame)

    def run_lockstep(self) -> None:
        warm = False
        while self._running():
            s = transport.recv(self.sub_sensors, 0.1)
            source = self.source_id
            if s is None or not self._accept(s):
                continue
            if source == self.source_id and int(self.frame["k"]) <= self.answered_k:
                self._answer_again()
                continue
            if not warm:
                self._warm_up()
                warm = True
            if self.sub_fault_log is not None:
                self._take_fault_log()
            self.topo.tick(self.frame)
            self._record()

    def _answer_again(self) -> None:
        """Lockstep: the plant sent a frame already flown again (it, or our answer, was lost
        on the way): the same command once more; the flight software does not run twice."""
        self.pub_jets.put(self.enc_jets.encode(self.jets, self.jets_seq, now_ns()))
        self.jets_seq += 1
        self.answers_repeated += 1

    def _next_good_frame(self) -> int | None:
        """Wait (interruptibly) for the next frame that decodes; its step, or None on stop."""
        while self._running():
            s = transport.recv(self.sub_sensors, 0.1)
            if s is not None and self._accept(s):
                return int(self.frame["k"])
        return None

    LOCK_FRAMES = 10        # real time: frames the phase lock takes the plant's schedule from
    LOCK_WAIT_S = 2.0       # ... waiting at most this long (wall time) for them to keep one schedule

    def run_realtime(self) -> None:
        # warm up on the plant's first frame (it offers that frame until we say ready, then
        # starts its clock), then phase-lock to the frames of the running clock: release
        # rt-offset after each publication
        warm_k = self._next_good_frame()
        if warm_k is None:
            return
        self._warm_up()
        # the plant starts its clock on this token (until then it offers frame warm_k again)
        self.ready = self.session.liveliness().declare_token(self.K.ready_fsw)
        transport.latest(self.sub_sensors)              # frames that came during the warm-up
        lock = warm_k
        while lock is not None and lock <= warm_k:      # a frame of the running clock, not an offer
            lock = self._next_good_frame()
        if lock is None:
            return
        # the plant's schedule: step k published at origin + k * period, never earlier, often
        # later in its first steps (its own first-call costs: step 1 came 32 ms late, step 2
        # 13 ms, then on time) -- so the earliest origin over LOCK_FRAMES frames, not the first
        # frames, once the last of them keep one schedule (not a catch-up burst); PhaseLock
        period = self.topo.executive.period_ns
        phase = PhaseLock(period, self.LOCK_FRAMES, int(self.LOCK_WAIT_S * 1e9))
        origin = phase.offer(lock, self.dec_sensors.last_t_pub_ns, now_ns())
        while origin is None:
            k = self._next_good_frame()
            if k is None:
                return
            origin = phase.offer(k, self.dec_sensors.last_t_pub_ns, now_ns())
            lock = k
        frames = phase.frames
        say(ROLE, f"phase lock on step {lock}: plant's publications "
                  f"{[round((t - k * period - origin) / 1e3) for k, t in frames]} us after the earliest")
        # tick k of the executive is the plant's step k; the first is the step after this
        # frame's (this one is already a few hundred us old)
        self.topo.executive.clock.start(origin + int(self.args.rt_offset_us * 1e3), k0=lock + 1)
        self.next_k = lock + 1
        self.lock_source = self.source_id
        self.n_frames = 0                               # frame ages from here on
        while self._running():
            if self.sub_fault_log is not None:
                self._take_fault_log()
            self.topo.tick()
            self._record()

    def run(self) -> int:
        a = self.args
        if a.mode == "realtime":    # the arrays the loop fills: no first-touch page fault in flight
            rt.prefault(self.history.truth_rows, self.history.fsw_rows, self.jitter_ns, self.frame_age_ns,
                       self.control_ns, self.lp_cycle)
        rt.gc_out_of_cycle()
        say(ROLE, f"{self.scn.name}, {a.mode}; waiting for the plant")
        if not transport.wait_for_alive(self.session, self.K.alive_sim, a.wait_peers):
            say(ROLE, f"no plant joined within {a.wait_peers:g} s")
        # an answer sent before the plant's subscription has reached this process is lost
        # (through a router the declaration can come after the first sensor frame): in
        # lockstep that would stall the run
        elif not transport.wait_for_subscriber(self.pub_jets, a.wait_peers):
            say(ROLE, f"the plant has not subscribed to the jet commands within {a.wait_peers:g} s")
        (self.run_realtime if a.mode == "realtime" else self.run_lockstep)()
        self.memory = rt.memory_status()        # at the end of the flight, before writing the records
        self.write()
        return 0

    def write(self) -> None:
        if not self.args.out:
            return
        out = Path(self.args.out)
        out.mkdir(parents=True, exist_ok=True)
        self.history.save(out / "fsw_history.npz")
        # every tick's release jitter and control task time and every frame's age, raw (the launcher
        # and ellipsled/node_reports.py sum them up)
        np.savez_compressed(out / "fsw_timing.npz", jitter_ns=self.jitter_ns[: self.ticks],
                            control_ns=self.control_ns[: self.ticks], lp_cycle=self.lp_cycle[: self.ticks],
                            frame_age_ns=self.frame_age_ns[: self.n_frames])
        rep = fsw_report(self.fsw, self.topo.executive.slips, self.samples)
        ex = self.topo.executive.telemetry()
        rep.update({
            "mode": self.args.mode, "ticks": self.ticks,
            "executive": ex, "tasks_us": self.topo.task_percentiles(), "params": self.fsw.params, "sensor_rejects": dict(self.dec_sensors.rejects),
            "monitor_counts": dict(self.fsw.monitor.counts), "answers_repeated": self.answers_repeated,
            "event_log": [{"t_s": e.t_s, "severity": e.severity.name, "source": e.source, "code": e.code,
                           "text": e.text} for e in self.events.history],
            "rt": self.rt_report, "memory": getattr(self, "memory", None),
            "ground_link": (dict(self.link.stats) if self.link is not None and hasattr(self.link, "stats") else None),
            "ground_link_tick": (self.link.budget.report() if self.link is not None and hasattr(self.link, "budget")
                                 else None),
        })
        (out / "fsw.json").write_text(json.dumps(rep, indent=2, default=str) + "\n")

    def close(self) -> None:
        self.topo.close()
        self.fsw.close()
        if self.link is not None:
            self.link.flush_events()
            self.link.close()
        transport.close(self.ready, self.token, self.plant_presence, self.sub_sensors, self.pub_jets, self.pub_state,
                        self.pub_events, self.pub_faults, self.sub_fault_log, self.session)


def _off_cpu_us(wall_ns: int, ru0, ru1) -> float:
    """Of ``wall_ns`` between two getrusage() readings of this thread, the time it was not
    on its CPU [us]."""
    cpu_us = (ru1.ru_utime - ru0.ru_utime + ru1.ru_stime - ru0.ru_stime) * 1e6
    return max(0.0, wall_ns / 1e3 - cpu_us)


def main(args) -> int:
    node = FswNode(args)
    try:
        return node.run()
    finally:
        node.close()
