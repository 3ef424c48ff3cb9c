"""The duty-cycle LP (fsw/controllability.py) against independent truth.

Truth: the torques the jets hold on average are the convex hull of the torques of every on/off
pattern of the usable jets (duty cycles in [0, 1]^p are the hull of {0, 1}^p), enumerated here
and wrapped by qhull (scipy ConvexHull); the bank authority is where the line {I v a - b} leaves
that hull, from the facet equations alone. The trim is checked by a grid over (dalpha, beta)
with the same hull membership test. No HiGHS on the truth side.
"""
import itertools
import math

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from common.model import inertia_matrix, inertia_vector, load_vehicle
from fsw.controllability import (aero_moment_per_rad, controllability, jet_columns, schedule_accel_need_radps2,
                                 velocity_dir_B)
from fsw.health import JetHealth
from tests.lp_oracle import weak_way_truth

VEH = load_vehicle("ellipsled")
T = np.asarray(VEH.torque_matrix_Nm, float)
I_NOM = np.asarray(VEH.inertia_kgm2, float)
V_B = velocity_dir_B(VEH.aero.alpha_trim_rad)
NO_AERO = np.zeros((3, 2))

CONFIGS = {
    "nominal": JetHealth(),
    "case1 (1 2 17 18 off)": JetHealth.of(failed_off=[1, 2, 17, 18]),
    "case2 (7 stuck on)": JetHealth.of(stuck_on=[2, 3, 4, 5, 8, 9, 10]),
    "case3 (4 at 50 %)": JetHealth.of(degraded=[(3, .5), (7, .5), (14, .5), (15, .5)]),
    "mixed, inhibited": JetHealth.of(failed_off=[7, 16, 18], degraded=[(1, .4), (3, .8), (8, .6)], inhibited=[12]),
    "stuck 95 N cancelled": JetHealth.of(failed_off=[2], stuck_on=[4, 12], degraded=[(13, .7), (18, .3)]),
}


def _hull(health):
    C, b = jet_columns(T, health)
    pts = np.array([C @ np.array(u) for u in itertools.product((0.0, 1.0), repeat=C.shape[1])])
    return ConvexHull(pts), b


def _inside(hull, x, tol=1e-6):
    return bool(np.all(hull.equations[:, :3] @ x + hull.equations[:, 3] <= tol))


def _authority_truth(hull, b, Iv):
    """max / min a with I v a - b in the hull: facets n.x + c <= 0 along x = Iv a - b."""
    n, c = hull.equations[:, :3], hull.equations[:, 3]
    k = n @ Iv
    r = -c + n @ b          # n.Iv a <= r
    a_max = np.min(r[k > 1e-12] / k[k > 1e-12])
    a_min = np.max(r[k < -1e-12] / k[k < -1e-12])
    return a_max, a_min


@pytest.mark.parametrize("name", list(CONFIGS))
def test_bank_authority_equals_the_hull_of_every_jet_pattern(name):
    h = CONFIGS[name]
    I = I_NOM * np.array([[1.2, 1.3, 1.3], [1.3, .85, 1.3], [1.3, 1.3, 1.3]])   # a dispersed truth inertia
    hull, b = _hull(h)
    assert _inside(hull, -b), "these configurations have jets that cancel their stuck-on bias"
    a_max, a_min = _authority_truth(hull, b, I @ V_B)
    r = controllability(T, h, I, V_B, NO_AERO, trim_max_deg=5.0, authority_min_radps2=0.0)
    assert r.trim_needed_deg == 0.0
    assert r.authority_pos_radps2 == pytest.approx(max(a_max, 0.0), rel=1e-6, abs=1e-9)
    assert r.authority_neg_radps2 == pytest.approx(max(-a_min, 0.0), rel=1e-6, abs=1e-9)
    assert r.bias_Nm == pytest.approx(np.linalg.norm(b))
    assert r.controllable == (min(a_max, -a_min) > 0)


