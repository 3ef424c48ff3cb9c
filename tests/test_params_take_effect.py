"""Every ground-settable parameter, set through the real ground link during a flight, changes
the behaviour it controls from the next cycles on.

The flight: case1 (its scheduled faults removed) flown by a FlightSoftware in its Topology
(RG1 control, RG2 residual check and the GroundLink on an ephemeral loopback port) stepping
the plant in-process; the ground station is a GroundClient sending signed PARAM_SET and
COMMAND_LONG over UDP. Each parameter's case flies twice, the same way, once with the
PARAM_SET and once without, and compares one concrete observable of the behaviour the
parameter controls (a detection, a mode, a rejection, the torque command, the estimates,
the jets fired). Independent truth: the other flight, and the direction the parameter's
documented meaning predicts. Where flight alone never exercises a limit, the test plays a
sensor fault in the frame path (a transducer offset, a corrupted vector, frames withheld).
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pytest

from common.model import load_scenario
from fsw.executive import LockstepClock
from fsw.flightsoftware import FlightSoftware, all_params
from fsw.groundlink import GroundLink
from fsw.params import param_ids
from fsw.topology import Topology
from gse.client import GroundClient
from gse.commands import make_request
from interfaces.mavlink import dialect as mav
from sim.plant import Plant

from tests.rig import Clock, write_key

JET = 2          # the jet case1 fires most in its first seconds


def f32(x: float) -> float:
    """What a PARAM_SET carries (float32)."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


class Flight:
    """FSW (in its Topology, ground link in RG2) + plant + ground station, stepped here."""

    def __init__(self, tmp_path, scenario: str = "case1"):
        self.scn = load_scenario(scenario).with_(faults=())
        self.plant = Plant(self.scn)
        self.fsw = FlightSoftware(self.scn)
        self.topo = Topology(self.fsw, LockstepClock())
        key = write_key(tmp_path)
        self.clock = Clock()
        self.gcs = GroundClient(key, listen="udp:127.0.0.1:0")
        self.gl = GroundLink(self.fsw, key, gcs=f"udp:127.0.0.1:{self.gcs.address[1]}", bind="udp:127.0.0.1:0",
                             inject=self._inject, clock=self.clock, tick_clock_ns=lambda: 0)
        self.gcs.set_vehicle(self.gl.address)
        self.topo.add(2, "groundlink", lambda c: self.gl.tick(self.frame))
        self.frame = self.plant.sensors
        self.tamper: Callable | None = None         # a sensor fault played on each frame
        self.ids = param_ids(p.name for p in all_params() if p.ground_settable)

    def _inject(self, jet, kind, eta):
        self.plant.set_fault(jet, kind, eta)
        return True

    def fly(self, n: int, every: Callable | None = None, withhold: bool = False) -> None:
        for _ in range(n):
            if withhold:
                self.topo.tick()                      # a period without a sensor frame
            else:
                frame = self.frame
                if self.tamper is not None:
                    frame = frame.copy()
                    self.tamper(frame)
                self.topo.tick(frame)
                self.frame = self.plant.step(self.topo.u)
            self.clock.t += self.scn.dt_control_s
            self.gcs.poll(0.0)
            if every is not None:
                every(self)

    def param_set(self, name: str, value: float, apply: bool = True) -> None:
        """PARAM_SET over the link (if ``apply``), then 10 cycles (two link ticks) either
        way, so both flights of a case stay in step; the vehicle must echo the value."""
        pid = self.ids[name]
        if apply:
            self.gcs.start(make_request("param", "set", pid, repr(value)))
        self.fly(10)
        if apply:
            got = self.gcs.state.params.get(pid)
            assert got == f32(value), f"{pid}: echo {got}, vehicle says {[e.text for e in self.gcs.state.events]}"
            assert self.fsw.params[name] == f32(value)

    def command(self, *words) -> None:
        pc = self.gcs.start(make_request(*words))
        self.fly(10)
        assert pc.done and pc.result == mav.MAV_RESULT_ACCEPTED, (words, pc.result)

    def codes(self) -> list[str]:
        return [e.code for e in self.fsw.events.history]

    def close(self):
        self.gl.close()
        self.gcs.close()
        self.fsw.close()


# ------------------------------------------------------------------ observables

