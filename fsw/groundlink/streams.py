"""The ground link's telemetry streams: their names and default rates, what each one says
now, and which go out in a tick (telemetry.py builds the messages; when a stream is due and
the tick's budget are schedule.py's; where a frame goes is link.py's)."""
from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from interfaces.mavlink.signing.verify import Reject

from . import telemetry as tm
from .schedule import RecentCost

# Telemetry streams and their default rates [Hz]; 0 disables a stream. The achieved rate
# is at most the rate at which the link ticks.
DEFAULT_RATES_HZ: dict[str, float] = {
    "HEARTBEAT": 1.0,
    "SYS_STATUS": 1.0,
    "ATTITUDE": 10.0,
    "ATTITUDE_QUATERNION": 10.0,
    "ATTITUDE_TARGET": 10.0,
    "ACTUATOR_OUTPUT_STATUS": 10.0,
    "NAMED_VALUE_FLOAT": 5.0,
    "ELLIPSLED_ENTRY_STATE": 5.0,
    "ELLIPSLED_JET_STATUS": 5.0,
    "ELLIPSLED_CONTROL_STATUS": 5.0,
    "ELLIPSLED_LOOP_TIMING": 1.0,
    "ELLIPSLED_GUIDANCE_STATUS": 2.0,        # guidance re-predicts at 0.5-1 Hz; range to go moves ~7 km/s
    "GLOBAL_POSITION_INT": 5.0,
    "VFR_HUD": 5.0,
    "ALTITUDE": 1.0,
    "SYSTEM_TIME": 1.0,
    "LOCAL_POSITION_NED": 5.0,
    "CURRENT_MODE": 0.5,                     # and at each mode change
}
ATTITUDE_GROUP = ("ATTITUDE", "ATTITUDE_QUATERNION", "ATTITUDE_TARGET", "NAMED_VALUE_FLOAT", "ELLIPSLED_ENTRY_STATE")
POSITION_GROUP = ("GLOBAL_POSITION_INT", "VFR_HUD", "ALTITUDE")
# streams of one message type each, built one by one (the groups share their geometry)
SINGLE_STREAMS = ("HEARTBEAT", "SYS_STATUS", "SYSTEM_TIME", "ACTUATOR_OUTPUT_STATUS", "ELLIPSLED_JET_STATUS",
                  "ELLIPSLED_CONTROL_STATUS", "ELLIPSLED_LOOP_TIMING", "ELLIPSLED_GUIDANCE_STATUS",
                  "LOCAL_POSITION_NED", "CURRENT_MODE")
MAX_RATE_HZ = 100.0
ALLOC_RING = 512                 # link ticks whose allocator solve time ELLIPSLED_CONTROL_STATUS's p99 is of
# What a tick sends as one unit: each single stream, the attitude group's streams in three
# units (the attitude messages, which share a frame conversion; the named values; the entry
# state: the two 5 Hz ones apart, so each unit's cost is one thing to estimate and the largest
# is a few frames) and the position group (one frame conversion); those of the groups only
# once navigation is valid.
SINGLE_UNITS = tuple((name,) for name in SINGLE_STREAMS)
ATTITUDE_UNITS = (ATTITUDE_GROUP[:3], ATTITUDE_GROUP[3:4], ATTITUDE_GROUP[4:])
ALL_UNITS = SINGLE_UNITS + ATTITUDE_UNITS + (POSITION_GROUP,)


def check_rates(rates: Mapping[str, float] | None) -> dict[str, float]:
    """DEFAULT_RATES_HZ with ``rates`` {stream: Hz} over it; ValueError naming a bad entry."""
    out = dict(DEFAULT_RATES_HZ)
    for name, hz in (rates or {}).items():
        if name not in DEFAULT_RATES_HZ:
            raise ValueError(f"rates: unknown stream {name!r} (known: {', '.join(DEFAULT_RATES_HZ)})")
        if isinstance(hz, bool) or not isinstance(hz, (int, float)) or not math.isfinite(hz) \
                or not 0.0 <= hz <= MAX_RATE_HZ:
            raise ValueError(f"rates.{name}: must be a number in [0, {MAX_RATE_HZ:g}] Hz, got {hz!r}")
        out[name] = float(hz)
    return out