@pytest.mark.parametrize("name", list(CONFIGS))
def test_authority_for_an_uncertain_inertia_holds_for_every_inertia_in_the_stated_range(name):
    """With each inertia element known to +-30 %, the authority promised is what the jets give
    for the worst inertia of that range: no inertia in it (every vertex of the 6-element box,
    hull truth) has less, and the box of I v it is computed on (its 8 corners, hull truth) has
    one that gives exactly that much."""
    h, u = CONFIGS[name], 0.3
    hull, b = _hull(h)
    r = controllability(T, h, I_NOM, V_B, NO_AERO, 5.0, 0.0, inertia_unc_frac=u)
    hv = np.array([I_NOM[0, 0], I_NOM[1, 1], I_NOM[2, 2], I_NOM[0, 1], I_NOM[0, 2], I_NOM[1, 2]])
    worst = [math.inf, math.inf]
    for s in itertools.product((1 - u, 1 + u), repeat=6):
        x = hv * np.array(s)
        I = np.array([[x[0], x[3], x[4]], [x[3], x[1], x[5]], [x[4], x[5], x[2]]])
        a_max, a_min = _authority_truth(hull, b, I @ V_B)
        worst = [min(worst[0], max(a_max, 0.0)), min(worst[1], max(-a_min, 0.0))]
    assert r.authority_pos_radps2 <= worst[0] * (1 + 1e-6) and r.authority_neg_radps2 <= worst[1] * (1 + 1e-6)
    Iv, half = I_NOM @ V_B, u * (np.abs(I_NOM) @ np.abs(V_B))
    corners = [_authority_truth(hull, b, Iv + half * np.array(sg)) for sg in itertools.product((-1, 1), repeat=3)]
    assert r.authority_pos_radps2 == pytest.approx(max(min(c[0] for c in corners), 0.0), rel=1e-6, abs=1e-9)
    assert r.authority_neg_radps2 == pytest.approx(max(min(-c[1] for c in corners), 0.0), rel=1e-6, abs=1e-9)
    nom = controllability(T, h, I_NOM, V_B, NO_AERO, 5.0, 0.0)
    assert r.authority_pos_radps2 >= nom.authority_pos_radps2 / (1 + u) ** 2   # the box costs < 1.3^2


def test_nominal_jets_turn_about_the_velocity_vector_by_a_few_deg_per_s2_each_way():
    r = controllability(T, JetHealth(), I_NOM, V_B, NO_AERO, 5.0, 0.0)
    assert 3.0 < math.degrees(r.authority_pos_radps2) < 5.0
    assert r.authority_pos_radps2 == pytest.approx(r.authority_neg_radps2, rel=0.01)   # near-symmetric layout
    assert r.controllable and r.reason == ""


def test_a_bias_the_jets_cannot_cancel_needs_the_smallest_trim_a_grid_finds():
    h = JetHealth.of(failed_off=[6, 16], stuck_on=[15], degraded=[(7, .5), (13, .5)])
    hull, b = _hull(h)
    assert not _inside(hull, -b)
    A = aero_moment_per_rad(800.0, VEH.S_ref_m2, VEH.l_ref_m, VEH.aero.C_lbeta, VEH.aero.C_malpha, VEH.aero.C_nbeta)
    r = controllability(T, h, I_NOM, V_B, A, trim_max_deg=5.0, authority_min_radps2=0.0, qbar_pa=800.0)
    assert 0.0 < r.trim_needed_deg < 30.0
    # grid truth: the smallest max(|dalpha|, |beta|) for which -b - A theta is in the hull,
    # a 0.1-deg grid over +-30 deg, then a 0.002-deg grid around its best point
    def best_on(da, be):
        th = np.radians(np.stack(np.meshgrid(da, be), -1).reshape(-1, 2))
        x = -b[None, :] - th @ A.T
        ok = np.all(x @ hull.equations[:, :3].T + hull.equations[:, 3] <= 1e-6, axis=1)
        s = np.max(np.abs(np.degrees(th)), axis=1)
        i = np.argmin(np.where(ok, s, np.inf))
        return s[i] if ok[i] else math.inf, np.degrees(th[i])
    coarse, (da0, be0) = best_on(np.arange(-30, 30.05, 0.1), np.arange(-30, 30.05, 0.1))
    assert math.isfinite(coarse)
    best, _ = best_on(np.arange(da0 - 0.2, da0 + 0.2, 0.002), np.arange(be0 - 0.2, be0 + 0.2, 0.002))
    assert r.trim_needed_deg == pytest.approx(best, abs=0.003)
    assert r.trim_needed_deg <= coarse + 1e-9
    # the same bias at a quarter of the dynamic pressure needs about four times the trim (small angles)
    r4 = controllability(T, h, I_NOM, V_B, A / 4.0, 5.0, 0.0, qbar_pa=200.0)
    assert r4.trim_needed_deg == pytest.approx(4.0 * r.trim_needed_deg, rel=1e-6)
    assert not r4.controllable and "trim offset" in r4.reason