def torque_mean(fl: Flight, n: int = 50) -> float:
    acc = []
    fl.fly(n, every=lambda f: acc.append(np.linalg.norm(f.fsw.u_cal_B)))
    return float(np.mean(acc))


def estimate_change(sl: slice, n: int = 150) -> Callable[[Flight], float]:
    def obs(fl: Flight) -> float:
        th0 = fl.fsw.control.theta_hat[sl].copy()
        fl.fly(n)
        return float(np.max(np.abs(fl.fsw.control.theta_hat[sl] - th0)))
    return obs


def d_hat_extreme(fn, n: int = 150) -> Callable[[Flight], float]:
    def obs(fl: Flight) -> float:
        vals = []
        fl.fly(n, every=lambda f: vals.append(fn(f.fsw.control.d_hat)))
        return float(fn(vals))
    return obs


def roll_command_sum(fl: Flight, n: int = 100) -> float:
    acc = []
    fl.fly(n, every=lambda f: acc.append(float(f.fsw.control.u_cal_B[0])))
    return float(np.sum(acc))


def axis_error(axis: int, n: int = 100) -> Callable[[Flight], float]:
    def obs(fl: Flight) -> float:
        acc = []
        fl.fly(n, every=lambda f: acc.append(abs(f.fsw.u_cal_B[axis] - f.fsw.tau_alloc_B[axis])))
        return float(np.sum(acc))
    return obs


def detection_of(jet: int, *inject: str, n: int = 200) -> Callable[[Flight], str]:
    """FDIR's finding on ``jet`` after the plant fault ``inject`` (injected from the ground)."""
    def obs(fl: Flight) -> str:
        if inject:
            fl.command("inject", str(jet), *inject)
        fl.fly(n)
        kinds = [d["kind"] for d in fl.fsw.fdir.detections if d["jet"] == jet]
        return kinds[0] if kinds else "none"
    return obs


def rejected(reason: str, n: int = 25) -> Callable[[Flight], bool]:
    def obs(fl: Flight) -> bool:
        before = fl.fsw.monitor.counts[reason]
        fl.fly(n)
        return fl.fsw.monitor.counts[reason] > before
    return obs


def event_within(code: str, n: int) -> Callable[[Flight], bool]:
    def obs(fl: Flight) -> bool:
        i = len(fl.fsw.events.history)
        fl.fly(n)
        return any(e.code == code for e in fl.fsw.events.history[i:])
    return obs


def residual_variation(fl: Flight) -> float:
    """Total variation of the residual over 4 s: a low-pass can only lower it."""
    acc = []
    fl.fly(200, every=lambda f: acc.append(f.fsw.fdir.residual_norm_Nm))
    return float(np.sum(np.abs(np.diff(acc))))


def max_residual_limit(fl: Flight) -> float:
    acc = []
    fl.fly(200, every=lambda f: acc.append(f.fsw.fdir.residual_limit_Nm))
    return float(np.max(acc))


def went_safe(fl: Flight) -> bool:
    fl.fly(200)
    return int(fl.fsw.modes.mode) == 2


def chart_switch_on_crossing(fl: Flight) -> bool:
    """The reported attitude jumps across the 180-degree principal angle (|sigma| 0.85 ->
    its shadow-side twin with |sigma_chart| = 1.3): the controller's chart switches only if
    1.3 exceeds control.sigma_switch."""
    s = np.array(fl.frame["sigma_BN"])
    u = s / np.linalg.norm(s)
    fl.tamper = lambda f: f["sigma_BN"].__setitem__(slice(None), -u / 1.3)
    switched = []
    fl.fly(3, every=lambda f: switched.append(bool(f.fsw.control.chart_switched)))
    return any(switched)


def jet_pulses_after(jet: int, n: int = 150) -> Callable[[Flight], int]:
    def obs(fl: Flight) -> int:
        before = int(fl.fsw.driver.pulses[jet - 1])
        fl.fly(n)
        return int(fl.fsw.driver.pulses[jet - 1]) - before
    return obs


def propellant_used(fl: Flight) -> float:
    before = fl.fsw.driver.propellant_kg
    fl.fly(100)
    return fl.fsw.driver.propellant_kg - before


