"""Predictor-corrector entry guidance (fsw/guidance/, docs/fsw/entry-guidance.md), each piece
against independent truth: the plant's own trajectory, a known root, a scripted heading
history, a known density scale."""
from __future__ import annotations

import math

import numpy as np
import pytest

from common.model import load_scenario
from common.events import EventLog
from fsw.guidance import corrector, estimator, geometry, lateral, npc, predictor, shaper, trigger
from fsw.navigation import Navigation
from fsw.params import load_params
from sim.openloop import OMEGA_N_RADPS, ZETA, ideal_torque
from sim.dynamics import A_V
from sim.plant import Plant

# the plant flown open loop (no flight software to command the parachute) ends at the deploy Mach itself
SCN = load_scenario("guided-nominal").with_(deploy_by="plant")
PARAMS = load_params(npc.PARAMS)


def fly_plant(scn, bank_of_energy, every=None):
    """The plant flown open loop to its end condition with the attitude held (ideal torque)
    on bank_of_energy(e), e = mu/r - V^2/2 from the plant's own state. Returns the planet-fixed
    start state, its energy, the final truth, and the frames seen every ``every`` steps."""
    plant = Plant(scn)
    pl = scn.planet
    I = plant.inertia_truth_kgm2
    kp, kd = OMEGA_N_RADPS ** 2, 2 * ZETA * OMEGA_N_RADPS
    u, tau, C = np.zeros(18, np.uint8), np.zeros(3), np.zeros((3, 3))
    x0 = geometry.planet_fixed(plant.x[:3], plant.x[3:6], 0.0, pl.omega_radps)
    e0 = pl.mu_m3ps2 / np.linalg.norm(x0[:3]) - 0.5 * float(x0[3:] @ x0[3:])
    frames = []
    while True:
        a = plant.aux
        e = pl.mu_m3ps2 / np.linalg.norm(plant.x[:3]) - 0.5 * a[A_V] ** 2
        if every and plant.k % every == 0:
            frames.append((plant.t_s, plant.sensors.copy(), plant.truth()["rho_kgpm3"]))
        done, reason = plant.done()
        if done:
            break
        ideal_torque(plant.x, a, I, bank_of_energy(e), 0.0, 0.0, scn.vehicle.aero.alpha_trim_rad, kp, kd, C, tau)
        plant.step(u, tau)
    return x0, e0, plant.truth(), reason, frames


def test_predictor_matches_the_plant_flown_open_loop_with_the_same_bank_history():
    """Same start, same bank-versus-energy law, the true density scale: the predicted
    deploy point is within 1 % of the range flown of the plant's (and 2 % in time). What
    differs: the plant flies 6-DOF with alpha and beta excursions and lift slope, the
    predictor at trim."""
    b0, bf = math.radians(130.0), math.radians(PARAMS["npc.bank_final_deg"])
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    xs = geometry.planet_fixed(*_initial_state(), 0.0, SCN.planet.omega_radps)
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(xs[:3]) - 0.5 * float(xs[3:] @ xs[3:])
    x0, _, tr, reason, _ = fly_plant(SCN, lambda e: b0 + (bf - b0) * min(1.0, max(0.0, (e - e0) / (ef - e0))))
    assert reason == "mach"
    c = predictor.predictor_constants(SCN, PARAMS)
    c[predictor.C_KRHO] = SCN.truth.density_scale
    c[predictor.C_NLIM] = c[predictor.C_QLIM] = 0.0          # the plant flies the law without the path-limit feedback
    out = np.zeros(predictor.N_O)
    predictor.predict(x0, c, b0, bf, e0, ef, 1.0, PARAMS["npc.dt_pred_s"], out, 0.0)
    assert out[predictor.O_FLAG] == predictor.REACHED
    R = SCN.planet.radius_m
    plant_end = geometry.unit_from_latlon(tr["lat_rad"], tr["lon_rad"])
    flown = geometry.central_angle(x0[:3], plant_end) * R
    miss = geometry.central_angle(out[:3], plant_end) * R
    assert flown > 500e3
    assert miss < 0.01 * flown, (miss, flown)
    assert out[predictor.O_T] == pytest.approx(tr["t_s"], rel=0.02)
    assert out[predictor.O_H] == pytest.approx(tr["h_m"], abs=1500.0)
    # and a bank 10 deg off moves the prediction by much more than that error (the test can fail)
    predictor.predict(x0, c, b0 - math.radians(10.0), bf, e0, ef, 1.0, PARAMS["npc.dt_pred_s"], out, 0.0)
    assert geometry.central_angle(out[:3], plant_end) * R > 3 * miss


def test_root_finder_recovers_a_known_bank():
    """Fly the predictor at phi_0* = 120 deg, put the target where it ends, start the
    corrector at 70 deg (a skip-out there: the corrector must walk out of it): it must find
    phi_0* again."""
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    eg = npc.EntryGuidance(SCN, dict(PARAMS, **{"npc.max_iter": 20}), EventLog(), 0.02)
    try:
        x = geometry.planet_fixed(*_initial_state(), 0.0, SCN.planet.omega_radps)
        out = np.zeros(predictor.N_O)
        b_star = math.radians(120.0)
        e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
        predictor.predict(x, eg.constants, b_star, eg.bank_final_rad, e0, ef, 1.0, PARAMS["npc.dt_pred_s"], out, 0.0)
        r = out[:3] / np.linalg.norm(out[:3])
        eg.target_u = r
        eg.bank0 = math.radians(70.0)
        res = eg.solve(x, 1.0, 1.0, 1.0)
        assert res["ok"] and res["predictions"] <= 21
        assert math.degrees(res["bank0_rad"]) == pytest.approx(120.0, abs=0.2)
        assert abs(res["miss_m"]) <= PARAMS["npc.tol_m"]
    finally:
        eg.close()


def _initial_state():
    from sim.dynamics import initial_translation
    return initial_translation(SCN)


def test_secant_on_a_known_function_and_the_no_root_case():
    root = 0.7
    n_calls = []

    def z(x):
        n_calls.append(x)
        return math.atan(3.0 * (root - x)) * 1e4 + (root - x) ** 3 * 1e3   # monotonic, decreasing
    x, zx, n, ok = corrector.solve_bank(z, 0.1, 2.8, 2.0, tol=1e-3, max_iter=20)
    assert ok and x == pytest.approx(root, abs=1e-6) and n == len(n_calls) <= 12
    # no root inside: the bound nearest the root, flagged
    x, zx, n, ok = corrector.solve_bank(z, 1.0, 2.8, 2.0, tol=1e-3, max_iter=20)
    assert not ok and x == 1.0
    x, zx, n, ok = corrector.solve_bank(lambda v: -z(v), 0.1, 0.5, 0.3, tol=1e-3, max_iter=20)
    assert not ok and x == 0.5
    # no root on a flat z (short everywhere, 30 m across the whole range): the bound the secant
    # runs into is no better by the tolerance (200 m), so the warm start stays
    flat = []
    x, zx, n, ok = corrector.solve_bank(lambda v: flat.append(v) or -1000.0 + 10.0 * v, 0.0, 3.0, 0.5, tol=200.0,
                                        max_iter=8)
    assert not ok and x == 0.5 and zx == -995.0 and max(flat) == 3.0     # the bound was tried, not taken
    # a root inside, but z flat near the bound the warm start sits on, its slope there pointing
    # the secant out of the bounds (a bound held for nearly all the energy to go): the other
    # bound brackets it
    kink = 1.0 + 1001.0 / 1500.0

    def bent(v):
        return 1000.0 + v if v < 1.0 else 1001.0 - 1500.0 * (v - 1.0)
    x, zx, n, ok = corrector.solve_bank(bent, 0.0, 3.0, 0.0, tol=1.0, max_iter=20)
    assert ok and x == pytest.approx(kink, abs=1e-3) and abs(zx) <= 1.0


def test_reversal_logic_on_a_scripted_heading_history():
    p = dict(PARAMS, **{"npc.dpsi_hi_deg": 8.0, "npc.dpsi_lo_deg": 2.0, "npc.rev_gap_s": 20.0,
                        "npc.v_norev_mps": 800.0})
    lat = lateral.LateralLogic(p, v_hi_mps=7000.0, v_lo_mps=500.0, sign0=1.0)
    assert math.degrees(lat.corridor(7000.0)) == pytest.approx(8.0)
    assert math.degrees(lat.corridor(3750.0)) == pytest.approx(5.0)
    assert math.degrees(lat.corridor(100.0)) == pytest.approx(2.0)
    # (t, V, heading error deg): inside, out on + (reverse to -), out on - too soon, later
    # out on - (reverse to +), out on + below v_norev (hold)
    script = [(0, 7000, 3.0), (10, 6900, 7.9), (11, 6880, 8.1), (12, 6860, 9.0), (20, 6000, -7.5),
              (31, 5000, -6.5), (40, 4000, -3.0), (60, 2000, 3.0), (70, 1500, 3.2), (80, 700, -9.0)]
    seen = []
    for t, V, d in script:
        if lat.update(t, V, math.radians(d)):
            seen.append((t, lat.sign))
    # t=20: -7.5 beyond corridor(6000) = 7.08 wants + but only 9 s after the reversal at 11;
    # t=31: -6.5 beyond 6.15 (20 s later); t=60: 3.0 inside 3.38; t=70: 3.2 beyond 2.92;
    # t=80: beyond, but below v_norev
    assert seen == [(11, -1.0), (31, 1.0), (70, -1.0)]
    assert lat.reversals == [11, 31, 70]