def test_without_dynamic_pressure_an_uncancelled_bias_has_no_trim_and_is_reported():
    h = JetHealth.of(failed_off=[6, 16], stuck_on=[15], degraded=[(7, .5), (13, .5)])
    r = controllability(T, h, I_NOM, V_B, NO_AERO, 5.0, 0.0, qbar_pa=0.0)
    assert math.isinf(r.trim_needed_deg) and not r.controllable
    assert "beyond what the jets and the aerodynamics can cancel" in r.reason
    assert r.authority_pos_radps2 == 0.0 and r.authority_neg_radps2 == 0.0


def test_near_zero_dynamic_pressure_reports_no_physical_trim_instead_of_a_huge_angle():
    """The linear trim answer grows as 1/qbar: at 0.01 Pa it is thousands of degrees. The reason
    says no trim within a right angle absorbs the residual (with the qbar), the event text '>90'."""
    h = JetHealth.of(failed_off=[6, 16], stuck_on=[15], degraded=[(7, .5), (13, .5)])
    A1 = aero_moment_per_rad(800.0, VEH.S_ref_m2, VEH.l_ref_m, VEH.aero.C_lbeta, VEH.aero.C_malpha, VEH.aero.C_nbeta)
    r800 = controllability(T, h, I_NOM, V_B, A1, 5.0, 0.0, qbar_pa=800.0)
    q = 0.01
    r = controllability(T, h, I_NOM, V_B, A1 * (q / 800.0), 5.0, 0.0, qbar_pa=q)
    # independent check of the scaling: the linear answer is (800 / q) times the one at 800 Pa
    assert r.trim_needed_deg == pytest.approx(r800.trim_needed_deg * 800.0 / q, rel=1e-6)
    assert r.trim_needed_deg > 90.0 and not r.controllable
    assert r.reason.startswith("no trim offset within 90 deg absorbs the ")
    assert f"at qbar {q:.0f} Pa" in r.reason and f"{r.residual_Nm:.0f} N m" in r.reason
    assert "TRIM >90DEG" in r.text() and len(r.text()) <= 50
    # below a right angle the angle itself is reported, as before
    r9 = controllability(T, h, I_NOM, V_B, A1 * (r800.trim_needed_deg / 60.0), 5.0, 0.0, qbar_pa=1.0)
    assert r9.reason.startswith("trim offset 60.0 deg needed")


def test_authority_below_what_the_schedule_needs_is_not_controllable():
    h = JetHealth.of(failed_off=[1, 13, 16], degraded=[(6, .3), (7, .3)])
    r = controllability(T, h, I_NOM, V_B, NO_AERO, 5.0, 0.0)
    weak = min(r.authority_pos_radps2, r.authority_neg_radps2)
    r2 = controllability(T, h, I_NOM, V_B, NO_AERO, 5.0, 1.01 * weak)
    assert r.controllable and not r2.controllable and "bank authority" in r2.reason


def test_schedule_need_is_the_quintic_peak_acceleration_of_the_hardest_step_left():
    sched = [(0.0, math.radians(85)), (60.0, math.radians(-85)), (130.0, math.radians(60)), (200.0, math.radians(-60))]
    s2 = 10.0 / math.sqrt(3.0)
    assert schedule_accel_need_radps2(sched, 0.0) == pytest.approx(s2 * math.radians(170) / 70.0 ** 2)
    assert schedule_accel_need_radps2(sched, 131.0) == pytest.approx(s2 * math.radians(145) / 70.0 ** 2)
    assert schedule_accel_need_radps2(sched, 250.0) == pytest.approx(s2 * math.radians(120) / 70.0 ** 2)
    assert schedule_accel_need_radps2(sched, 271.0) == 0.0