def stuck_pair_controllable(fl: Flight) -> bool:
    """Jets 14 and 18 stuck on at 60 s (qbar 1.4 kPa), injected from the ground: the other
    jets cannot cancel their 284 N m; an alpha/beta trim offset of 1.8 deg can, if the
    parameter allows it. What the controllability LP concludes after FDIR isolates them."""
    for jet in (14, 18):
        fl.command("inject", str(jet), "stuck_on")
    fl.fly(50)
    return bool(fl.fsw.controllability.controllable)


def armed_after_entry(fl: Flight) -> bool:
    fl.command("mode", "entry")
    return bool(fl.fsw.driver.armed)


# ------------------------------------------------------------------ set-ups (both flights)

def offset_chamber(jet: int, dp: float):
    def setup(fl: Flight) -> None:
        def tamper(frame):
            frame["chamber"][jet - 1] += dp     # a transducer offset
        fl.tamper = tamper
    return setup


def ground(*steps):
    """Commands or parameter sets both flights get before the case's own set."""
    def setup(fl: Flight) -> None:
        for s in steps:
            if s[0] == "param":
                fl.param_set(s[1], s[2])
            else:
                fl.command(*s)
    return setup


def corrupt_once(field: str, fn):
    """The case's observation window starts with one frame whose ``field`` is replaced."""
    def setup(fl: Flight) -> None:
        state = {"n": 0}

        def tamper(frame):
            if state["n"] == 0:
                frame[field][:] = fn(np.array(frame[field]))
            state["n"] += 1
        fl.after_set = lambda: setattr(fl, "tamper", tamper)
    return setup


def withhold(n: int):
    def obs(fl: Flight) -> bool:
        fl.fly(n, withhold=True)
        return bool(fl.fsw.monitor.stale)
    return obs


def cycles_outside_the_sign_box(fl: Flight) -> int:
    """Cycles whose allocated torque leaves [min(0, demand), max(0, demand)] on some axis."""
    n = 0
    for _ in range(200):
        fl.fly(1)
        d, t = fl.fsw.u_cal_B, fl.fsw.tau_alloc_B
        n += bool(np.any((t < np.minimum(d, 0.0) - 1e-9) | (t > np.maximum(d, 0.0) + 1e-9)))
    return n


@dataclass
class Case:
    name: str
    value: float
    observe: Callable[[Flight], object]
    relation: str                       # set vs default: ">", "<", "!=", or "==" with ``expect``
    expect: tuple = ()                  # (with the set, without it) for "=="
    setup: Callable[[Flight], None] | None = None
    at: int = 25                        # cycles flown before the set
    scenario: str = "case1"             # flown with its scheduled faults removed


# ------------------------------------------------------------------ guidance mode npc
# (guided-nominal; a set is applied by the next guidance cycle, at 1 s, so observations
# start with the answer of that cycle: index 1 of the answer histories)
GUIDED = "guided-nominal"


def npc_after(fn, n: int = 110) -> Callable[[Flight], float]:
    """fn(EntryGuidance, answers since the set) after n cycles (two answers from the set on)."""
    def obs(fl: Flight) -> float:
        fl.fly(n)
        e = fl.fsw.entry
        return fn(e, slice(1, min(e.cycles, e.STATS)))
    return obs


def bank_cmd_mean(fl: Flight, n: int = 110) -> float:
    acc = []
    fl.fly(n, every=lambda f: acc.append(f.fsw.entry.bank_cmd))
    return float(np.mean(acc))


def reverses(speed: str, dpsi_deg: float, *, t_go_s: float = math.inf, t_rev_s: float = 0.0,
             second_after_s: float | None = None) -> Callable[[Flight], bool]:
    """Does the flight's lateral logic (its parameters as the next guidance cycle left them)
    decide a reversal on a scripted input: heading error dpsi_deg beyond the side the bank
    turns away from, at the entry speed ("hi") or the deploy speed ("lo"), with the predicted
    time to go and reversal time given; with ``second_after_s``, a first reversal is
    decided (large error) and this one asked that many seconds later."""
    def obs(fl: Flight) -> bool:
        fl.fly(60)
        lat = fl.fsw.entry.lateral
        V, t = (lat.v_hi_mps if speed == "hi" else lat.v_lo_mps), fl.fsw.t_s
        if second_after_s is not None:
            assert lat.update(t, V, math.radians(30.0) * lat.sign)
            t += second_after_s
        return lat.update(t, V, math.radians(dpsi_deg) * lat.sign, t_go_s=t_go_s, t_rev_s=t_rev_s)
    return obs