def test_density_estimator_recovers_a_known_density_scale():
    """The plant with density x0.8 (and x1.25): the FSW's estimate from the sensed
    acceleration, its own navigation and its undispersed model converges to the scale
    once the drag is measurable, L/D to 1 (the plant flies at trim)."""
    for scale in (0.8, 1.25):
        scn = SCN.with_(truth=SCN.truth.__class__(**{**SCN.truth.__dict__, "density_scale": scale}),
                        max_duration_s=120.0)
        _, _, _, _, frames = fly_plant(scn, lambda e: math.radians(120.0), every=1)
        nav = Navigation(scn.planet, scn.vehicle)
        est = estimator.DensityEstimator(PARAMS, scn.vehicle.S_ref_m2, scn.vehicle.mass_kg, scn.vehicle.aero.C_L,
                                   scn.vehicle.aero.C_D)
        for t, f, _ in frames:
            n = nav.update(t, f["sigma_BN"], f["omega_BN_B"], f["r_N"], f["v_N"], f["accel_B"])
            est.update(scn.dt_control_s, n.accel_B, n.C_BN, n.vrel_N, n.rho_kgpm3)
        assert est.updates > 1000
        assert est.k_rho == pytest.approx(scale, rel=0.02), scale
        assert est.k_ld == pytest.approx(1.0, abs=0.05)


def test_shaper_respects_the_limits_and_reverses_the_shorter_way():
    dt, w, a = 0.02, math.radians(8.0), math.radians(1.0)
    sh = shaper.BankShaper(math.radians(60.0), w, a, dt)
    sh.command(math.radians(-60.0))          # 120 deg through 0 (lift up), not 240 through 180
    phis, rates, accs = [], [], []
    for k in range(3000):
        p, pd, pdd = sh.evaluate(k * dt)
        phis.append(p), rates.append(pd), accs.append(pdd)
    assert max(abs(r) for r in rates) <= w + 1e-9 and max(abs(x) for x in accs) <= a + 1e-9
    assert math.degrees(phis[-1]) == pytest.approx(-60.0, abs=0.05) and min(phis) > math.radians(-60.5)
    sh2 = shaper.BankShaper(math.radians(120.0), w, a, dt)
    sh2.command(math.radians(-120.0))        # above 90 deg the shorter way is through 180 (lift down)
    for k in range(3000):
        p, _, _ = sh2.evaluate(k * dt)
    assert math.degrees(p) == pytest.approx(240.0, abs=0.05)


def test_ellipse_of_a_known_normal_sample():
    from ellipsled.montecarlo.deploy import CHI2_2DOF_99, deploy_stats
    rng = np.random.default_rng(3)
    n = 20000
    down, cross = rng.normal(0.0, 2.0, n), rng.normal(0.0, 1.0, n)
    st = deploy_stats({"deploy_miss_km": np.hypot(down, cross), "downrange_err_km": down,
                       "crossrange_err_km": cross})
    assert st["ellipse99_major_km"] == pytest.approx(2 * 2.0 * math.sqrt(CHI2_2DOF_99), rel=0.03)
    assert st["ellipse99_minor_km"] == pytest.approx(2 * 1.0 * math.sqrt(CHI2_2DOF_99), rel=0.03)
    assert st["miss_p50_km"] == pytest.approx(np.median(np.hypot(down, cross)))


def test_a_run_that_never_deployed_is_listed_not_put_in_the_ellipse():
    """A skip-out's last point (2,900 km away) or a run that reached the end altitude first
    has miss figures but no deploy point: counted and named, kept out of the percentiles and
    the ellipse, and outside the requirement's share over all runs."""
    from ellipsled.montecarlo.deploy import deploy_stats
    rng = np.random.default_rng(4)
    n = 400
    down, cross = rng.normal(0.0, 2.0, n), rng.normal(0.0, 1.0, n)
    base = {"deploy_miss_km": np.hypot(down, cross), "downrange_err_km": down, "crossrange_err_km": cross,
            "end_reason": ["mach"] * n, "run_id": list(range(n))}
    ref = deploy_stats(base)
    rows = {k: list(v) for k, v in base.items()}
    for k, v in {"deploy_miss_km": [2926.8, 4.0], "downrange_err_km": [2900.0, 3.9], "crossrange_err_km": [390.0, 0.8],
                 "end_reason": ["timeout", "altitude"], "run_id": [n, n + 1]}.items():
        rows[k] += v
    st = deploy_stats(rows)
    assert st["with_deploy"] == n and st["runs"] == n + 2
    assert st["no_deploy"] == [{"run": n, "end_reason": "timeout"}, {"run": n + 1, "end_reason": "altitude"}]
    for k in ("ellipse99_major_km", "ellipse99_minor_km", "miss_p99_km", "within_msl_requirement"):
        assert st[k] == ref[k]
    assert st["within_msl_requirement_all"] == pytest.approx(ref["within_msl_requirement"] * n / (n + 2))


def test_guided_campaign_draws_entry_state_and_density_waves_and_keeps_the_default_draws():
    from ellipsled.montecarlo.campaign import apply_dispersion, draw_run, load_campaign
    from sim.dynamics import A_RHO, P_RHO_SCALE
    g = load_campaign("guided")
    base = load_scenario(g.scenario)
    seed, d = draw_run(g, base, 5)
    assert abs(d["speed_offset_mps"]) <= 20 and abs(d["heading_offset_deg"]) <= 0.1
    assert abs(d["north_offset_km"]) <= 5 and len(d["density_waves"]) == 9
    sc = apply_dispersion(base, d, seed, "r5")
    assert sc.speed_rel_mps == pytest.approx(7300.0 + d["speed_offset_mps"])
    # the plant's density is the model x scale x (1 + sum of the waves) at its altitude
    plant = Plant(sc)
    h = plant.aux[0]
    f = 1.0 + sum(a * math.sin(2 * math.pi * h / L + ph) for a, L, ph in sc.truth.density_waves)
    model = sc.planet.rho0_kgpm3 * math.exp(-h / sc.planet.scale_height_m)
    assert plant.aux[A_RHO] == pytest.approx(model * plant.p[P_RHO_SCALE] * f, rel=1e-12)
    # a campaign without the new ranges draws exactly what it drew before them
    dflt = load_campaign("default")
    _, d0 = draw_run(dflt, load_scenario("nominal"), 5)
    assert "density_waves" not in d0 and "speed_offset_mps" not in d0


def _state_heading_east(V=3000.0, h=30e3):
    """Planet-fixed state on the equator at longitude 0, heading east (level)."""
    R = SCN.planet.radius_m + h
    return np.array([R, 0.0, 0.0, 0.0, V, 0.0])


def test_corridor_reverses_on_a_constructed_heading_error_and_not_towards_the_target():
    """Heading east from (0, 0), the target at (+/-0.5 deg, 5 deg): its bearing by the
    spherical-trig formula is 90 -/+ 5.7 deg, outside a 4-deg corridor. Turning right
    (positive bank) with the target to the left must reverse; with the target to the
    right the same turn closes on it and must not."""
    p = dict(PARAMS, **{"npc.dpsi_hi_deg": 4.0, "npc.dpsi_lo_deg": 4.0, "npc.rev_gap_s": 20.0,
                        "npc.v_norev_mps": 0.0})
    x = _state_heading_east()
    for lat_t, want_rev in ((0.5, True), (-0.5, False)):
        lat2, lon2 = math.radians(lat_t), math.radians(5.0)
        bearing = math.atan2(math.sin(lon2) * math.cos(lat2), math.sin(lat2))     # from (0, 0)
        dpsi, _ = geometry.heading_error(x, geometry.unit_from_latlon(lat2, lon2))
        assert math.degrees(dpsi) == pytest.approx(90.0 - math.degrees(bearing), abs=1e-6)
        assert abs(math.degrees(dpsi)) > 5.0
        lat = lateral.LateralLogic(p, v_hi_mps=7000.0, v_lo_mps=500.0, sign0=1.0)
        assert lat.update(100.0, 3000.0, dpsi) is want_rev
        assert lat.sign == (-1.0 if want_rev else 1.0)
        assert lat.rules == (["corridor"] if want_rev else [])


def test_final_reversal_fires_when_a_reversal_nulls_the_predicted_deploy_crossrange():
    """Truth by construction: the target is the predictor's deploy point for phi_0 = 120 deg
    flown right (+) for 100 s, then left. Offered each second tau the crossranges of
    'keep right to the end' and 'reverse at tau' (the crossrange function against that
    target), the logic must reverse at tau = 100 s +- 1 s, by the final rule, never by the
    corridor (a heading error inside it)."""
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    x = geometry.planet_fixed(*_initial_state(), 0.0, SCN.planet.omega_radps)
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    c = predictor.predictor_constants(SCN, PARAMS)
    b0, bf, dt, R = math.radians(120.0), math.radians(PARAMS["npc.bank_final_deg"]), PARAMS["npc.dt_pred_s"], \
        SCN.planet.radius_m
    out = np.zeros(predictor.N_O)
    predictor.predict(x, c, b0, bf, e0, ef, -1.0, dt, out, 100.0)       # right (+) before 100 s, left after
    assert out[predictor.O_FLAG] == predictor.REACHED
    target = out[:3] / np.linalg.norm(out[:3])
    predictor.predict(x, c, b0, bf, e0, ef, 1.0, dt, out, 0.0)
    keep = geometry.crossrange(x[:3], target, out[:3], R)
    lat = lateral.LateralLogic(dict(PARAMS, **{"npc.v_norev_mps": 0.0}), 7300.0, 450.0, sign0=1.0)
    fired = None
    for tau in range(0, 200):
        predictor.predict(x, c, b0, bf, e0, ef, -1.0, dt, out, float(tau))
        rev = geometry.crossrange(x[:3], target, out[:3], R)
        if lat.update(float(tau), 5000.0, 0.0, keep, rev):
            fired = tau
            break
    assert keep < -10e3          # flown right all the way it ends well right of the target
    assert fired is not None and abs(fired - 100) <= 1, fired
    assert lat.rules == ["final"] and lat.sign == -1.0 and lat.final
    # after the final reversal the corridor is off; the prediction alone may reverse again
    assert not lat.update(300.0, 5000.0, math.radians(30.0))
    # and none when the reversal would not end before the deploy
    lat2 = lateral.LateralLogic(dict(PARAMS, **{"npc.v_norev_mps": 0.0}), 7300.0, 450.0, sign0=1.0)
    assert not lat2.update(100.0, 5000.0, 0.0, keep, -1.0, t_go_s=20.0, t_rev_s=15.0)
    assert lat2.update(100.0, 5000.0, 0.0, keep, -1.0, t_go_s=40.0, t_rev_s=15.0)


