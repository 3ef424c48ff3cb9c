"""ELLIPSLED_GUIDANCE_STATUS over real signed UDP on loopback: in mode npc it carries the
flight software's own guidance figures (predicted deploy point, range to go, bank command,
reversals, the controllability LP's answer); in profile mode the npc fields say "not
available" (flag clear, value 0); a non-finite value never goes out; the stream has its
default rate and answers SET_MESSAGE_INTERVAL and REQUEST_MESSAGE like every other.

Independent truth: the plant's own latitude/longitude (range to go), great-circle
distances by the haversine formula written here, and a constructed geometry whose
downrange/crossrange split is known in closed form.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fsw.groundlink import telemetry as tm
from interfaces.mavlink import dialect as mav

from tests.rig import ACCEPTED, Rig

MSG = "ELLIPSLED_GUIDANCE_STATUS"
F = mav
FLOATS = ("target_lat", "target_lon", "range_to_go", "predicted_lat", "predicted_lon", "predicted_alt",
          "predicted_miss", "downrange_error", "crossrange_error", "time_to_go", "bank_0", "bank_cmd",
          "density_scale", "last_reversal_time", "authority_pos", "authority_neg", "bias", "trim_needed")


def haversine(lat1, lon1, lat2, lon2, R):
    a = math.sin((lat2 - lat1) / 2) ** 2 + math.cos(lat1) * math.cos(lat2) * math.sin((lon2 - lon1) / 2) ** 2
    return 2 * R * math.asin(math.sqrt(a))


def fresh(rig, after_t):
    """The first ELLIPSLED_GUIDANCE_STATUS sent after FSW time ``after_t`` [s]."""
    def got():
        m = rig.gcs.state.latest.get(MSG)
        return m is not None and m.time_boot_ms >= after_t * 1000.0 - 1
    rig.clock.t += 1.0
    assert rig.exchange(got, 3.0), "no fresh guidance status"
    return rig.gcs.state.latest[MSG]


@pytest.fixture(scope="module")
def guided(tmp_path_factory):
    r = Rig(tmp_path_factory.mktemp("guided"), scenario="guided-nominal")
    r.fly(200)                 # 4 s: corrections from the cycles at 0, 1, 2, 3 s applied
    yield r
    r.close()


def test_npc_status_carries_the_flight_softwares_own_guidance_figures(guided):
    rig = guided
    m = fresh(rig, rig.fsw.t_s)
    e, scn, R = rig.fsw.entry, rig.scn, rig.scn.planet.radius_m
    assert m.mode == F.ELLIPSLED_GUIDANCE_MODE_NPC
    assert m.flags & F.ELLIPSLED_GUIDANCE_FLAGS_TARGET and m.flags & F.ELLIPSLED_GUIDANCE_FLAGS_PREDICTION
    assert e.cycles >= 3 and m.cycles == e.cycles
    assert (m.target_lat, m.target_lon) == pytest.approx((scn.target_lat_rad, scn.target_lon_rad), abs=1e-7)
    # range to go from the navigation position: the plant's truth position within nav error
    truth = rig.plant.truth()
    rtg = haversine(truth["lat_rad"], truth["lon_rad"], scn.target_lat_rad, scn.target_lon_rad, R)
    assert m.range_to_go == pytest.approx(rtg, abs=1000.0)
    assert 500e3 < m.range_to_go < 2000e3
    # the predicted deploy point is the corrector's (float32 on the wire)
    assert (m.predicted_lat, m.predicted_lon) == pytest.approx(tuple(e.pred_impact), abs=2e-7)
    assert m.predicted_alt == pytest.approx(e.pred_h_m, rel=1e-6)
    assert m.time_to_go == pytest.approx(e.t_go_s, rel=1e-6)
    # phi_0 flown (the corrector's own parameter goes beyond the bounds when it holds one)
    assert m.bank_0 == pytest.approx(e.bank0_cmd, rel=1e-6) and e.bank_min_rad - 1e-6 <= m.bank_0 <= e.bank_max_rad + 1e-6
    assert m.bank_cmd == pytest.approx(e.bank_cmd, rel=1e-6) and 0.0 < m.bank_cmd < math.pi
    assert m.bank_sign == (1 if e.lateral.sign > 0 else -1)
    assert m.density_scale == pytest.approx(e.estimator.k_rho, rel=1e-6)
    miss = haversine(e.pred_impact[0], e.pred_impact[1], scn.target_lat_rad, scn.target_lon_rad, R)
    assert m.predicted_miss == pytest.approx(miss, abs=5.0)
    # the split is a decomposition of the miss (small angles: Pythagoras on the sphere)
    assert math.hypot(m.downrange_error, m.crossrange_error) == pytest.approx(m.predicted_miss, rel=0.02, abs=50.0)
    # no root / frozen flags follow the corrector's own criteria
    assert bool(m.flags & F.ELLIPSLED_GUIDANCE_FLAGS_NO_ROOT) == (abs(e.miss_m) > e.params["npc.tol_m"])
    assert not m.flags & F.ELLIPSLED_GUIDANCE_FLAGS_FROZEN
    # the same two figures as NAMED_VALUE_FLOAT, for stock ground stations (a tick apart)
    nv = rig.gcs.state.named
    assert nv["rtg_km"] == pytest.approx(m.range_to_go / 1e3, abs=2.0)
    assert nv["miss_km"] == pytest.approx(m.predicted_miss / 1e3, abs=0.5)
    lp = rig.fsw.controllability
    assert bool(m.flags & F.ELLIPSLED_GUIDANCE_FLAGS_LP) == (lp is not None)
    if lp is not None:
        assert m.authority_pos == pytest.approx(lp.authority_pos_radps2, rel=1e-6)
        assert m.authority_neg == pytest.approx(lp.authority_neg_radps2, rel=1e-6)
        assert bool(m.flags & F.ELLIPSLED_GUIDANCE_FLAGS_CONTROLLABLE) == lp.controllable


def test_a_reversal_decision_reaches_the_ground_with_its_time_and_rule(guided):
    rig = guided
    e = rig.fsw.entry
    before = fresh(rig, rig.fsw.t_s)
    n0, sign0 = before.reversals, before.bank_sign
    # the lateral logic decides a corridor reversal (heading error far outside the corridor
    # on the side the current sign turns away from)
    t = rig.fsw.t_s
    dpsi = 0.5 if e.lateral.sign > 0 else -0.5
    assert e.lateral.update(t, 7000.0, dpsi)
    rig.fly(10)
    m = fresh(rig, rig.fsw.t_s)
    assert m.reversals == n0 + 1 == len(e.lateral.reversals)
    assert m.last_reversal_time == pytest.approx(t, abs=1e-4)
    assert m.last_reversal_rule == F.ELLIPSLED_REVERSAL_RULE_CORRIDOR
    assert m.bank_sign == -sign0


def test_non_finite_values_never_go_out(guided):
    rig = guided
    e, fsw = rig.fsw.entry, rig.fsw
    auth = fsw.authority
    saved = (e.pred_h_m, e.bank_cmd, auth.controllability)
    try:
        e.pred_h_m = math.nan
        e.bank_cmd = math.inf
        if auth.controllability is not None:
            auth.controllability = dataclasses.replace(auth.controllability, authority_neg_radps2=math.nan,
                                                       trim_needed_deg=math.inf)
        m = fresh(rig, fsw.t_s)
    finally:
        e.pred_h_m, e.bank_cmd, auth.controllability = saved
    assert all(math.isfinite(getattr(m, f)) for f in FLOATS)
    assert not m.flags & (F.ELLIPSLED_GUIDANCE_FLAGS_PREDICTION | F.ELLIPSLED_GUIDANCE_FLAGS_LP
                          | F.ELLIPSLED_GUIDANCE_FLAGS_TRIM)
    assert m.predicted_alt == 0.0 and m.bank_cmd == 0.0 and m.authority_pos == 0.0
    assert m.flags & F.ELLIPSLED_GUIDANCE_FLAGS_TARGET          # unaffected groups still go out


def test_profile_mode_says_not_available(tmp_path):
    rig = Rig(tmp_path)                      # case1: the paper's profile, no target
    try:
        rig.fly(60)
        m = fresh(rig, rig.fsw.t_s)
        assert m.mode == F.ELLIPSLED_GUIDANCE_MODE_PROFILE
        assert not m.flags & (F.ELLIPSLED_GUIDANCE_FLAGS_TARGET | F.ELLIPSLED_GUIDANCE_FLAGS_PREDICTION
                              | F.ELLIPSLED_GUIDANCE_FLAGS_FINAL_REVERSAL)
        assert m.cycles == m.reversals == m.bank_sign == 0
        assert all(getattr(m, f) == 0.0 for f in FLOATS[:14])
        assert "rtg_km" not in rig.gcs.state.named and "miss_km" not in rig.gcs.state.named
        lp = rig.fsw.controllability
        assert bool(m.flags & F.ELLIPSLED_GUIDANCE_FLAGS_LP) == (lp is not None)
        # the default rate, then the interval and one-shot services like every stream
        n0 = rig.gcs.state.rx_counts.get(MSG, 0)
        rig.fly(250)                          # 5 s of flight at the fake clock
        rig.exchange(lambda: False, 0.2)
        assert 9 <= rig.gcs.state.rx_counts[MSG] - n0 <= 11            # 2 Hz
        mid = F.MAVLINK_MSG_ID_ELLIPSLED_GUIDANCE_STATUS
        assert rig.raw_command(F.MAV_CMD_SET_MESSAGE_INTERVAL, mid, 100_000, 0, 0, 0, 0, 0) == ACCEPTED
        n0 = rig.gcs.state.rx_counts[MSG]
        rig.fly(250)
        rig.exchange(lambda: False, 0.2)
        assert 48 <= rig.gcs.state.rx_counts[MSG] - n0 <= 52          # 10 Hz
        assert rig.raw_command(F.MAV_CMD_SET_MESSAGE_INTERVAL, mid, -1, 0, 0, 0, 0, 0) == ACCEPTED
        rig.fly(100)
        rig.exchange(lambda: False, 0.2)
        n0 = rig.gcs.state.rx_counts[MSG]
        assert rig.raw_command(F.MAV_CMD_REQUEST_MESSAGE, mid, 0, 0, 0, 0, 0, 0) == ACCEPTED
        rig.exchange(lambda: rig.gcs.state.rx_counts[MSG] > n0, 1.0)
        assert rig.gcs.state.rx_counts[MSG] == n0 + 1
    finally:
        rig.close()


def test_deploy_errors_split_a_known_geometry():
    """Vehicle on the equator at 0 deg heading east to a target at 10 deg E; a point 1 deg
    beyond the target and 0.5 deg north: 1 deg long, 0.5 deg left (negative: right is +)."""
    R = 3.3895e6
    d = math.radians
    miss, down, cross = tm.deploy_errors((0.0, 0.0), (0.0, d(10)), (d(0.5), d(11)), R)
    assert miss == pytest.approx(haversine(0.0, d(10), d(0.5), d(11), R), rel=1e-9)
    assert cross == pytest.approx(-d(0.5) * R, rel=1e-9)
    # along-track: the foot of the point on the equator, atan(tan(11 deg)/...) = 11 deg exactly
    assert down == pytest.approx(d(1.0) * R, rel=1e-9)
    # heading west of the target: the point short by 2 deg and 0.3 deg south, i.e. left
    miss, down, cross = tm.deploy_errors((0.0, d(20)), (0.0, d(10)), (d(-0.3), d(12)), R)
    assert down == pytest.approx(-d(2.0) * R, rel=1e-9)
    assert cross == pytest.approx(-d(0.3) * R, rel=1e-9)
    # on the target: no path, the whole miss is downrange
    assert tm.deploy_errors((0.1, 0.2), (0.1, 0.2), (0.1, 0.21), R)[1:] == pytest.approx(
        (haversine(0.1, 0.2, 0.1, 0.21, R), 0.0))


def test_the_fsw_state_record_carries_the_same_guidance_figures_through_the_codec(guided):
    """What the live bridge draws the map from (the FSW's output record FSW_STATE, filled by
    fsw/output.py) survives the codec (which refuses non-finite numbers) and equals the
    corrector's values; a non-finite predicted point goes out as 0 with its flag clear, never
    refused."""
    from fsw.output import OutputFiller
    from interfaces import codec, records
    e, fsw = guided.fsw.entry, guided.fsw
    c = codec.Codec.for_schema("FSW_STATE")
    filler = OutputFiller(fsw.scenario)
    filler.fill(fsw, fsw.driver.last_command)
    for name in records.FSW_STATE.names:                         # what the FSW filled at its last cycle
        if name not in records.FSW_STATE_SHELL:
            assert np.array_equal(filler.rec[name], fsw.output[name]), name
    got = c.decode(c.encode(fsw.output, 1, 0))
    assert got is not None and int(got["guid_cycles"]) == e.cycles
    assert int(got["guid_flags"]) == records.GUID_TARGET | records.GUID_PREDICTION | records.GUID_NPC
    assert (float(got["pred_lat_rad"]), float(got["pred_lon_rad"])) == tuple(e.pred_impact)
    assert float(got["bank_cmd_rad"]) == e.bank_cmd
    saved = e.pred_impact.copy()
    try:
        e.pred_impact[0] = math.nan
        filler.fill(fsw, fsw.driver.last_command)
    finally:
        e.pred_impact[:] = saved
    st = filler.rec
    assert not st["guid_flags"] & records.GUID_PREDICTION and st["pred_lat_rad"] == st["pred_lon_rad"] == 0.0
    assert c.decode(c.encode(st, 2, 0)) is not None