def half_sensed_accel(fl: Flight) -> None:
    """Estimator from the start (k_drag_min 0) on a sensed acceleration halved: K_rho < 1."""
    fl.param_set("npc.k_drag_min", 0.0)
    fl.tamper = lambda f: f["accel_B"].__imul__(0.5)


R_MARS = 3396.2e3
CASES = [
    # SAMI controller
    Case("control.lambda_radps", 3.0, torque_mean, ">"),
    Case("control.q_weight", 1e3, estimate_change(slice(0, 6)), ">"),
    Case("control.gamma_h", 1e4, estimate_change(slice(0, 6)), ">"),
    Case("control.gamma_d", 1e4, estimate_change(slice(6, 9)), ">"),
    Case("control.h_bound_frac", 0.02, estimate_change(slice(0, 3)), "<",
         setup=ground(("param", "control.gamma_h", 1e4))),
    Case("control.h_prod_scale", 1.0, estimate_change(slice(3, 6)), ">"),
    Case("control.d_min", 1.0, d_hat_extreme(np.min), ">",
         setup=ground(("param", "control.gamma_d", 1e4))),
    Case("control.d_max", 1.0, d_hat_extreme(np.max), "<",
         setup=ground(("param", "control.gamma_d", 1e4))),
    Case("control.deadzone", 1e4, estimate_change(slice(0, 9)), "==", (0.0, None)),
    Case("control.int_limit", 0.0, lambda fl: [fl.fly(50), float(np.max(np.abs(fl.fsw.control.eps_int)))][1],
         "==", (0.0, None)),
    Case("control.shortfall_frac", 0.0,
         lambda fl: sum([fl.fly(1), bool(fl.fsw.control.saturated)][1] for _ in range(100)), ">"),
    Case("control.safe_rate_gain", 5.0, torque_mean, ">", setup=ground(("mode", "safe"))),
    Case("control.sigma_switch", 1.5, chart_switch_on_crossing, "==", (False, True)),
    # jets 14 and 18 stuck on at q-bar ~1 Pa: pitch and yaw short, the roll command then
    # carries their error about the velocity vector
    Case("control.bank_keep", 1.0, roll_command_sum, "!=",
         setup=ground(("inject", "14", "stuck_on"), ("inject", "18", "stuck_on"))),
    # allocator
    Case("allocator.w_roll", 0.0, axis_error(0), ">"),
    Case("allocator.w_pitch", 0.0, axis_error(1), ">"),
    Case("allocator.w_yaw", 0.0, axis_error(2), ">"),
    Case("allocator.penalty_per_N", 10.0, propellant_used, "<"),
    Case("allocator.spill_jets", 0.0, cycles_outside_the_sign_box, "==", (0, None)),
    Case("allocator.fault_tolerance", 0.0, jet_pulses_after(JET), ">",
         setup=ground(("mark", str(JET), "failed_off"))),
    # FDIR jet monitor (faults injected in the plant from the ground, or a transducer offset)
    Case("fdir.persist_s", 4.0, detection_of(JET, "stuck_on", n=150), "==", ("none", "stuck_on")),
    Case("fdir.on_threshold", 0.25, detection_of(JET), "==", ("stuck_on", "none"),
         setup=offset_chamber(JET, 0.3)),
    Case("fdir.off_threshold", 0.1, detection_of(JET, "degraded", "0.15"), "==", ("none", "failed_off")),
    Case("fdir.degraded_lo", 0.5, detection_of(JET, "degraded", "0.4"), "==", ("none", "degraded")),
    Case("fdir.degraded_hi", 0.85, detection_of(JET, "degraded", "0.9"), "==", ("none", "degraded")),
    Case("fdir.delay_s", 3.0,
         lambda fl: [fl.command("inject", str(JET), "failed_off"), fl.fly(200),
                     round(fl.fsw.fdir.detections[0]["t_apply_s"] - fl.fsw.fdir.detections[0]["t_s"], 6)][2],
         "==", (3.0, 0.0)),
    # analytic-redundancy residual (later in the entry, where it is small against its threshold)
    Case("fdir.res_thr_Nm", 0.0, event_within("unexplained_torque", 500), "==", (True, False), at=750),
    # (its relative part: the limit it sets; with the jets idle the torque reference is ~0.1 N m
    # against a residual of 0.5-2 N m of sensor and model error, so no relative factor alone
    # decides an alarm there)
    Case("fdir.res_rel", 10.0, max_residual_limit, ">", setup=ground(("param", "fdir.res_thr_Nm", 0.0))),
    Case("fdir.res_persist_s", 60.0, event_within("unexplained_torque", 500), "==", (False, True), at=750,
         setup=ground(("param", "fdir.res_thr_Nm", 0.0))),
    Case("fdir.res_tau_s", 0.0, residual_variation, ">"),
    # sensor-frame monitor
    Case("fdir.stale_s", 0.2, withhold(5), "==", (False, True)),
    Case("fdir.omega_max_radps", 0.02, rejected("range"), "==", (True, False)),
    Case("fdir.sigma_tol", 0.1, rejected("range"), "==", (False, True),
         setup=corrupt_once("sigma_BN", lambda s: s / np.linalg.norm(s) * 1.05)),
    Case("fdir.r_below_m", 1000.0, rejected("range"), "==", (True, False),
         setup=corrupt_once("r_N", lambda r: r / np.linalg.norm(r) * (R_MARS - 3000.0))),
    Case("fdir.alt_max_m", 1000.0, rejected("range"), "==", (True, False)),
    Case("fdir.v_max_mps", 1.0, rejected("range"), "==", (True, False)),
    Case("fdir.accel_max_mps2", 1.0, rejected("range"), "==", (True, False),
         setup=corrupt_once("accel_B", lambda a: np.array([5.0, 0.0, 0.0]))),
    Case("fdir.chamber_lo", 0.0, rejected("chamber_range"), "==", (True, False)),
    Case("fdir.chamber_hi", 1.0, rejected("chamber_range", 100), "==", (True, False), at=5),
    # failsafes
    Case("fdir.safe_track_deg", 0.5, went_safe, "==", (True, False)),
    Case("fdir.safe_track_s", 60.0, went_safe, "==", (False, True),
         setup=ground(("param", "fdir.safe_track_deg", 0.5))),
    # jet driver
    Case("driver.arm_on_entry", 0, armed_after_entry, "==", (False, True),
         setup=ground(("mode", "standby"), ("arm", "off"))),
    # guidance (read at a reconfiguration: FDIR isolating a fault injected from the ground)
    Case("guidance.authority_use", 0.05,
         lambda fl: [fl.command("inject", str(JET), "failed_off"), fl.fly(100), fl.fsw.guidance.profile.accel_limit_radps2][2],
         "<"),
    Case("guidance.trim_max_deg", 0.0, stuck_pair_controllable, "==", (False, True), at=3000),
    # predictor-corrector (mode npc): the corrector's answer phi_0. A higher final bank flies
    # shorter: less bank is needed early; the bounds clip it; a deploy energy taken higher
    # reaches phi_f earlier (more lift): more bank early
    Case("npc.bank_final_deg", 150.0, npc_after(lambda e, a: e.bank0_cmd), "<", at=10, scenario=GUIDED),
    Case("npc.bank_max_deg", 90.0, npc_after(lambda e, a: e.bank0_cmd), "<", at=10, scenario=GUIDED),
    # (bank_min: the range solution below it, the answer holds the bound: fsw/guidance/corrector.py bank_profile)
    Case("npc.bank_min_deg", 90.0, npc_after(lambda e, a: e.bank0_cmd == math.radians(90.0)), "==", (True, False),
         at=10, scenario=GUIDED, setup=ground(("param", "npc.bank_final_deg", 150.0))),
    Case("npc.h_deploy_m", 30000.0, npc_after(lambda e, a: e.bank0_cmd), ">", at=10, scenario=GUIDED),
    # ... its effort: predictions per cycle (max_iter: a large correction needed, phi_f moved
    # first; tol_m: the warm answers of the entry accepted sooner); the integration step:
    # another predicted deploy point, so another answer
    Case("npc.max_iter", 1, npc_after(lambda e, a: int(e.calls[a].max())), "<", at=10, scenario=GUIDED,
         setup=ground(("param", "npc.bank_final_deg", 150.0))),
    Case("npc.tol_m", 1e5, npc_after(lambda e, a: int(e.calls[a].max())), "<", at=10, scenario=GUIDED),
    Case("npc.dt_pred_s", 10.0, npc_after(lambda e, a: (e.bank0_cmd, e.pred_h_m, e.t_go_s)), "!=", at=10,
         scenario=GUIDED),
    # density estimate (true density 1.2 x the model)
    Case("npc.k_drag_min", 0.0, npc_after(lambda e, a: e.estimator.updates), ">", at=10, scenario=GUIDED),
    Case("npc.k_max", 1.0, npc_after(lambda e, a: e.estimator.k_rho), "<", at=10, scenario=GUIDED,
         setup=ground(("param", "npc.k_drag_min", 0.0))),
    Case("npc.k_tau_s", 100.0, npc_after(lambda e, a: abs(e.estimator.k_rho - 1.0)), "<", at=10, scenario=GUIDED,
         setup=ground(("param", "npc.k_drag_min", 0.0))),
    Case("npc.k_min", 1.0, npc_after(lambda e, a: e.estimator.k_rho), ">", at=10, scenario=GUIDED,
         setup=half_sensed_accel),
    # path-limit feedback (altitude rate): closing on the limits sooner, or lower limits, lift
    # the bank up (smaller magnitude); no gain, no feedback
    Case("npc.hdot_tau_s", 200.0, bank_cmd_mean, "<", at=10, scenario=GUIDED),
    Case("npc.limit_frac", 0.1, bank_cmd_mean, "<", at=10, scenario=GUIDED,
         setup=ground(("param", "npc.hdot_tau_s", 50.0))),
    Case("npc.hdot_gain", 0.0, bank_cmd_mean, ">", at=10, scenario=GUIDED,
         setup=ground(("param", "npc.hdot_tau_s", 200.0))),
    # lateral logic: the reversal decisions it makes on scripted inputs
    Case("npc.dpsi_hi_deg", 2.0, reverses("hi", 5.0), "==", (True, False), at=10, scenario=GUIDED),
    Case("npc.dpsi_lo_deg", 5.0, reverses("lo", 2.0), "==", (False, True), at=10, scenario=GUIDED),
    Case("npc.rev_gap_s", 300.0, reverses("hi", 30.0, second_after_s=30.0), "==", (False, True), at=10,
         scenario=GUIDED),
    Case("npc.v_norev_mps", 8000.0, reverses("hi", 30.0), "==", (False, True), at=10, scenario=GUIDED),
    Case("npc.tgo_freeze_s", 300.0, reverses("hi", 30.0, t_go_s=100.0, t_rev_s=10.0), "==", (False, True),
         at=10, scenario=GUIDED),
    # the deploy-altitude floor: one far above any deploy puts the floor's search for a range
    # trade into every answer (predictor calls per answer; this early in the entry every trade
    # it tries misses by more than npc.floor_miss_max_m, so it keeps the range solution)
    Case("npc.h_floor_m", 30000.0, npc_after(lambda e, a: float(np.sum(e.calls[a]))), ">", at=10, scenario=GUIDED),
]