def test_a_correction_that_raises_keeps_the_command_and_never_stalls_the_run(monkeypatch):
    """The correction runs on a worker thread that batch and lockstep wait for: an exception
    there must come back as an event with the previous command kept, not as a silent thread
    death that leaves the control loop waiting for ever."""
    from ellipsled import batch

    def boom(self, *a, **k):
        raise FloatingPointError("injected")
    monkeypatch.setattr(npc.EntryGuidance, "solve", boom)
    s, h, fsw = batch.run("guided-nominal", duration_s=4.0)
    assert h["t_s"][-1] >= 3.9
    assert fsw.entry.faults >= 3 and fsw.entry.cycles == 0
    assert any(e.code == "guidance_fault" and "INJECTED" in e.text.upper() for e in fsw.events.history)
    assert np.all(np.isfinite(h["bank_ref_rad"]))


def test_shaped_transition_reverses_the_shorter_way_in_the_rest_to_rest_time():
    """The predictor's model of the reference: a reversal at 136 deg goes through 180 deg
    (lift down) and settles on -136 deg (224 on that branch) in the rest-to-rest time of the
    trapezoidal rate profile within the limits (closed form, BankShaper.transition_s), and
    with a switch at 5 s it holds 136 deg until then; below 90 deg it goes through 0."""
    dtc, w, a, ts = 0.02, math.radians(8.0), math.radians(0.5), 0.5
    sh = shaper.BankShaper(0.0, w, a, dtc)
    tab = np.zeros(shaper.N_TRANSITION)
    for phi0, t_switch in ((136.0, 0.0), (136.0, 5.0), (-40.0, 0.0)):
        b = math.radians(phi0)
        shp = np.array([b, 0.0, math.copysign(1.0, b), 0.0, w, a, dtc, abs(b)])
        n = shaper.shaped_transition(shp, b, t_switch, -b, ts, tab)
        path = np.degrees(tab[:n])
        swing = 2.0 * min(abs(b), math.pi - abs(b))
        assert (n - 1) * ts == pytest.approx(t_switch + sh.transition_s(swing), abs=1.5), phi0   # + the settling tail
        if phi0 > 90.0:
            assert path[-1] == pytest.approx(224.0, abs=0.1) and path.max() <= 224.5            # the discrete braking overshoots a little
        else:
            assert path[-1] == pytest.approx(-40.0 + 80.0, abs=0.1) and path.min() >= -40.5
        if t_switch:
            assert np.all(path[: int(t_switch / ts)] == pytest.approx(phi0))
        assert np.all(np.abs(np.diff(path)) <= math.degrees(w) * ts + 1e-6)        # the rate limit
    # settled on the command already: nothing to model
    shp = np.array([math.radians(70.0), 0.0, 1.0, 0.0, w, a, dtc, math.radians(70.0)])
    assert shaper.shaped_transition(shp, math.radians(70.0), 0.0, math.radians(70.0), ts, tab) == 1


def test_predicting_through_the_shaper_once_settled_is_the_law_and_a_slow_reversal_through_lift_down_costs_range():
    """From the entry state with the reference settled on the law's bank, predict_shaped is
    predict bit for bit. With the reference at -120 deg and the law +120 deg, the reversal
    goes through 180 deg at the shaper's pace: the slower the reversal (a lower acceleration
    limit, as the controllability LP gives a degraded vehicle), the longer the lift points
    down and the shorter the predicted range; with a fast shaper it approaches the instant
    reversal of predict."""
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    x = geometry.planet_fixed(*_initial_state(), 0.0, SCN.planet.omega_radps)
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    c = predictor.predictor_constants(SCN, PARAMS)
    b0, bf, dt = math.radians(120.0), math.radians(PARAMS["npc.bank_final_deg"]), PARAMS["npc.dt_pred_s"]
    ref, out = np.zeros(predictor.N_O), np.zeros(predictor.N_O)
    predictor.predict(x, c, b0, bf, e0, ef, 1.0, dt, ref, 0.0)
    predictor.predict_shaped(x, c, b0, bf, e0, ef, 1.0, dt, out, np.array([b0, 0.0, 1.0, 0.0, 0.1, 0.01, 0.02, b0]), 0.0)
    assert np.array_equal(out, ref, equal_nan=True)

    def range_km(accel_dps2):
        shp = np.array([-b0, 0.0, -1.0, 0.0, math.radians(8.0), math.radians(accel_dps2), 0.02, b0])
        predictor.predict_shaped(x, c, b0, bf, e0, ef, 1.0, dt, out, shp, 0.0)
        assert out[predictor.O_FLAG] == predictor.REACHED
        return geometry.central_angle(x[:3], out[:3]) * SCN.planet.radius_m / 1e3
    r_inst = geometry.central_angle(x[:3], ref[:3]) * SCN.planet.radius_m / 1e3
    r_slow, r_mid, r_fast = range_km(0.25), range_km(1.0), range_km(100.0)
    assert r_slow < r_mid < r_fast
    assert r_fast == pytest.approx(r_inst, abs=0.02 * r_inst)


def _answer(scn, params, x, target_u, bank0_rad, shp=None) -> tuple[dict, "npc.EntryGuidance"]:
    """The corrector's answer from the state x for the target target_u, first guess
    bank0_rad, and the guidance that gave it (closed; its attributes stay readable)."""
    eg = npc.EntryGuidance(scn, params, EventLog(), 0.02)
    try:
        eg.target_u = target_u
        eg.bank0 = bank0_rad
        return eg.solve(x, 1.0, 1.0, 1.0, shp=shp), eg
    finally:
        eg.close()


def test_deploy_altitude_floor_trades_range_for_altitude():
    """From the plant's state 90 s into an entry flown at 90 deg, a target that the range
    solution (phi_0 = 110 deg) reaches entering the deploy box at h_b: with the floor 300 m
    above h_b the corrector lifts up late, range kept (phi_f lowered, phi_0 solved again: more
    lift down before, the box entered at the floor), and with phi_f's lowest for that
    (npc.lift_final_min_deg) just below phi_f it trades range instead; with the floor 500 m above h_b, beyond
    what lifting up late reaches, it gives up range (more lift up: the deploy point long) for a
    predicted box-entry altitude at the floor (within the corrector's tolerance); with the
    floor below h_b the answer is the range solution; with the trade bounded, it stops at the bound. (From the entry interface the deploy altitude barely
    depends on phi_0 and not monotonically: there the floor is a best effort.)"""
    _, _, _, _, frames = fly_plant(SCN.with_(max_duration_s=95.0), lambda e: math.radians(90.0), every=200)
    t, f, _ = [fr for fr in frames if fr[0] >= 90.0][0]
    x = geometry.planet_fixed(f["r_N"], f["v_N"], t, SCN.planet.omega_radps)
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    out = np.zeros(predictor.N_O)
    base = dict(PARAMS, **{"npc.max_iter": 20, "npc.floor_miss_max_m": 1e7})     # unbounded here
    eg = npc.EntryGuidance(SCN, dict(base, **{"npc.h_floor_m": 0.0}), EventLog(), 0.02)
    try:
        predictor.predict(x, eg.constants, math.radians(110.0), eg.bank_final_rad, e0, ef, 1.0, PARAMS["npc.dt_pred_s"], out, 0.0)
    finally:
        eg.close()
    target = out[:3] / np.linalg.norm(out[:3])

    def solve(**over) -> tuple[dict, float]:
        """The corrector's answer from x for the target, first guess 100 deg, with these
        parameters over base; and the bank_final_rad it was configured with."""
        ans, eg = _answer(SCN, dict(base, **over), x, target, math.radians(100.0))
        return ans, eg.bank_final_rad

    free, _ = solve(**{"npc.h_floor_m": 0.0})
    assert free["ok"] and not free["floor"] and math.degrees(free["bank0_rad"]) == pytest.approx(110.0, abs=0.5)
    lift, bank_final_rad = solve(**{"npc.h_floor_m": free["h_box_m"] + 300.0})
    assert lift["ok"] and not lift["floor"] and abs(lift["miss_m"]) <= PARAMS["npc.tol_m"]      # range kept
    assert lift["h_box_m"] >= free["h_box_m"] + 300.0 - PARAMS["npc.tol_m"]
    assert lift["bank_final_rad"] == lift["f_family_rad"] < bank_final_rad                     # lift up late ...
    assert lift["bank0_rad"] > free["bank0_rad"]                                                # ... lift down before
    for floor_m, binds in ((free["h_box_m"] + 500.0, True), (free["h_box_m"] - 2000.0, False)):
        res, _ = solve(**{"npc.h_floor_m": floor_m})
        assert res["floor"] is binds
        if binds:
            assert res["h_box_m"] >= floor_m - PARAMS["npc.tol_m"]
            assert res["bank0_rad"] < free["bank0_rad"] and res["miss_m"] > 10e3         # long
            assert res["p_range_rad"] == pytest.approx(free["bank0_rad"], abs=1e-6)     # next cycle's warm start
            res_binds = res
        else:
            assert res["bank0_rad"] == free["bank0_rad"] and res["h_box_m"] == free["h_box_m"]
    # a trade bounded to half that miss: the floor gives up less (below the floor, within the bound)
    traded = res_binds["miss_m"]
    res, _ = solve(**{"npc.h_floor_m": free["h_box_m"] + 500.0, "npc.floor_miss_max_m": 0.5 * traded})
    assert res["h_box_m"] < free["h_box_m"] + 500.0 - PARAMS["npc.tol_m"]
    assert free["bank0_rad"] >= res["bank0_rad"] > res_binds["bank0_rad"] and abs(res["miss_m"]) <= 0.5 * traded
    assert res["floor"] == (res["bank0_rad"] < free["bank0_rad"])      # a trade is flagged; none is the range solution
    # the lift-up late lowers phi_f no further than npc.lift_final_min_deg (the lateral lift left at the
    # end): that bound just below phi_f, it has nothing to give, and the floor trades range instead
    assert lift["bank_final_rad"] >= math.radians(PARAMS["npc.lift_final_min_deg"])
    held, _ = solve(**{"npc.h_floor_m": free["h_box_m"] + 300.0,
                       "npc.lift_final_min_deg": math.degrees(bank_final_rad) - 0.1})
    assert held["floor"] and held["f_family_rad"] == bank_final_rad and held["miss_m"] > PARAMS["npc.tol_m"]
    assert held["h_box_m"] >= free["h_box_m"] + 300.0 - PARAMS["npc.tol_m"]