def test_the_lp_is_cheap_enough_for_every_reconfiguration():
    h = JetHealth.of(failed_off=[6, 16], stuck_on=[15], degraded=[(7, .5), (13, .5)])
    A = aero_moment_per_rad(800.0, VEH.S_ref_m2, VEH.l_ref_m, VEH.aero.C_lbeta, VEH.aero.C_malpha, VEH.aero.C_nbeta)
    controllability(T, h, I_NOM, V_B, A, 5.0, 0.0)
    times = [controllability(T, h, I_NOM, V_B, A, 5.0, 0.0).solve_s for _ in range(5)]
    assert min(times) < 0.1       # generous sanity bound on a shared host; the figure is in the README


def test_the_truth_label_uses_the_faults_the_plant_applied_with_their_thrust_factors():
    from common.model import FaultEvent, load_scenario
    from ellipsled.controllable import truth_controllability, truth_health
    from fsw.health import DEGRADED, FAILED_OFF, NOMINAL, STUCK_ON
    scn = load_scenario("nominal").with_(faults=(
        FaultEvent(10.0, (3, 4), "failed_off"), FaultEvent(10.0, (15,), "stuck_on"),
        FaultEvent(10.0, (7,), "degraded", 0.4),
        FaultEvent(900.0, (9,), "failed_off")))               # after the end: never applied
    applied = [(10.0, 3, "failed_off"), (10.0, 4, "failed_off"), (10.0, 15, "stuck_on"), (10.0, 7, "degraded")]
    h = truth_health(scn, applied)
    assert [int(h.state[j - 1]) for j in (3, 4, 15, 7, 9)] == [FAILED_OFF, FAILED_OFF, STUCK_ON, DEGRADED, NOMINAL]
    assert h.eta[6] == 0.4
    t = np.linspace(0.0, 600.0, 601)
    q = np.where(t < 300.0, 5000.0, 150.0)
    lab = truth_controllability(scn, applied, t, q, 5.0)
    assert lab["qbar_min_pa"] == 150.0                       # the lowest dynamic pressure after the fault
    assert truth_controllability(scn, [], t, q, 5.0) == {"controllable": True, "reason": ""}


def test_a_one_way_authority_of_lp_round_off_is_no_authority():
    """Two stuck-on jets whose bias uses up exactly what the rest can give one way: the LP answers
    a few 1e-17 rad/s^2 that way, which is no authority (a vehicle that cannot roll that way at all),
    not a controllable run (a dispersed guided run drawn from a Monte Carlo campaign). No trim
    allowed: with one, the aerodynamics take part of the bias and give that way authority back
    (tests/test_controllability_trim_edge.py)."""
    h = JetHealth.of(failed_off=[3, 4, 16, 18], stuck_on=[5, 14], degraded=[(9, 0.3378089323928256),
                                                                          (15, 0.5692506836223459)])
    A = aero_moment_per_rad(22.758377871340358, VEH.S_ref_m2, VEH.l_ref_m, VEH.aero.C_lbeta * 0.9567196463078076,
                            VEH.aero.C_malpha * 1.1833231551876164, VEH.aero.C_nbeta * 1.1435900431781738)
    scale = np.array([0.7014487213172172, 0.9830821868080623, 0.7236671888220503, 1.0292863306861064,
                      1.2894518858157027, 1.24303287928905])
    r = controllability(T, h, inertia_matrix(inertia_vector(I_NOM) * scale), V_B, A, 0.0, 0.0)
    assert r.trim_needed_deg == 0.0 and r.authority_neg_radps2 > math.radians(1.0)
    assert abs(r.authority_pos_radps2) < 1e-12          # what the LP answers for "none"
    assert not r.controllable and r.reason.startswith("bank authority +")