class TelemetryStreams:
    """The messages of each telemetry stream of one GroundLink, from its FlightSoftware
    (``link.fsw``, which the link's warm-up swaps) and what is kept here between ticks: the
    executive's loop timing, the allocator's solve times, the tick's sensor frame, the local
    origin and the mode CURRENT_MODE last told. SYS_STATUS reads the link's counters."""

    def __init__(self, link) -> None:
        self.link = link
        self.loop_timing: dict[int, tuple] = {}       # rate group -> ELLIPSLED_LOOP_TIMING fields
        self.alloc_ring = np.zeros(ALLOC_RING, dtype=np.int64)   # the allocator's last solve times [ns] ...
        self.alloc_samples = 0                                    # ... how many were taken
        self.alloc_degraded = 0
        self.sensors = None                            # latest sensor frame given to tick()
        self.origin = None                             # LOCAL_POSITION_NED's, at the first navigation fix
        self.mode_sent = None                          # the Mode CURRENT_MODE last told
        self.unit_ns: dict[tuple[str, ...], int] = {}  # what each unit is taken to cost [ns] (``_cost``)
        self.unit_costs: dict[tuple[str, ...], RecentCost] = {}    # ... from its last sends' costs
        self.cut = False                               # the last tick's budget deferred a stream
        self.deferred_ns = 0                           # ... and what those would have cost [ns]
        self.sent_ns = 0                               # what the last tick's streams cost [ns]
        self.miss = RecentCost()                       # by how much a unit's cost exceeds its estimate [ns]

    def set_loop_timing(self, rate_group: int, *, jitter_p50_us: float, jitter_p99_us: float,
                        jitter_max_us: float, compute_p50_us: float, compute_p99_us: float,
                        compute_max_us: float, cycle_slips: int) -> None:
        """Latest timing statistics of one rate group (from the executive), sent as
        ELLIPSLED_LOOP_TIMING (one message per rate group at that stream's rate)."""
        self.loop_timing[int(rate_group)] = (jitter_p50_us, jitter_p99_us, jitter_max_us, compute_p50_us,
                                             compute_p99_us, compute_max_us, int(cycle_slips))

    def sample_allocator(self) -> None:
        fsw = self.link.fsw
        self.alloc_ring[self.alloc_samples % ALLOC_RING] = int(getattr(fsw, "alloc_ns", 0))
        self.alloc_samples += 1
        if fsw.allocator.degraded:
            self.alloc_degraded += 1

    def send_due(self, now: float, ms: int) -> None:
        """The streams due at ``now``, those a period overdue first, then the longest-waiting
        first, while the link's tick has time for each (as long as it took recently); the
        first one that does not fit ends the tick's streams (a later, smaller one must not
        overtake it for good), unless it is the tick's first and a period overdue: then it
        goes while any time is left (the most overdue unit goes every tick, however short the
        budget or dear the units: none waits for good, and the budget gives way by one unit
        at most). What is left stays due, counted."""
        link = self.link
        fsw, sched = link.fsw, link.schedule
        C_LN = None
        self.cut, self.deferred_ns, self.sent_ns = False, 0, 0
        first = True
        # a period overdue first: receiving left their cost for them (schedule.py), which a
        # longer-waiting slower stream must not take
        for unit, overdue, n_due in sched.sending_order(ALL_UNITS if tm.nav_valid(fsw) else SINGLE_UNITS, now):
            self.cut = self.cut or not self._fits(unit, overdue and first)
            first = False
            if self.cut:
                link.stats["tx_deferred"] += n_due
                self.deferred_ns += self.unit_ns.get(unit, 0)
                continue
            t0 = link.budget.elapsed_ns()
            if unit in SINGLE_UNITS:
                sched.take(unit[0], now)
                msgs = self.single(unit[0], ms)
            else:
                if C_LN is None:
                    C_LN = tm.local_ned_dcm(fsw.nav.state.r_N)
                group = POSITION_GROUP if unit is POSITION_GROUP else ATTITUDE_GROUP
                want = tuple(n in unit and sched.take(n, now) for n in group)
                msgs = (tm.position if unit is POSITION_GROUP else tm.attitude)(fsw, ms, C_LN, want)
            for msg in msgs:
                link._send(msg)
            cost = link.budget.elapsed_ns() - t0
            self.sent_ns += cost
            self.miss.add(max(0, cost - self.unit_ns.get(unit, cost)))
            self._cost(unit, cost)

    def _cost(self, unit: tuple[str, ...], ns: int) -> None:
        """``unit`` was sent at a cost of ``ns``: its estimate (schedule.RecentCost; a unit
        not sent keeps its estimate: the most overdue unit goes whatever it is, see
        ``send_due``)."""
        est = self.unit_costs.get(unit)
        if est is None:
            est = self.unit_costs[unit] = RecentCost()
        est.add(ns)
        self.unit_ns[unit] = est.ns

    def overdue_ns(self, now: float) -> int:
        """What the units with a stream a period overdue at ``now`` cost recently [ns]:
        they go first this tick (``send_due``), receiving leaves them that."""
        units = ALL_UNITS if tm.nav_valid(self.link.fsw) else SINGLE_UNITS
        return sum(self.unit_ns.get(u, 0) for _, _, u, overdue, _ in self.link.schedule.due(units, now) if overdue)

    def _fits(self, unit: tuple[str, ...], forced: bool) -> bool:
        """Inside a tick: time is left for ``unit`` as long as it took recently and by as
        much as the units' costs recently exceeded their estimates (a unit's cost moves with
        what the tick ran before it: the caches it left); ``forced`` (the tick's most overdue
        unit): any time left. Outside one (a warm-up): always."""
        if not self.link.in_tick:
            return True
        left = self.link.budget.left_ns()
        return left > 0 and (forced or left >= self.unit_ns.get(unit, 0) + self.miss.ns)

    def messages(self, name: str) -> list:
        """The messages of stream ``name`` now, outside its schedule (a one-shot request);
        empty while what it reports does not exist yet (no navigation, no timing)."""
        fsw = self.link.fsw
        ms = int(max(0.0, fsw.t_s) * 1000.0) & 0xFFFFFFFF
        if name in SINGLE_STREAMS:
            return list(self.single(name, ms))
        if not tm.nav_valid(fsw):
            return []
        C_LN = tm.local_ned_dcm(fsw.nav.state.r_N)
        if name in ATTITUDE_GROUP:
            return list(tm.attitude(fsw, ms, C_LN, tuple(n == name for n in ATTITUDE_GROUP)))
        return list(tm.position(fsw, ms, C_LN, tuple(n == name for n in POSITION_GROUP)))

    def single(self, name: str, ms: int):
        """The messages of one of SINGLE_STREAMS at ``ms`` (time_boot_ms)."""
        link = self.link
        fsw = link.fsw
        if name == "HEARTBEAT":
            yield tm.heartbeat(fsw)
        elif name == "SYS_STATUS":
            yield tm.sys_status(fsw, self.loop_timing, link.rejections, link.stats["kernel_drops"],
                                link.stats["refused_early"], link.link.counts[Reject.UNSIGNED],
                                link.stats["reads_limited"])
        elif name == "SYSTEM_TIME":
            yield tm.system_time(fsw, link.wall_clock())
        elif name == "ACTUATOR_OUTPUT_STATUS":
            yield tm.actuator_output_status(fsw)
        elif name == "ELLIPSLED_JET_STATUS":
            yield tm.jet_status(fsw, ms, self.sensors)
        elif name == "ELLIPSLED_CONTROL_STATUS":
            yield tm.control_status(fsw, ms, self.alloc_ring[:min(self.alloc_samples, ALLOC_RING)],
                                    self.alloc_degraded)
        elif name == "ELLIPSLED_LOOP_TIMING":
            yield from tm.loop_timing(ms, self.loop_timing)
        elif name == "ELLIPSLED_GUIDANCE_STATUS":
            yield tm.guidance_status(fsw, ms)
        elif name == "LOCAL_POSITION_NED":
            origin = self.local_origin()
            if origin is not None:
                yield tm.local_position_ned(fsw, ms, origin)
        elif name == "CURRENT_MODE":
            self.mode_sent = fsw.modes.mode
            yield tm.current_mode(fsw)

    def local_origin(self):
        """LOCAL_POSITION_NED's origin (telemetry.local_origin), taken at the first navigation
        fix; None before it."""
        if self.origin is None and tm.nav_valid(self.link.fsw):
            self.origin = tm.local_origin(self.link.fsw)
        return self.origin

    def origin_message(self, p) -> list:
        """GPS_GLOBAL_ORIGIN, when requested (``p``: the request's parameters, unused)."""
        origin = self.local_origin()
        return [] if origin is None else [tm.gps_global_origin(self.link.fsw, origin)]
