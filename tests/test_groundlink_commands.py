"""Ground link commands: every COMMAND_LONG the vehicle knows, answered with the right
MAV_RESULT over real signed UDP on loopback, and its effect checked on the FSW objects
(or on the plant the injection was forwarded to). Also: HEARTBEAT system_status follows
mode and FDIR. On the shared ground-link rig (tests/rig.py).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fsw.health import DEGRADED, FAILED_OFF, NOMINAL, STUCK_ON
from fsw.modes import Mode
from gse.commands import make_request
from interfaces.mavlink import dialect as mav
from interfaces.vocabulary import FAULT_HEALTH

from tests.rig import ACCEPTED, DENIED, UNSUPPORTED, Rig, rig  # noqa: F401  (the shared fixture)


# --------------------------------------------------------------------------- injection

@pytest.mark.parametrize("words, expect", [
    (("inject", "17", "failed_off"), (17, "failed_off", 1.0)),
    (("inject", "5", "stuck_on"), (5, "stuck_on", 1.0)),
    (("inject", "3", "degraded", "0.4"), (3, "degraded", 0.4)),
    (("inject", "0", "nominal"), (0, "nominal", 1.0)),
])
def test_valid_injection_is_forwarded_to_the_plant_and_accepted(rig, words, expect):
    assert rig.command(*words) == ACCEPTED
    jet, kind, eta = rig.injected[-1]
    assert (jet, kind) == expect[:2] and math.isclose(eta, expect[2], rel_tol=1e-6)
    state = FAULT_HEALTH[kind]
    assert (rig.plant.fault_state == state).any() or (jet == 0 and (rig.plant.fault_state == NOMINAL).all())
    if jet:
        assert rig.plant.fault_state[jet - 1] == state


def test_injection_of_all_jets_reaches_every_jet(rig):
    assert rig.command("inject", "0", "failed_off") == ACCEPTED
    assert (rig.plant.fault_state == FAILED_OFF).all()


def test_invalid_injections_are_refused_never_forwarded(rig):
    inj = mav.MAV_CMD_INJECT_FAILURE
    unit, off, wrong = mav.FAILURE_UNIT_SYSTEM_MOTOR, mav.FAILURE_TYPE_OFF, mav.FAILURE_TYPE_WRONG
    cases = [
        ((unit, off, 19, 0), DENIED),                       # jet 19
        ((unit, off, -1, 0), DENIED),
        ((unit, off, 2.5, 0), DENIED),                      # not an integer
        ((unit, off, float("nan"), 0), DENIED),
        ((unit, wrong, 4, 0.0), DENIED),                    # eta <= 0
        ((unit, wrong, 4, 1.0), DENIED),                    # eta >= 1
        ((unit, wrong, 4, -0.3), DENIED),
        ((unit, wrong, 4, float("nan")), DENIED),
        ((unit, mav.FAILURE_TYPE_GARBAGE, 4, 0), UNSUPPORTED),   # type 3: unknown here
        ((unit, mav.FAILURE_TYPE_INTERMITTENT, 4, 0), UNSUPPORTED),
        ((unit, 99, 4, 0), UNSUPPORTED),
        ((mav.FAILURE_UNIT_SENSOR_GYRO, off, 4, 0), UNSUPPORTED),   # not an RCS jet
        ((100, off, 4, 0), UNSUPPORTED),
    ]
    for params, expect in cases:
        assert rig.raw_command(inj, *params) == expect, params
    assert rig.injected == []
    assert (rig.plant.fault_state == NOMINAL).all()
    texts = rig.texts()
    assert any("JET 19 DENIED" in t for t in texts)
    assert any("ETA" in t and "DENIED" in t for t in texts)
    assert any("TYPE 3 UNSUPPORTED" in t for t in texts)


def test_plant_unavailable_gives_temporarily_rejected_and_errors_are_mapped(tmp_path):
    def refusing(jet, kind, eta):
        raise ValueError("no such jet")

    def broken(jet, kind, eta):
        raise RuntimeError("zenoh closed")

    r = Rig(tmp_path)
    try:
        r.fly(2)
        r.inject_answer = False
        assert r.command("inject", "17", "failed_off") == mav.MAV_RESULT_TEMPORARILY_REJECTED
        r.gl.inject = refusing
        assert r.command("inject", "17", "failed_off") == DENIED
        r.gl.inject = broken
        assert r.command("inject", "17", "failed_off") == mav.MAV_RESULT_FAILED
        r.gl.inject = None
        assert r.command("inject", "17", "failed_off") == UNSUPPORTED
        assert (r.plant.fault_state == NOMINAL).all()
        assert any("PLANT UNAVAILABLE" in t for t in r.texts())
    finally:
        r.close()


# --------------------------------------------------------------------------- other commands

def test_mode_commands_follow_the_allowed_transitions(rig):
    assert rig.fsw.modes.mode == Mode.ENTRY
    assert rig.command("mode", "safe") == ACCEPTED and rig.fsw.modes.mode == Mode.SAFE
    assert rig.command("mode", "standby") == ACCEPTED and rig.fsw.modes.mode == Mode.STANDBY
    assert rig.command("mode", "safe") == DENIED and rig.fsw.modes.mode == Mode.STANDBY   # STANDBY -> SAFE not allowed
    assert rig.command("mode", "entry") == ACCEPTED and rig.fsw.modes.mode == Mode.ENTRY
    assert rig.raw_command(mav.ELLIPSLED_CMD_SET_MODE, 3) == DENIED
    assert rig.raw_command(mav.ELLIPSLED_CMD_SET_MODE, 1.5) == DENIED
    assert rig.fsw.modes.mode == Mode.ENTRY


def test_arm_disarm_and_the_standard_arm_command(rig):
    assert rig.fsw.driver.armed
    assert rig.command("arm", "off") == ACCEPTED and not rig.fsw.driver.armed
    rig.fly(5)
    assert not rig.fsw.driver.last_command.any()           # disarmed: nothing fires
    assert rig.raw_command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED and rig.fsw.driver.armed
    assert rig.raw_command(mav.ELLIPSLED_CMD_ARM_JETS, 2) == DENIED and rig.fsw.driver.armed


def test_fault_tolerance_on_off(rig):
    assert rig.command("ft", "off") == ACCEPTED
    assert rig.fsw.allocator.fault_tolerance is False and rig.fsw.params["allocator.fault_tolerance"] == 0.0
    assert rig.command("ft", "on") == ACCEPTED
    assert rig.fsw.allocator.fault_tolerance is True and rig.fsw.params["allocator.fault_tolerance"] == 1.0
    assert rig.raw_command(mav.ELLIPSLED_CMD_FAULT_TOLERANCE, 0.5) == DENIED


def test_fdir_mark_clear_and_delay(rig):
    fsw = rig.fsw
    assert rig.command("mark", "3", "degraded", "0.5") == ACCEPTED
    assert fsw.fdir.health_active.state[2] == DEGRADED and math.isclose(fsw.fdir.health_active.eta[2], 0.5)
    assert fsw.allocator._health.state[2] == DEGRADED            # the allocator adopted it at once
    assert rig.command("mark", "7", "failed") == ACCEPTED and fsw.fdir.health_active.state[6] == FAILED_OFF
    assert rig.command("mark", "8", "stuck_on") == ACCEPTED and fsw.fdir.health_active.state[7] == STUCK_ON
    assert rig.command("mark", "9", "inhibited") == ACCEPTED
    assert fsw.driver.inhibit[8] and fsw.fdir.health_active.inhibited[8]
    assert rig.command("mark", "3", "nominal") == ACCEPTED and fsw.fdir.health_active.state[2] == NOMINAL
    assert rig.command("clear", "0") == ACCEPTED
    assert (fsw.fdir.health_active.state == NOMINAL).all() and not fsw.driver.inhibit.any()
    assert (fsw.allocator._health.state == NOMINAL).all()
    # invalid marks
    mark = mav.ELLIPSLED_CMD_FDIR_MARK_JET
    assert rig.raw_command(mark, 19, 1, 1) == DENIED
    assert rig.raw_command(mark, 0, 1, 1) == DENIED                # mark needs one jet
    assert rig.raw_command(mark, 3, 3, 1.0) == DENIED              # degraded with eta 1
    assert rig.raw_command(mark, 3, 7, 1.0) == DENIED              # unknown health
    assert rig.raw_command(mav.ELLIPSLED_CMD_FDIR_CLEAR, 19) == DENIED
    # delay
    assert rig.command("delay", "1.5") == ACCEPTED and fsw.fdir.delay_s == 1.5 and fsw.params["fdir.delay_s"] == 1.5
    for bad in (-1.0, 61.0, float("nan"), float("inf")):
        assert rig.raw_command(mav.ELLIPSLED_CMD_FDIR_SET_DELAY, bad) == DENIED
    assert fsw.fdir.delay_s == 1.5
    texts = rig.texts()
    assert "GND MARK JET 3 DEGRADED ETA 0.50" in texts and "FDIR DELAY 1.50 S" in texts


def test_unknown_command_is_unsupported_and_other_targets_are_ignored(rig):
    assert rig.raw_command(12345) == UNSUPPORTED
    assert rig.raw_command(mav.MAV_CMD_NAV_TAKEOFF) == UNSUPPORTED
    # a command for system 7 gets no answer at all
    before = len(rig.gcs.state.acks)
    rig.gcs.send(mav.MAVLink_command_long_message(7, 1, mav.ELLIPSLED_CMD_ARM_JETS, 0, 0, 0, 0, 0, 0, 0, 0))
    rig.exchange(lambda: False, 0.2)
    assert len(rig.gcs.state.acks) == before and rig.fsw.driver.armed


def test_heartbeat_system_status_follows_mode_and_fdir(rig):
    def status():
        rig.gcs.state.latest.pop("HEARTBEAT", None)
        rig.clock.t += 1.0
        assert rig.exchange(lambda: "HEARTBEAT" in rig.gcs.state.latest)
        hb = rig.gcs.state.latest["HEARTBEAT"]
        return hb.system_status, hb.custom_mode, bool(hb.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)

    assert status() == (mav.MAV_STATE_ACTIVE, Mode.ENTRY, True)
    rig.command("mark", "4", "failed")
    assert status()[0] == mav.MAV_STATE_CRITICAL
    rig.command("mode", "safe")
    assert status()[:2] == (mav.MAV_STATE_EMERGENCY, Mode.SAFE)
    rig.command("clear", "0")
    rig.command("mode", "standby")
    rig.command("arm", "off")
    assert status() == (mav.MAV_STATE_STANDBY, Mode.STANDBY, False)


def test_fdir_detection_of_an_injected_failure_reaches_the_ground(rig):
    """End to end in one process: inject jet 17 failed_off from the ground, fly, FDIR declares it,
    its STATUSTEXT and the CRITICAL heartbeat come down."""
    assert rig.command("inject", "17", "failed_off") == ACCEPTED
    rig.fly(150)
    assert any(d["jet"] == 17 and d["kind"] == "failed_off" for d in rig.fsw.fdir.detections)
    texts = rig.texts()
    assert "JET 17 FAILED_OFF" in texts
    js = rig.gcs.state.latest["ELLIPSLED_JET_STATUS"]
    assert js.health[16] == mav.ELLIPSLED_JET_HEALTH_FAILED_OFF
    assert np.count_nonzero(np.array(js.health)) == 1


# --------------------------------------------------------------------------- failures inside the vehicle

def test_a_command_whose_handler_raises_is_answered_failed_with_a_statustext(rig, monkeypatch):
    def broken(on):
        raise RuntimeError("driver fault")
    monkeypatch.setattr(rig.fsw, "cmd_arm", broken)
    assert rig.command("arm", "off") == mav.MAV_RESULT_FAILED          # answered, not left to time out
    assert any("FAILED: RUNTIMEERROR" in t.upper() for t in rig.texts())
    assert rig.command("mode", "standby") == ACCEPTED                  # the link keeps working
    assert rig.fsw.modes.mode == Mode.STANDBY


def test_a_parameter_whose_owner_fails_keeps_its_value_and_says_so(rig, monkeypatch):
    def broken(name, value):
        raise RuntimeError("owner fault")
    monkeypatch.setitem(rig.fsw.registry._hooks, "fdir.stale_s", broken)
    before = rig.fsw.params["fdir.stale_s"]
    rig.gcs.start(make_request("param", "set", "F_STALE_S", "0.14"))
    assert rig.exchange(lambda: "F_STALE_S" in rig.gcs.state.params)
    assert rig.gcs.state.params["F_STALE_S"] == pytest.approx(before)  # echo (float32): the unchanged value
    assert rig.fsw.params["fdir.stale_s"] == before
    assert any("F_STALE_S FAILED: RuntimeError" in t for t in rig.texts())