def test_deploy_altitude_floor_without_a_higher_deploy_keeps_the_range_solution():
    """From the plant's state 90 s into an entry flown at 90 deg, a target 8 km short of the
    shortest flight (the phi_0 bound, 120 deg here, held: no root, the range solution beyond
    the bound). With the floor above that deploy and a 2 km trade bound, every trade is
    refused (all miss by more): the answer is the range solution's held-bound flight, not the
    floor's line from the bound (a different flight: 61-104 km long in a dispersed run)."""
    _, _, _, _, frames = fly_plant(SCN.with_(max_duration_s=95.0), lambda e: math.radians(90.0), every=200)
    t, f, _ = [fr for fr in frames if fr[0] >= 90.0][0]
    x = geometry.planet_fixed(f["r_N"], f["v_N"], t, SCN.planet.omega_radps)
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    base = dict(PARAMS, **{"npc.max_iter": 20, "npc.bank_max_deg": 120.0, "npc.floor_miss_max_m": 2000.0})
    out = np.zeros(predictor.N_O)
    hi = math.radians(120.0)
    predictor.predict(x, predictor.predictor_constants(SCN, base), hi, hi, e0, ef, 1.0, PARAMS["npc.dt_pred_s"], out, 0.0)
    r_end = out[:3] / np.linalg.norm(out[:3])
    axis = np.cross(x[:3], r_end)
    axis /= np.linalg.norm(axis)
    ang = -8e3 / SCN.planet.radius_m
    target = r_end * math.cos(ang) + np.cross(axis, r_end) * math.sin(ang)
    res = {}
    for name, h_floor in (("free", 0.0), ("floor", None)):
        eg = npc.EntryGuidance(SCN, dict(base, **{"npc.h_floor_m": 0.0}), EventLog(), 0.02)
        try:
            eg.target_u = target
            eg.bank0 = math.radians(100.0)
            if h_floor is None:
                eg.params["npc.h_floor_m"] = res["free"]["h_box_m"] + 500.0
            res[name] = eg.solve(x, 1.0, 1.0, 1.0)
        finally:
            eg.close()
    free, fl = res["free"], res["floor"]
    assert not free["ok"] and free["held"] and free["miss_m"] > 5e3       # beyond the bound, long
    assert not fl["floor"] and fl["held"]
    for k in ("bank0_rad", "bank_line_rad", "bank_final_rad", "miss_m", "h_final_m"):
        assert fl[k] == free[k], k


def test_final_reversal_at_the_cycle_nearest_the_crossing():
    """A scripted 'reverse now' crossrange crossing zero between two cycles: the logic reverses
    at the cycle on the nearer side, before the crossing when waiting would overshoot more."""
    p = dict(PARAMS, **{"npc.v_norev_mps": 0.0})
    for before, after, want in ((-0.3e3, 0.9e3, 10), (-0.9e3, 0.3e3, 11)):
        lat = lateral.LateralLogic(p, 7300.0, 450.0, sign0=1.0)
        xr = {9: before - 1.2e3, 10: before, 11: after}
        fired = [t for t in range(9, 12) if lat.update(float(t), 5000.0, 0.0, 20e3, xr[t])]
        assert fired == [want] and lat.rules == ["final"]


def test_final_reversal_waits_until_the_held_pair_is_due_too():
    """Scripted pairs, 'keep' 20 km left each cycle (the sign pushes left). The re-solved
    'reverse now' crossrange crosses to +0.3 km at cycle 10 (due: even reversing leaves the
    deploy on the pushed side), while the held pair's (this magnitude, an instant flip) still
    overshoots to -30 km and closes 10 km a cycle: no final reversal until the held pair is due
    too (cycle 13, +0.5 km), and the corridor stays on meanwhile (a heading error beyond it at
    cycle 11 reverses by the corridor). Without the held pair (NaN) the re-solved pair alone
    decides, at cycle 10."""
    p = dict(PARAMS, **{"npc.v_norev_mps": 0.0})
    rev = {t: 0.3e3 + 0.1e3 * (t - 10) for t in range(9, 15)}
    rev[9] = -0.9e3
    held = {9: -39.5e3, 10: -29.5e3, 11: -19.5e3, 12: -9.5e3, 13: 0.5e3, 14: 10.5e3}
    lat = lateral.LateralLogic(p, 7300.0, 450.0, sign0=1.0)
    fired = [t for t in range(9, 15) if lat.update(float(t), 5000.0, 0.0, 20e3, rev[t], math.inf, 0.0, 20e3, held[t])]
    assert fired == [13] and lat.rules == ["final"]
    lat = lateral.LateralLogic(p, 7300.0, 450.0, sign0=1.0)
    assert lat.update(10.0, 5000.0, 0.0, 20e3, rev[10], math.inf, 0.0, 20e3, held[10]) is False
    assert lat.update(11.0, 5000.0, math.radians(30.0), 20e3, rev[11], math.inf, 0.0, 20e3, held[11])
    assert lat.rules == ["corridor"] and not lat.final
    lat = lateral.LateralLogic(p, 7300.0, 450.0, sign0=1.0)
    assert [t for t in range(9, 15) if lat.update(float(t), 5000.0, 0.0, 20e3, rev[t])] == [10]


def _held_profile(p, lo, hi, f, frac):
    """The corrector's family written out independently: inside the bounds the line from p to
    f; beyond hi, hi held for the fraction k = (p - hi) / (hi - f) of the energy span, then a
    line from hi to f (below lo likewise)."""
    if lo <= p <= hi:
        return p + (f - p) * frac
    bound, k = (hi, (p - hi) / (hi - f)) if p > hi else (lo, (lo - p) / (f - lo))
    return bound if frac <= k else bound + (f - bound) * (frac - k) / (1.0 - k)


def test_corrector_family_holds_a_bound_and_the_next_cycle_finds_the_same_profile():
    """bank_profile's line clipped to the bounds (as the predictor and steer fly it) is the
    held-bound profile written out independently; it is continuous at the bounds and the
    bank rises with p at every energy (more lift down); profile_at re-anchors a profile at a
    later energy into the parameter whose profile is the remainder of the same one."""
    lo, hi, f = math.radians(10.0), math.radians(165.0), math.radians(60.0)
    p_lo, p_hi = corrector.profile_span(lo, hi, f)
    assert (p_lo, p_hi) == pytest.approx((lo - (f - lo), hi + (hi - f)))
    fracs = np.linspace(0.0, 0.99, 34)       # (a bound held "to the end" leaves it in the last 1e-6)

    def flown(p, fr):
        b0, bf = corrector.bank_profile(p, lo, hi, f)
        return min(hi, max(lo, b0 + (bf - b0) * fr))
    ps = np.linspace(p_lo + 1e-3, p_hi - 1e-3, 301)
    for p in ps:
        for fr in fracs:
            assert flown(p, fr) == pytest.approx(_held_profile(p, lo, hi, f, fr), abs=1e-9)
    prof = np.array([[flown(p, fr) for fr in fracs] for p in ps])
    assert np.all(np.diff(prof, axis=0) >= -1e-12)                      # monotonic in p
    for b in (lo, hi):                                                    # continuous at the bounds
        assert [flown(b + 1e-9, fr) for fr in fracs] == pytest.approx([flown(b - 1e-9, fr) for fr in fracs], abs=1e-7)
    assert [flown(p_hi, fr) for fr in fracs] == pytest.approx([hi] * len(fracs))   # held to the end
    for p in (math.radians(40.0), math.radians(120.0), p_hi - math.radians(30.0), p_lo + math.radians(20.0)):
        for a in (0.1, 0.4, 0.8):
            q = corrector.profile_at(p, lo, hi, f, a)
            for g in np.linspace(0.0, 1.0, 11):
                assert flown(q, g) == pytest.approx(_held_profile(p, lo, hi, f, a + g * (1.0 - a)), abs=1e-9)


