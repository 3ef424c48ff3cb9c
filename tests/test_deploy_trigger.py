"""The parachute deploy (fsw/guidance/trigger.py, sim/plant.py): the FSW's trigger fires where a
constructed state crosses its condition inside the deploy box, the plant deploys on command
inside the box or at its edge without one, and bad commands are refused and counted."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from common import atmosphere
from common.events import EventLog
from common.model import load_scenario
from ellipsled.montecarlo.campaign import Criteria
from interfaces.event_catalogue import EV
from interfaces.records import DEPLOY_EDGE, DEPLOY_FLOOR, DEPLOY_NONE, DEPLOY_RANGE, DEPLOY_VELOCITY
from fsw.flightsoftware import FlightSoftware
from fsw.guidance.trigger import DeployTrigger
from sim.dynamics import A_H, A_MACH, A_QBAR
from sim.plant import Plant

GUIDED = load_scenario("guided-nominal")
BOX = GUIDED.vehicle.deploy_box
R = GUIDED.planet.radius_m
OM = GUIDED.planet.omega_radps
TLON = GUIDED.target_lon_rad


def _nav(lon_rad: float, mach: float, h_m: float = 9000.0, qbar_pa: float = 700.0, speed: float = 450.0):
    """A navigation state on the equator at ``lon_rad`` (t = 0: inertial = planet-fixed axes),
    flying due east at ``speed`` relative to the planet, level."""
    r = R + h_m
    u = np.array([math.cos(lon_rad), math.sin(lon_rad), 0.0])
    east = np.array([-math.sin(lon_rad), math.cos(lon_rad), 0.0])
    r_N = r * u
    v_N = speed * east + np.cross([0.0, 0.0, OM], r_N)
    return SimpleNamespace(r_N=r_N, v_N=v_N, mach=mach, h_m=h_m, qbar_pa=qbar_pa)


def _trigger(rule: str, **over) -> tuple[DeployTrigger, EventLog]:
    ev = EventLog()
    fsw = FlightSoftware(GUIDED, EventLog(), param_overrides={"deploy": {"trigger": rule, **over}})
    fsw.close()
    return DeployTrigger(GUIDED, fsw.params, ev), ev


def test_range_trigger_fires_exactly_when_the_target_is_passed_inside_the_box():
    trig, ev = _trigger("range")
    # 10 m of arc (at the vehicle's radius) per sample, from 25 m short of the target to 25 m past it
    d = 10.0 / (R + 9000.0)
    lons = [TLON + (i + 0.5) * d for i in range(-3, 3)]
    fired = [trig.update(_nav(lon, mach=2.0), 0.0) for lon in lons]
    assert fired == [0, 0, 0, 1, 1, 1]         # the first sample past the target
    assert trig.code == DEPLOY_RANGE
    assert trig.range_to_go_m == pytest.approx(-5.0 * R / (R + 9000.0), abs=0.01)   # on the planet's surface
    assert [e.code for e in ev.history] == [EV.DEPLOY_COMMAND.name]


def test_range_trigger_waits_for_the_box_when_the_target_is_passed_too_fast():
    trig, _ = _trigger("range")
    past = TLON + 1e-3
    assert trig.update(_nav(past, mach=BOX.mach_max + 0.1), 0.0) == 0        # past, but above the box's Mach
    assert trig.update(_nav(past, mach=2.0, qbar_pa=BOX.qbar_max_pa * 1.05), 0.0) == 0   # dynamic pressure too high
    assert trig.update(_nav(past, mach=BOX.mach_max - 0.01), 0.0) == 1
    assert trig.code == DEPLOY_RANGE


def test_range_trigger_short_of_the_target_fires_at_the_box_edge_margin():
    trig, ev = _trigger("range")
    short = TLON - 0.01                              # 34 km short: never reached
    margin = trig.params["deploy.mach_margin"]
    assert trig.update(_nav(short, mach=BOX.mach_min + margin + 0.01), 0.0) == 0
    assert trig.update(_nav(short, mach=BOX.mach_min + margin), 0.0) == 1
    assert trig.code == DEPLOY_EDGE
    trig, _ = _trigger("range", h_floor_m=0.0)       # the altitude edge likewise (the floor off)
    h_edge = BOX.h_min_m + trig.params["deploy.h_margin_m"]
    assert trig.update(_nav(short, mach=2.0, h_m=h_edge + 1.0), 0.0) == 0
    assert trig.update(_nav(short, mach=2.0, h_m=h_edge - 1.0), 0.0) == 1
    assert trig.code == DEPLOY_EDGE


@pytest.mark.parametrize("rule", ["range", "velocity"])
def test_inside_the_box_the_altitude_floor_trades_the_range_to_go(rule):
    trig, ev = _trigger(rule)
    floor = trig.params["deploy.h_floor_m"]
    short = TLON - 0.01
    assert trig.update(_nav(short, mach=2.2, h_m=floor + 1.0), 0.0) == 0
    assert trig.update(_nav(short, mach=2.2, h_m=floor - 1.0), 0.0) == 1
    assert trig.code == DEPLOY_FLOOR
    trig, _ = _trigger(rule)                           # above the box's Mach: no deploy at the floor
    assert trig.update(_nav(short, mach=BOX.mach_max + 0.1, h_m=floor - 1.0), 0.0) == 0


def test_velocity_trigger_fires_at_its_mach_wherever_the_target_is():
    trig, _ = _trigger("velocity")
    m = trig.params["deploy.mach"]
    assert trig.update(_nav(TLON + 1e-3, mach=m + 0.01), 0.0) == 0   # past the target: no matter
    assert trig.update(_nav(TLON - 1e-2, mach=m), 0.0) == 1
    assert trig.code == DEPLOY_VELOCITY
    assert trig.update(_nav(TLON, mach=m + 0.5), 0.0) == 1           # latched


def _plant_at(mach: float, h_m: float) -> Plant:
    """guided-nominal's plant moved to a level, eastward state at h_m flying at ``mach``."""
    p = Plant(GUIDED, seed=3)
    speed = mach * atmosphere.speed_of_sound(h_m)
    nav = _nav(0.0, mach, h_m=h_m, speed=speed)
    p.set_state(r_N=nav.r_N, v_N=nav.v_N)
    return p