def test_held_trim_moves_to_the_weak_way_best_one_closest_to_it():
    """A trim chosen at a high dynamic pressure and carried (clipped at trim_max) to a low one
    no longer balances the bias: with it held, the weaker way has nothing (truth: scipy on a
    grid of trims), while another trim within trim_max gives it authority. Asked with the held
    trim, the LP returns that best weak way and the trim giving it; a held trim that is already
    best stays where it is."""
    from common.model import load_scenario
    from fsw.controllability import aero_moment_per_rad, jet_columns, inertia_corners, velocity_dir_B
    veh = load_scenario("case2").vehicle
    a = veh.aero
    h = JetHealth.of(failed_off=[6, 7, 15, 16], stuck_on=[4, 14], degraded=[(13, 0.575)])
    v = velocity_dir_B(a.alpha_trim_rad)
    A = aero_moment_per_rad(422.0, veh.S_ref_m2, veh.l_ref_m, a.C_lbeta, a.C_malpha, a.C_nbeta)
    args = (veh.torque_matrix_Nm, h, veh.inertia_kgm2, v, A, 5.0, 0.0, 422.0, veh.inertia_uncertainty_frac)
    C, b = jet_columns(veh.torque_matrix_Nm, h)
    W = inertia_corners(veh.inertia_kgm2, v, veh.inertia_uncertainty_frac)
    held = np.radians([-5.0, 2.32])
    assert weak_way_truth(C, b, A, W, held) == 0.0
    grid = np.radians(np.linspace(-5.0, 5.0, 21))
    best = max(weak_way_truth(C, b, A, W, np.array([x, y])) for x in grid for y in grid)
    assert best > math.radians(0.5)
    r = controllability(*args, held)
    weak = min(r.authority_pos_radps2, r.authority_neg_radps2)
    theta = np.radians([r.trim_alpha_deg, r.trim_beta_deg])
    assert np.max(np.abs(theta)) <= math.radians(5.0) * (1 + 1e-6)
    assert weak >= best * (1 - 1e-6)
    assert weak == pytest.approx(weak_way_truth(C, b, A, W, theta), rel=1e-6)
    # already the best: held where it is (not moved to another trim as good)
    r2 = controllability(*args, theta)
    assert np.radians([r2.trim_alpha_deg, r2.trim_beta_deg]) == pytest.approx(theta, abs=1e-9)
    assert min(r2.authority_pos_radps2, r2.authority_neg_radps2) == pytest.approx(weak, rel=1e-6)


def test_a_guided_entry_needs_a_turn_from_lift_down_to_lift_up(tmp_path):
    """A guided entry's label asks for the acceleration that turns the bank through 180 deg rest
    to rest within GUIDED_TURN_S (4 pi / T^2), each way. Run 50 of the guided campaign at master
    seed 1111 (a stuck-on bias that leaves one way 0.005 deg/s^2, which turns the bank through
    180 deg in no less than 6 minutes, longer than the guided flight after its fault) is not
    controllable as a guided entry; the same jets flying the paper's schedule (mode profile, a
    single-entry schedule: no need) keep the label they had."""
    from common.model import load_scenario
    from ellipsled.controllable import truth_controllability
    from ellipsled.montecarlo.campaign import load_campaign, pinned_scenario_toml
    from common.config import resolve
    from fsw.controllability import GUIDED_TURN_S, guided_accel_need_radps2

    assert guided_accel_need_radps2("npc") == pytest.approx(4.0 * math.pi / GUIDED_TURN_S ** 2)
    assert guided_accel_need_radps2("profile") == 0.0
    camp = load_campaign("guided")
    text = pinned_scenario_toml(camp, resolve("scenarios", camp.scenario), 50, 1111)
    (tmp_path / "run50.toml").write_text(text)
    scn = load_scenario(tmp_path / "run50.toml")
    assert scn.guidance_mode == "npc"
    applied = [(ev.t_s, j, ev.kind) for ev in scn.faults for j in ev.jets]
    t = np.linspace(0.0, 300.0, 301)
    q = np.full_like(t, 18.9)              # the lowest dynamic pressure after its fault, as flown
    lab = truth_controllability(scn, applied, t, q, 5.0)
    weak = min(lab["authority_pos_degps2"], lab["authority_neg_degps2"])
    assert 0.0 < weak < 0.02
    assert not lab["controllable"] and "deg/s2" in lab["reason"]
    assert lab["need_degps2"] == pytest.approx(math.degrees(guided_accel_need_radps2("npc")))
    assert truth_controllability(scn.with_(guidance_mode="profile"), applied, t, q, 5.0)["controllable"]