def test_corrector_answers_a_target_only_a_held_bound_reaches():
    """A target where a constant bank at the phi_0 bound (110 deg here: more, held from the
    entry interface, dives into the ground) deploys: the line from 110 deg to phi_f = 60 deg
    flies ~400 km long, so the plain family has no root; the answer holds the bound to
    (nearly) the end and its prediction lands on the target (the deploy-altitude floor off:
    this dive deploys at 1.5 km)."""
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    x = geometry.planet_fixed(*_initial_state(), 0.0, SCN.planet.omega_radps)
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    p = dict(PARAMS, **{"npc.max_iter": 20, "npc.bank_max_deg": 110.0, "npc.h_floor_m": 0.0})
    eg = npc.EntryGuidance(SCN, p, EventLog(), 0.02)
    try:
        hi, dt = eg.bank_max_rad, PARAMS["npc.dt_pred_s"]
        out = np.zeros(predictor.N_O)
        predictor.predict(x, eg.constants, hi, hi, e0, ef, 1.0, dt, out, 0.0)
        assert out[predictor.O_FLAG] == predictor.REACHED
        eg.target_u = out[:3] / np.linalg.norm(out[:3])
        s_togo = geometry.central_angle(x[:3], eg.target_u) * eg.radius_m
        predictor.predict(x, eg.constants, hi, eg.bank_final_rad, e0, ef, 1.0, dt, out, 0.0)
        assert geometry.central_angle(x[:3], out[:3]) * eg.radius_m - s_togo > 200e3     # the plain family's best: long
        eg.bank0 = math.radians(120.0)
        res = eg.solve(x, 1.0, 1.0, 1.0)
    finally:
        eg.close()
    assert res["ok"] and res["held"] and abs(res["miss_m"]) <= PARAMS["npc.tol_m"]
    assert res["bank0_rad"] == pytest.approx(hi)
    assert res["p_range_rad"] > eg.p_max_rad - math.radians(10.0)                 # held for most of the energy to go


def test_guided_nominal_flies_what_it_predicted_after_the_final_reversal():
    """guided-nominal in batch, the plant the truth: from the first answer after the final
    reversal to the freeze, every predicted deploy point the FSW published is within 150 m of
    where the vehicle deployed. (When each cycle's phi_0 was held for the cycle and pinned at
    its bound while the prediction had the bank leave it, the prediction drifted by 1 km:
    the flown deploy was 1.1 km across from the one predicted after the reversal.) The floor's
    margin held at its minimum (a range traded for altitude is a prediction past the target by
    design, not a prediction error) and the velocity trigger at the predictor's deploy Mach (the
    range trigger deploys where the target is reached, not where the prediction ends)."""
    from ellipsled import batch
    scn = load_scenario("guided-nominal")
    fsw_over = {**scn.fsw, "npc": {**scn.fsw.get("npc", {}), "floor_margin_max_m": PARAMS["npc.floor_margin_min_m"]},
                "deploy": {"trigger": "velocity", "mach": scn.end_mach}}
    s, h, fsw = batch.run(scn.with_(fsw=fsw_over), reference=False)
    assert s["end_reason"] == "deploy" and s["guidance"]["reversal_rules"][-1] == "final"
    t = np.asarray(h["t_s"])
    t_rev = s["guidance"]["reversal_times_s"][-1]
    t_freeze = t[-1] - PARAMS["npc.tgo_freeze_s"]
    sel = (t >= t_rev + 1.0) & (t <= t_freeze)
    assert sel.sum() > 30 * 50
    R = SCN.planet.radius_m
    end = geometry.unit_from_latlon(float(h["lat_rad"][-1]), float(h["lon_rad"][-1]))
    d = [geometry.central_angle(geometry.unit_from_latlon(a, b), end) * R
         for a, b in zip(np.asarray(h["pred_lat_rad"])[sel][::50], np.asarray(h["pred_lon_rad"])[sel][::50])]
    assert max(d) < 150.0, max(d)
    assert s["deploy_miss_km"] <= 1.0


def test_a_reversal_turns_round_only_when_the_other_way_is_the_shorter():
    """reversal_other_way on constructed shaper states (hand-worked angles): a reversal begun
    at -92 deg through 180 deg (target +10 deg on that way: -350 deg, 258 deg on) may turn
    round through 0 deg (102 deg, plus braking v^2/a when moving away from it); not when the
    magnitude commanded keeps the way it began the shorter one, not once the reference is
    on the commanded side, not when the braking makes the other way longer. The shaper's
    transition flown with the other way goes back through 0 deg to +10 deg."""
    d = math.radians
    a, rate = d(1.0), d(8.0)

    def shp(phi, phid, mag, turn, sign=1.0):
        return np.array([d(phi), d(phid), sign, turn, rate, a, 0.02, d(mag)])
    s0 = shp(-92.0, -2.0, 10.0, -2.0 * math.pi)           # on its way to -350 deg
    alt = shaper.reversal_other_way(s0, 1.0)
    assert alt is not None and alt[3] == pytest.approx(0.0, abs=1e-12) and alt[2] == 1.0
    assert np.array_equal(np.delete(alt, 3), np.delete(s0, 3))
    assert shaper.reversal_other_way(shp(-92.0, -2.0, 92.0, -2.0 * math.pi), 1.0) is None    # 176 < 184 deg
    assert shaper.reversal_other_way(shp(20.0, 2.0, 10.0, 0.0), 1.0) is None                   # on the + side
    # moving at 8 deg/s towards -180: 64 deg of braking. From -92: 102 + 64 < 258; from -150:
    # 160 + 64 > 200
    assert shaper.reversal_other_way(shp(-92.0, -8.0, 10.0, -2.0 * math.pi), 1.0) is not None
    assert shaper.reversal_other_way(shp(-150.0, -8.0, 10.0, -2.0 * math.pi), 1.0) is None
    # a reversal begun at +70 deg through 0 deg, then 165 deg commanded: -165 deg is 235 deg on,
    # +195 deg is 125 deg back (plus 4 deg of braking): it may turn round through 180 deg
    back = shaper.reversal_other_way(shp(70.0, -2.0, 165.0, 0.0, -1.0), -1.0)
    assert back is not None and back[3] == pytest.approx(2.0 * math.pi, abs=1e-12)
    tab = np.empty(shaper.N_TRANSITION)
    n = shaper.shaped_transition(alt, d(10.0), 0.0, d(10.0), 0.5, tab)
    path = np.degrees(tab[:n])
    assert path.min() >= -92.0 - 2.0 ** 2 / 2.0 - 1e-6               # brakes within v^2/2a
    assert path[-1] == pytest.approx(10.0, abs=0.1) and path.max() < 10.5           # back through 0 deg
    assert np.all(np.diff(path[np.argmin(path):np.argmax(path) + 1]) >= 0.0)
    n0 = shaper.shaped_transition(s0, d(10.0), 0.0, d(10.0), 0.5, tab)
    assert np.degrees(tab[n0 - 1]) == pytest.approx(-350.0, abs=0.1)   # the way it began


def test_predicted_box_entry_is_where_a_prediction_to_the_box_mach_ends():
    """O_H_BOX, the altitude where the deploy box is entered (the highest the trigger can
    deploy), against its independent truth: the same prediction ended at the box's Mach
    maximum instead of the deploy Mach (the box's dynamic-pressure maximum not binding there
    in the nominal atmosphere). Without a box the final altitude."""
    box = SCN.vehicle.deploy_box
    x0 = geometry.planet_fixed(*_initial_state(), 0.0, SCN.planet.omega_radps)
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x0[:3]) - 0.5 * float(x0[3:] @ x0[3:])
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    c = predictor.predictor_constants(SCN, PARAMS)
    b, bf = math.radians(150.0), math.radians(60.0)      # about guided-nominal's solution
    out, ref = np.zeros(predictor.N_O), np.zeros(predictor.N_O)
    predictor.predict(x0, c, b, bf, e0, ef, 1.0, 0.5, out, 0.0)
    c_box = c.copy()
    c_box[predictor.C_MACH_F] = box.mach_max
    predictor.predict(x0, c_box, b, bf, e0, ef, 1.0, 0.5, ref, 0.0)
    assert out[predictor.O_FLAG] == ref[predictor.O_FLAG] == predictor.REACHED
    assert out[predictor.O_H_BOX] == pytest.approx(ref[predictor.O_H], abs=50.0)
    assert out[predictor.O_H_BOX] > out[predictor.O_H] + 500.0       # the box entered above the deploy Mach
    c[predictor.C_BOX_MACH] = 0.0
    predictor.predict(x0, c, b, bf, e0, ef, 1.0, 0.5, out, 0.0)
    assert out[predictor.O_H_BOX] == out[predictor.O_H]


def test_floor_margin_carries_a_falling_prediction_over_the_cycles_to_go():
    """The floor's margin from the measured change of the predicted box-entry altitude: a
    prediction that falls 30 m every cycle with 100 cycles to go is a bias worth about 3 km
    (n times the drift), not the random walk's 300 m (sqrt(n) times); noise of the same RMS
    about a zero mean stays about the random walk; a rising prediction needs no margin."""
    p = dict(PARAMS, **{"npc.floor_margin_k": 1.0, "npc.floor_margin_min_m": 0.0, "npc.floor_margin_max_m": 1e4})
    margins = {}
    for name, step in (("falling", lambda i: -30.0), ("noise", lambda i: 30.0 * (-1) ** i), ("rising", lambda i: 30.0)):
        eg = npc.EntryGuidance(SCN, p, EventLog(), 0.02)
        try:
            h = 9000.0
            for i in range(200):
                h += step(i)
                eg._measure_prediction(h, 100.0)
            margins[name] = eg.floor_margin_m
        finally:
            eg.close()
    assert margins["falling"] == pytest.approx(3000.0, rel=0.05)
    assert 300.0 - 15.0 <= margins["noise"] <= 400.0      # the low-passed mean of +-30 m still wobbles a little
    assert margins["rising"] < 10.0