def test_every_ground_settable_parameter_has_a_case():
    assert sorted(c.name for c in CASES) == sorted(p.name for p in all_params() if p.ground_settable)


def fly_case(tmp_path, case: Case, apply: bool):
    where = tmp_path / ("set" if apply else "default")
    where.mkdir()
    fl = Flight(where, case.scenario)
    try:
        fl.after_set = None
        fl.fly(case.at)
        if case.setup is not None:
            case.setup(fl)
        fl.param_set(case.name, case.value, apply)
        if fl.after_set is not None:
            fl.after_set()
        return case.observe(fl)
    finally:
        fl.close()


KNOWN_OPEN: dict[str, str] = {}


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.xfail(strict=False, reason=KNOWN_OPEN[c.name]))
                                  if c.name in KNOWN_OPEN else c for c in CASES], ids=lambda c: c.name)
def test_a_ground_set_changes_what_the_parameter_controls(tmp_path, case):
    with_set = fly_case(tmp_path, case, True)
    without = fly_case(tmp_path, case, False)
    if case.relation == ">":
        assert with_set > without, (with_set, without)
    elif case.relation == "<":
        assert with_set < without, (with_set, without)
    elif case.relation == "!=":
        assert with_set != without, (with_set, without)
    else:
        want_set, want_default = case.expect
        assert with_set == want_set, (with_set, without)
        if want_default is None:        # "anything but the set value"
            assert without != want_set, (with_set, without)
        else:
            assert without == want_default, (with_set, without)