def test_plant_deploys_at_the_box_edge_without_a_command_and_records_it():
    p = _plant_at(BOX.mach_min - 0.1, 9000.0)
    assert p.aux[A_MACH] < BOX.mach_min
    assert p.done() == (True, "box_edge")
    assert p.deploy_report() == {"by": "box_edge", "edge": "mach_min", "refused_outside_box": 0}
    p = _plant_at(1.8, BOX.h_min_m - 100.0)
    assert p.done() == (True, "box_edge") and p.deploy_edge == "h_min"


def test_plant_deploys_on_command_inside_the_box_and_holds_a_command_given_outside():
    p = _plant_at(1.8, 9000.0)
    assert BOX.inside(p.aux[A_MACH], p.aux[A_QBAR], p.aux[A_H])      # the constructed state is in the box
    assert p.done() == (False, "")
    p.command_deploy(1)
    assert p.done() == (True, "deploy")
    assert p.deploy_report()["by"] == "command"
    p = _plant_at(BOX.mach_max + 0.5, 9000.0)                          # too fast: held, counted
    p.command_deploy(1)
    assert p.done() == (False, "") and p.deploy_refused == 1


def test_plant_refuses_bad_deploy_commands():
    p = Plant(GUIDED, seed=3)
    for bad in (2, -1, 0.5, "1", None):
        with pytest.raises(ValueError):
            p.command_deploy(bad)
    assert not p.deploy_commanded
    paper = Plant(load_scenario("case1"), seed=3)          # the paper's plant deploys at Mach 2 itself
    assert paper.deploy_box is None
    paper.command_deploy(0)
    with pytest.raises(ValueError):
        paper.command_deploy(1)


def test_sim_node_counts_a_deploy_command_out_of_range():
    from ellipsled.sil.sim_node import SimNode, command_refusal
    from interfaces import records
    rec = records.new(records.JETS)
    rec["k"], rec["deploy"] = 5, 2
    node = SimpleNamespace(rejects={})
    node._rejected = lambda why, detail: node.rejects.__setitem__(why, node.rejects.get(why, 0) + 1)
    assert SimNode._refused(node, rec, 5) and node.rejects == {"deploy_range": 1}
    rec["deploy"] = 1
    assert command_refusal(rec, 5) is None


def test_guided_campaign_criteria_judge_deploy_altitude_and_box():
    c = Criteria(completed=True, finite=True, bank_err_max_after_fault_deg=5.0, deploy_miss_km=12.5,
                 deploy_alt_min_km=6.0, deploy_in_box=True)
    good = {"completed": True, "nonfinite": False, "bank_err_max_after_fault_deg": 1.0, "deploy_miss_km": 1.0,
            "deploy_alt_km": 6.5, "deploy": {"ok": True}}
    assert c.failures(good) == []
    assert c.failures({**good, "deploy_alt_km": 5.9}) == ["deploy_alt_min_km"]
    assert c.failures({**good, "deploy": {"ok": False}}) == ["deploy_in_box"]
    assert c.failures({k: v for k, v in good.items() if k != "deploy"}) == ["deploy_in_box"]


def test_paper_cases_deploy_at_their_end_condition():
    for name in ("case1", "case2", "case3", "case4", "nominal"):
        assert load_scenario(name).deploy_by == "plant"
    assert GUIDED.deploy_by == "fsw"
    assert DEPLOY_NONE == 0


def test_floor_margin_is_k_times_the_measured_prediction_change_grown_over_the_cycles_to_go():
    fsw = FlightSoftware(GUIDED, EventLog())
    try:
        g = fsw.entry
        p = g.params
        assert g.floor_margin_m == p["npc.floor_margin_min_m"]      # nothing measured yet
        # predictions changing by +-100 m every cycle, 1 s apart, 400 s to go: RMS 100 m,
        # 400 cycles to go -> k * 100 * 20 = 4000 m with k = 2 (within the bounds given)
        g._period_s = 1.0
        p["npc.floor_margin_max_m"] = 10_000.0
        for i in range(60):
            g._measure_prediction(8000.0 + (100.0 if i % 2 else 0.0), 400.0)
        assert g.floor_margin_m == pytest.approx(p["npc.floor_margin_k"] * 100.0 * 20.0, rel=1e-3)   # no drift
        g._measure_prediction(8000.0 + (100.0 if 60 % 2 else 0.0), 4.0)      # near the deploy: the minimum
        assert g.floor_margin_m == p["npc.floor_margin_min_m"]
        p["npc.floor_margin_max_m"] = 1500.0
        g._measure_prediction(8100.0, 400.0)
        assert g.floor_margin_m == 1500.0                                      # clamped
    finally:
        fsw.close()