def _correction(t_s, sign, h_box_m, turn_rad=math.nan):
    """A corrector's answer (Correction) with only what EntryGuidance._apply reads."""
    return dict(t_s=t_s, sign=sign, predictions=3, compute_ns=0, bank0_rad=1.0, miss_m=0.0, p_range_rad=1.0,
                e0_jpkg=math.nan, f_family_rad=1.0, bank_line_rad=1.0, bank_final_rad=1.0, floor=False, held=False,
                ok=True, lat_rad=0.0, lon_rad=0.0, h_final_m=h_box_m - 1500.0, h_box_m=h_box_m, t_go_s=100.0,
                turn_rad=turn_rad, xr_keep_m=math.nan, xr_rev_m=math.nan, xr_keep_held_m=math.nan,
                xr_rev_held_m=math.nan)


def test_floor_margin_does_not_count_a_reversal_as_prediction_error():
    """The margin measures what a prediction failed to foresee. A prediction steady to 10 m a
    cycle, then a drop of 2.5 km: made by the answer for the other bank sign (a reversal, which
    through lift down does deploy lower) or by a reversal turned round, the margin stays what
    the steady part gives; the same drop with the sign and the way kept is an error, and the
    margin grows by about its share (sqrt(0.2) x 2.5 km x sqrt(100 cycles to go), clipped)."""
    p = dict(PARAMS, **{"npc.floor_margin_k": 1.0, "npc.floor_margin_min_m": 0.0, "npc.floor_margin_max_m": 1e5})
    margins = {}
    for case in ("steady", "reversed", "turned", "kept"):
        eg = npc.EntryGuidance(SCN, p, EventLog(), 0.02)
        try:
            h = 12000.0
            for i in range(60):
                h += 10.0 * (-1) ** i
                eg._apply(_correction(float(i), 1.0, h))
            if case != "steady":
                sign = -1.0 if case == "reversed" else 1.0
                turn = 0.5 if case == "turned" else math.nan
                eg._apply(_correction(60.0, sign, h - 2500.0, turn))
                eg._apply(_correction(61.0, sign, h - 2510.0))
            margins[case] = eg.floor_margin_m
        finally:
            eg.close()
    assert margins["steady"] < 200.0
    assert margins["reversed"] < 200.0 and margins["turned"] < 200.0
    assert margins["kept"] > 5000.0

def _unit(res):
    """The predicted deploy point of a corrector's answer, a unit vector (planet-fixed)."""
    return geometry.unit_from_latlon(res["lat_rad"], res["lon_rad"])


def test_range_trigger_aims_the_deploy_point_the_reserve_beyond_the_target():
    """The same oracle as the root-finder's: the predictor flown at phi_0* = 120 deg ends at a
    point P. The target put 2 km short of P along the track: with the range trigger and a 2 km
    reserve the corrector's answer is phi_0* again (its deploy point P, 2 km beyond the
    target); with the velocity trigger (no reserve) it flies 2 km shorter (more bank); and a
    flight software that leaves the deploy to the plant aims at the target too."""
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    x = geometry.planet_fixed(*_initial_state(), 0.0, SCN.planet.omega_radps)
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    out = np.zeros(predictor.N_O)
    c = predictor.predictor_constants(SCN, PARAMS)
    b_star = math.radians(120.0)
    predictor.predict(x, c, b_star, math.radians(PARAMS["npc.bank_final_deg"]), e0, ef, 1.0, PARAMS["npc.dt_pred_s"],
                      out, 0.0)
    end_u = out[:3] / np.linalg.norm(out[:3])
    axis = np.cross(x[:3], end_u)
    axis /= np.linalg.norm(axis)
    ang = -2e3 / SCN.planet.radius_m              # 2 km back along the great circle from x through P
    target = end_u * math.cos(ang) + np.cross(axis, end_u) * math.sin(ang)
    base = dict(PARAMS, **{"npc.max_iter": 20, "npc.h_floor_m": 0.0, "npc.range_reserve_m": 2000.0,
                           "npc.tol_m": 50.0})
    fsw_scn = SCN.with_(deploy_by="fsw")

    def answer(scn, trigger):
        ans, eg = _answer(scn, dict(base, **{"deploy.trigger": trigger}), x, target, math.radians(100.0))
        return ans, eg.reserve_m

    rng, reserve = answer(fsw_scn, "range")
    assert reserve == 2000.0 and rng["ok"]
    assert math.degrees(rng["bank0_rad"]) == pytest.approx(120.0, abs=0.3)
    past = geometry.central_angle(x[:3], _unit(rng)) * SCN.planet.radius_m - rng["range_to_go_m"]
    assert past == pytest.approx(2000.0, abs=base["npc.tol_m"])         # the deploy point 2 km beyond the target
    assert rng["range_to_go_m"] == pytest.approx(geometry.central_angle(x[:3], target) * SCN.planet.radius_m)
    for scn, trigger in ((fsw_scn, "velocity"), (SCN, "range")):
        res, reserve = answer(scn, trigger)
        assert reserve == 0.0 and res["ok"] and res["bank0_rad"] > rng["bank0_rad"] + math.radians(0.2)
        assert geometry.central_angle(x[:3], _unit(res)) * SCN.planet.radius_m - res["range_to_go_m"] == pytest.approx(
            0.0, abs=base["npc.tol_m"])


def test_range_trigger_turns_a_reversal_round_that_leaves_the_vehicle_short_of_the_target():
    """From the plant's state 180 s into an entry flown at 90 deg, a reversal under way through
    lift down (begun at -92 deg, now -100 deg, 10 deg commanded: 250 deg on, 110 deg back
    through lift up). The predictor is the oracle: flown at the lower bound (the most range)
    the way it goes, it ends R_cur from the vehicle, and the other way much further. With the
    range trigger (2 km reserve) and the target 1 km beyond R_cur, the way it goes falls 3 km
    short of the aim point, 1 km short of the target itself: the corrector turns it round and
    solves the range the other way. With the target 1 km short of R_cur (the vehicle short of
    the aim point only, by 1 km), or with the velocity trigger (no reserve: 1 km short, within
    the range the guidance trades), the reversal keeps its way."""
    _, _, _, _, frames = fly_plant(SCN.with_(max_duration_s=185.0), lambda e: math.radians(90.0), every=200)
    t, f, _ = [fr for fr in frames if fr[0] >= 180.0][0]
    x = geometry.planet_fixed(f["r_N"], f["v_N"], t, SCN.planet.omega_radps)
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    d = math.radians
    shp = np.array([d(-100.0), d(-2.0), 1.0, -2.0 * math.pi, d(8.0), d(1.0), 0.02, d(10.0)])
    alt = shaper.reversal_other_way(shp, 1.0)
    assert alt is not None
    base = dict(PARAMS, **{"npc.max_iter": 20, "npc.h_floor_m": 0.0, "npc.range_reserve_m": 2000.0})
    c = predictor.predictor_constants(SCN, base)
    lo, out = d(base["npc.bank_min_deg"]), np.zeros(predictor.N_O)
    reach = []
    for s in (shp, alt):
        predictor.predict_shaped(x, c, lo, lo, e0, ef, 1.0, base["npc.dt_pred_s"], out, s, 0.0)
        assert out[predictor.O_FLAG] == predictor.REACHED
        reach.append((geometry.central_angle(x[:3], out[:3]) * SCN.planet.radius_m, out[:3] / np.linalg.norm(out[:3])))
    (r_cur, end_u), (r_alt, _) = reach
    assert r_alt > r_cur + 20e3                      # the other way reaches much further
    x_u = x[:3] / np.linalg.norm(x[:3])
    axis = np.cross(x_u, end_u)
    axis /= np.linalg.norm(axis)

    def answer(beyond_m, scn, trigger):
        ang = (r_cur + beyond_m) / SCN.planet.radius_m
        return _answer(scn, dict(base, **{"deploy.trigger": trigger}), x,
                       x_u * math.cos(ang) + np.cross(axis, x_u) * math.sin(ang), d(60.0), shp=shp.copy())[0]

    fsw_scn = SCN.with_(deploy_by="fsw")
    turned = answer(1000.0, fsw_scn, "range")
    assert turned["turn_rad"] == pytest.approx(0.0, abs=1e-12)            # the other way round: back through 0
    assert turned["ok"] and abs(turned["miss_m"]) <= base["npc.tol_m"]
    for beyond_m, scn, trigger in ((-1000.0, fsw_scn, "range"), (1000.0, fsw_scn, "velocity")):
        kept = answer(beyond_m, scn, trigger)
        assert math.isnan(kept["turn_rad"]) and not kept["ok"]
        assert kept["miss_m"] == pytest.approx(-1000.0, abs=base["npc.tol_m"])      # 1 km short of its aim


def _abeam_case():
    """A prediction (120 deg to phi_f 60 deg from the entry interface) and its independent truth:
    P, where the same prediction ended at Mach 2.15 (inside the deploy box) ends, and a target
    1 km left of the track at P (the vehicle passes it abeam at P, 1 km to its right)."""
    x0 = geometry.planet_fixed(*_initial_state(), 0.0, SCN.planet.omega_radps)
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x0[:3]) - 0.5 * float(x0[3:] @ x0[3:])
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    c = predictor.predictor_constants(SCN.with_(deploy_by="fsw"), dict(PARAMS, **{"deploy.trigger": "range"}))
    b, bf = math.radians(120.0), math.radians(60.0)
    end, at = np.zeros(predictor.N_O), np.zeros(predictor.N_O)
    predictor.predict(x0, c, b, bf, e0, ef, 1.0, 0.5, end, 0.0)
    c_p = c.copy()
    c_p[predictor.C_MACH_F] = 2.15
    predictor.predict(x0, c_p, b, bf, e0, ef, 1.0, 0.5, at, 0.0)
    P, E = at[:3].copy(), end[:3].copy()
    up = P / np.linalg.norm(P)
    track = (E - P) - float((E - P) @ up) * up
    left = np.cross(up, track / np.linalg.norm(track))
    target = up + 1000.0 / SCN.planet.radius_m * left
    return x0, e0, ef, c, (b, bf), P, E, target / np.linalg.norm(target)


def test_predicted_range_trigger_point_is_where_the_target_comes_abeam():
    """O_R_TRIG and O_XR_TRIG, where the range trigger fires and the crossrange there, against
    their truth (_abeam_case: P, and the target 1 km left of the track at P): at P within a few
    tens of metres and -1 km (the vehicle right of the target). The prediction's end lies 2.9 km
    further on, and its offset off the great circle from the state to the target is no measure of
    that miss (the track meets the circle at an angle): 2.7 km. A target passed above the box's
    Mach: the trigger fires where the box is entered (the same prediction ended at the box's Mach
    maximum). Without the range trigger (C_TRIG 0) the prediction's end and NaN."""
    x0, e0, ef, c, (b, bf), P, E, target = _abeam_case()
    R = SCN.planet.radius_m
    c[predictor.C_TGT:predictor.C_TGT + 3] = target
    out = np.zeros(predictor.N_O)
    predictor.predict(x0, c, b, bf, e0, ef, 1.0, 0.5, out, 0.0)
    trig = out[predictor.O_R_TRIG:predictor.O_R_TRIG + 3]
    assert np.linalg.norm(trig - P) < 50.0
    assert out[predictor.O_XR_TRIG] == pytest.approx(-1000.0, abs=20.0)
    assert np.array_equal(out[:3], E) and np.linalg.norm(E - P) > 2500.0
    assert abs(geometry.crossrange(x0[:3], target, E, R)) > 2000.0      # the end's offset: not the miss
    # a target passed above the box: the box entry
    c_q, c_box = c.copy(), c.copy()
    c_q[predictor.C_MACH_F], c_box[predictor.C_MACH_F] = 2.6, SCN.vehicle.deploy_box.mach_max
    passed, entry = np.zeros(predictor.N_O), np.zeros(predictor.N_O)
    predictor.predict(x0, c_q, b, bf, e0, ef, 1.0, 0.5, passed, 0.0)
    predictor.predict(x0, c_box, b, bf, e0, ef, 1.0, 0.5, entry, 0.0)
    c[predictor.C_TGT:predictor.C_TGT + 3] = passed[:3] / np.linalg.norm(passed[:3])
    predictor.predict(x0, c, b, bf, e0, ef, 1.0, 0.5, out, 0.0)
    assert np.linalg.norm(out[predictor.O_R_TRIG:predictor.O_R_TRIG + 3] - entry[:3]) < 50.0
    c[predictor.C_TRIG] = 0.0
    predictor.predict(x0, c, b, bf, e0, ef, 1.0, 0.5, out, 0.0)
    assert np.array_equal(out[predictor.O_R_TRIG:predictor.O_R_TRIG + 3], out[:3])
    assert math.isnan(out[predictor.O_XR_TRIG])


def test_lateral_pair_judges_the_range_trigger_by_its_miss_abeam_the_target():
    """The corrector's deploy crossranges for the lateral logic (_abeam_case's target): with the
    range trigger, the miss where the target comes abeam. Truth by brute force: the answer's
    profile flown by the predictor to a sweep of end Mach numbers inside the box, the closest
    of those points to the target (the vehicle passes right of it: the miss negative). With the
    velocity trigger (which deploys at its Mach wherever the target is) the offset of the
    deploy point off the great circle to the target, as before, and that is another figure."""
    x0, e0, ef, _, _, _, _, target = _abeam_case()
    R = SCN.planet.radius_m
    base = dict(PARAMS, **{"npc.max_iter": 20, "npc.h_floor_m": 0.0, "npc.range_reserve_m": 2000.0})
    fsw_scn = SCN.with_(deploy_by="fsw")
    got = {}
    for trigger in ("range", "velocity"):
        eg = npc.EntryGuidance(fsw_scn, dict(base, **{"deploy.trigger": trigger}), EventLog(), 0.02)
        try:
            eg.target_u, eg.bank0 = target, math.radians(120.0)
            res = eg.solve(x0, 1.0, 1.0, 1.0, t_flip=20.0)
            c = eg.constants.copy()
        finally:
            eg.close()
        assert res["ok"] and math.isfinite(res["xr_rev_m"])
        got[trigger] = res
        if trigger == "range":
            out, dist = np.zeros(predictor.N_O), []
            for mach in np.arange(2.3, 1.999, -0.002):
                c[predictor.C_MACH_F] = mach
                predictor.predict(x0, c, res["bank_line_rad"], res["bank_final_rad"], e0, ef, 1.0,
                                  base["npc.dt_pred_s"], out, 0.0)
                dist.append(geometry.central_angle(out[:3], target) * R)
            i_min = int(np.argmin(dist))
            assert 0 < i_min < len(dist) - 1                        # abeam inside the sweep
            assert res["xr_keep_m"] == pytest.approx(-dist[i_min], abs=30.0)
    end = _unit(got["velocity"])
    assert got["velocity"]["xr_keep_m"] == pytest.approx(geometry.crossrange(x0[:3], target, end, R), abs=1.0)
    assert abs(got["velocity"]["xr_keep_m"] - got["range"]["xr_keep_m"]) > 300.0


def test_trigger_crossrange_counts_only_within_the_reserve_of_the_target():
    """Corrector._deploy_crossrange on constructed predictions: the trigger's crossrange
    (O_XR_TRIG) is the answer when its point lies within the range reserve (2 km) of the
    target along the track (1.5 km past it, 0.3 km across); at the box entry 20 km past a
    target the track turned away from, the end's offset off the great circle to the target
    instead (here 4.3 km), as for the velocity trigger."""
    x0, _, _, _, _, _, E, target = _abeam_case()
    R = SCN.planet.radius_m
    eg = npc.EntryGuidance(SCN.with_(deploy_by="fsw"), dict(PARAMS, **{"deploy.trigger": "range",
                                                                       "npc.range_reserve_m": 2000.0}),
                           EventLog(), 0.02)
    try:
        eg.target_u = target
        assert eg.constants[predictor.C_TRIG] == 1.0 and eg.reserve_m == 2000.0
        up = target
        east = np.cross([0.0, 0.0, 1.0], up)
        east /= np.linalg.norm(east)
        north = np.cross(up, east)

        def at(d_north_m, d_east_m):        # a point near the target, the track northwards
            p = up + (d_north_m * north + d_east_m * east) / R
            return p / np.linalg.norm(p) * R
        end = at(3000.0, 7000.0)
        out = np.zeros(predictor.N_O)
        out[:3] = end
        out[predictor.O_XR_TRIG] = -300.0
        out[predictor.O_R_TRIG:predictor.O_R_TRIG + 3] = at(1500.0, 300.0)
        assert eg._deploy_crossrange(x0, out) == -300.0
        out[predictor.O_R_TRIG:predictor.O_R_TRIG + 3] = at(20e3, 300.0)
        off = eg._deploy_crossrange(x0, out)
        assert off == geometry.crossrange(x0[:3], target, end, R) and abs(off) > 3000.0
    finally:
        eg.close()


def test_lateral_pair_reverses_into_the_range_solution_the_shaper_will_fly():
    """The final reversal's pair is the two flights the corrector would fly. A late state (1.7
    km/s at 17 km, about 100 s to the deploy), the bank sign -1 at 60 deg, the target where that
    answer deploys, and the reference shaper at -40 deg still moving away at 7 deg/s (towards a
    larger magnitude commanded before): a reversal commanded one cycle on first brakes, out to
    -64 deg, then turns back through lift up, which flies long, and the corrector then answers
    with more bank. Truth by brute force: the predictor flown through the shaper with the
    reversal commanded at t_flip, on a 0.5 deg grid of the family's parameter; the range
    solution where its miss changes sign (interpolated), and the deploy crossrange of that
    flight. The reversed crossrange the lateral logic gets is that one, not the one of this
    answer's magnitude flipped at once (kilometres apart)."""
    d = math.radians
    R = SCN.planet.radius_m
    x = np.array([R + 17e3, 0.0, 0.0, 1700.0 * math.sin(d(-3.0)), 1700.0 * math.cos(d(-3.0)), 0.0])
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    dt, f = PARAMS["npc.dt_pred_s"], d(PARAMS["npc.bank_final_deg"])
    lo, hi = d(PARAMS["npc.bank_min_deg"]), d(PARAMS["npc.bank_max_deg"])
    c = predictor.predictor_constants(SCN, PARAMS)
    out = np.zeros(predictor.N_O)
    shp = np.array([d(-40.0), d(-7.0), -1.0, 0.0, d(8.0), d(1.0), 0.02, d(60.0), d(1.0)])
    predictor.predict_shaped(x, c, d(60.0), f, e0, ef, -1.0, dt, out, shp, 0.0)
    target = out[:3] / np.linalg.norm(out[:3])
    t_flip = 1.0
    tab = np.empty(shaper.N_TRANSITION)
    n = shaper.shaped_transition(shp, d(-60.0), t_flip, d(60.0), 0.5, tab)
    assert np.degrees(tab[:n]).min() < -60.0 and np.degrees(tab[n - 1]) == pytest.approx(60.0, abs=0.1)
    base = dict(PARAMS, **{"npc.max_iter": 20, "npc.h_floor_m": 0.0, "npc.tol_m": 20.0})
    eg = npc.EntryGuidance(SCN, base, EventLog(), 0.02)
    try:
        eg.target_u, eg.bank0 = target, d(60.0)
        res = eg.solve(x, -1.0, 1.0, 1.0, t_flip=t_flip, shp=shp, h_floor_m=0.0)
        c = eg.constants.copy()
    finally:
        eg.close()
    assert res["ok"] and abs(res["xr_keep_m"]) < 300.0          # kept, it deploys at the target
    s_togo = geometry.central_angle(x[:3], target) * R

    def flown(p):
        b0, bf = corrector.bank_profile(p, lo, hi, f)
        predictor.predict_shaped(x, c, b0, bf, e0, ef, 1.0, dt, out, shp, t_flip)
        assert out[predictor.O_FLAG] == predictor.REACHED
        return geometry.central_angle(x[:3], out[:3]) * R - s_togo, geometry.crossrange(x[:3], target, out[:3], R)
    ps = np.arange(*corrector.profile_span(lo, hi, f), d(0.5))
    z = np.array([flown(p)[0] for p in ps])
    cross = np.flatnonzero(np.sign(z[:-1]) != np.sign(z[1:]))
    assert len(cross) == 1                                        # one range solution reversed
    i = cross[0]
    p_root = ps[i] + (ps[i + 1] - ps[i]) * z[i] / (z[i] - z[i + 1])
    assert math.degrees(p_root) > 70.0                            # more bank than kept
    xr_truth = flown(p_root)[1]
    assert res["xr_rev_m"] == pytest.approx(xr_truth, abs=150.0)
    # this answer's magnitude, the reversal in effect at once: another figure
    predictor.predict(x, c, res["bank_line_rad"], res["bank_final_rad"], e0, ef, 1.0, dt, out, t_flip)
    assert abs(geometry.crossrange(x[:3], target, out[:3], R) - xr_truth) > 5000.0


def test_lateral_pair_has_no_reversed_crossrange_when_no_reversal_reaches_the_range():
    """The reversed half of the final reversal's pair counts only when a range solution exists
    for it. A late state (1.9 km/s at 21 km), the answer -87 deg, the target where it deploys,
    and an attitude chain left 1 deg/s^2 of acceleration (a reconfigured vehicle): with the
    reference at rest at -119.5 deg (beyond 90: past a larger magnitude commanded before) a
    reversal goes through lift down, ~30 s at that acceleration, and deploys short at any bank
    of the family; with it at rest at -87 deg it goes through lift up and the range is
    reached. Truth by brute force: the reversed flight (the predictor through the shaper, the
    reversal commanded one cycle on) on a 1-deg grid of the family's parameter, its miss
    against what the guidance accepts (npc.floor_miss_max_m; no range reserve: the plant
    deploys). Without a solution the reversed crossrange is NaN (the final rule then waits: the
    bank the corrector would fly there deploys kilometres short, and the next answers fly
    another reversal than the one predicted), with one it is a figure."""
    d = math.radians
    R = SCN.planet.radius_m
    V, gam = 1900.0, d(-3.0)
    x = np.array([R + 21e3, 0.0, 0.0, V * math.sin(gam), V * math.cos(gam), 0.0])
    e0 = SCN.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    ef = predictor.deploy_energy(SCN, PARAMS["npc.h_deploy_m"])
    dt, f = PARAMS["npc.dt_pred_s"], d(PARAMS["npc.bank_final_deg"])
    lo, hi = d(PARAMS["npc.bank_min_deg"]), d(PARAMS["npc.bank_max_deg"])
    miss_max = PARAMS["npc.floor_miss_max_m"]
    out = np.zeros(predictor.N_O)
    for phi_deg, reachable in ((-119.5, False), (-87.0, True)):
        shp = np.array([d(phi_deg), 0.0, -1.0, 0.0, d(8.0), d(1.0), 0.02, d(87.0), d(1.0)])
        c = predictor.predictor_constants(SCN, PARAMS)
        predictor.predict_shaped(x, c, d(87.0), f, e0, ef, -1.0, dt, out, shp, 0.0)
        target = out[:3] / np.linalg.norm(out[:3])
        eg = npc.EntryGuidance(SCN, dict(PARAMS, **{"npc.max_iter": 20, "npc.h_floor_m": 0.0, "npc.tol_m": 20.0}),
                               EventLog(), 0.02)
        try:
            eg.target_u, eg.bank0 = target, d(87.0)
            res = eg.solve(x, -1.0, 1.0, 1.0, t_flip=1.0, shp=shp, h_floor_m=0.0)
            c = eg.constants.copy()
        finally:
            eg.close()
        assert res["ok"] and abs(res["miss_m"]) <= 20.0            # kept, the range is reached
        s_togo = geometry.central_angle(x[:3], target) * R
        z = []
        for p in np.arange(*corrector.profile_span(lo, hi, f), d(1.0)):
            b0, bf = corrector.bank_profile(p, lo, hi, f)
            predictor.predict_shaped(x, c, b0, bf, e0, ef, 1.0, dt, out, shp, 1.0)
            assert out[predictor.O_FLAG] == predictor.REACHED
            z.append(geometry.central_angle(x[:3], out[:3]) * R - s_togo)
        z = np.array(z)
        solvable = bool(np.any(np.sign(z[:-1]) != np.sign(z[1:])) or np.any(np.abs(z) <= miss_max))
        assert solvable is reachable
        if reachable:
            assert math.isfinite(res["xr_rev_m"])
        else:
            assert z.max() < -miss_max                             # short at every bank, by kilometres
            assert math.isnan(res["xr_rev_m"])



def test_range_trigger_raises_the_magnitude_off_the_lift_up_bound_to_null_the_crossrange_where_it_fires():
    """An answer that flies the lift-up bound (a target beyond what any bank reaches by the deploy
    condition) with crossrange left. Truth by construction: from a late state (1 km/s, 16 km,
    -4 deg) the predictor flown at 35 deg held to the end (sign +1) passes a point P at Mach 1.6,
    inside the deploy box at 9.7 km, before the range trigger's last point (Mach 1.45); the target
    put at P. Every bank ends short of the aim point at the deploy condition (Mach 2), so the range
    solution holds 10 deg, along which the trigger fires 4.8 km off the target. With the range
    trigger the corrector's answer is 35 deg held again (within the secant's 200 m), and flown on
    to the trigger's last point it fires at P with the crossrange within that tolerance; with the
    velocity trigger (it deploys at the deploy condition, short, wherever the bank) the bound stays."""
    prm = dict(load_params(npc.PARAMS + trigger.PARAMS))
    scn = SCN.with_(deploy_by="fsw")
    R = scn.planet.radius_m
    g = math.radians(-4.0)
    x = np.array([R + 16e3, 0.0, 0.0, 1000.0 * math.sin(g), 1000.0 * math.cos(g), 0.0])
    e0 = scn.planet.mu_m3ps2 / np.linalg.norm(x[:3]) - 0.5 * float(x[3:] @ x[3:])
    ef = predictor.deploy_energy(scn, prm["npc.h_deploy_m"])
    dt = prm["npc.dt_pred_s"]
    b_star = math.radians(35.0)
    c = predictor.predictor_constants(scn, prm)
    at = np.zeros(predictor.N_O)
    c_p = c.copy()
    c_p[predictor.C_MACH_F] = 1.6
    predictor.predict(x, c_p, b_star, b_star, e0, ef, 1.0, dt, at, 0.0)
    target = at[:3] / np.linalg.norm(at[:3])
    assert np.linalg.norm(at[:3]) - R > prm["npc.h_fire_m"] + 2000.0

    def trigger_xr(b):
        """Where the trigger fires flown at b held, on to its last point: (crossrange, distance to P)."""
        c_end = c.copy()
        c_end[predictor.C_MACH_F], c_end[predictor.C_H_FLOOR] = 1.45, prm["deploy.h_floor_m"]
        c_end[predictor.C_TGT:predictor.C_TGT + 3] = target
        out = np.zeros(predictor.N_O)
        predictor.predict(x, c_end, b, b, e0, ef, 1.0, dt, out, 0.0)
        return out[predictor.O_XR_TRIG], np.linalg.norm(out[predictor.O_R_TRIG:predictor.O_R_TRIG + 3] - at[:3])

    lo = math.radians(prm["npc.bank_min_deg"])
    xr_lo, _ = trigger_xr(lo)
    assert xr_lo > 4000.0                       # the bound's crossrange where it fires
    for trig, reach in (("range", True), ("velocity", False)):
        eg = npc.EntryGuidance(scn, dict(prm, **{"deploy.trigger": trig}), EventLog(), 0.02)
        try:
            eg.target_u, eg.bank0 = target, lo
            res = eg.solve(x, 1.0, 1.0, 1.0, h_floor_m=6000.0)
        finally:
            eg.close()
        assert res["held"] and not res["ok"] and res["miss_m"] < -5000.0     # short of the aim point at Mach 2
        if reach:
            assert math.degrees(res["bank0_rad"]) == pytest.approx(35.0, abs=1.5)
            assert res["bank_final_rad"] == res["bank0_rad"]                # held to the end
            xr, miss_p = trigger_xr(res["bank0_rad"])
            assert abs(xr) <= prm["npc.tol_m"] and miss_p < 300.0
        assert res.get("reach", False) is reach
        if not reach:
            assert res["bank0_rad"] == pytest.approx(lo)
