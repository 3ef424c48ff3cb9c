"""Monte Carlo campaign: data file validation, the per-run draw, the dispersed scenario,
success criteria, the Parquet store and the campaign folder (no Dask here)."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pyarrow.parquet as pq
import pytest

from common.config import DATA_DIR, ConfigError
from common.model import INERTIA_KEYS, inertia_vector, load_scenario
from ellipsled.montecarlo.campaign import (apply_dispersion, dispersion_columns, dispersion_from_columns, draw_run,
                                           load_campaign)
from ellipsled.montecarlo.engine import execute_run, make_task, prepare_out
from ellipsled.montecarlo.store import ResultStore, flatten

DEFAULT = (DATA_DIR / "campaigns" / "default.toml").read_text()


def _camp(tmp_path, text=DEFAULT, name="c.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.fixture(scope="module")
def camp():
    return load_campaign("default")


@pytest.fixture(scope="module")
def base(camp):
    return load_scenario(camp.scenario)


def test_default_campaign_carries_the_spec_dispersions(camp):
    d = camp.dispersions
    assert d.inertia_scale == d.density_scale == d.aero_scale == (0.7, 1.3)
    assert d.bank0_err_deg == (-5.0, 5.0) and d.flight_path_offset_deg == (-0.25, 0.25)
    assert (d.n_failed_off, d.n_stuck_on, d.n_degraded) == ((1, 4), (0, 2), (0, 3))
    assert d.degraded_eta == (0.3, 0.9) and d.fault_t_s == (2.0, 300.0) and d.fdir_delay_s == (0.0, 2.0)
    assert camp.break_runs == ()
    assert camp.max_duration_s == 1000.0


def test_campaign_time_cap_replaces_the_base_scenarios(tmp_path, camp):
    out = tmp_path / "mc"
    assert load_scenario(camp.scenario).max_duration_s == 700.0
    assert prepare_out(out, camp, 1, None).max_duration_s == 1000.0
    from ellipsled.montecarlo.engine import read_meta
    assert read_meta(out)["campaign"]["max_duration_s"] == 1000.0


@pytest.mark.parametrize("old,new,field", [
    ("density_scale = [0.7, 1.3]", "density_scale = [1.3, 0.7]", "dispersions.density_scale"),
    ("density_scale = [0.7, 1.3]", "density_scale = [0.0, 1.3]", "dispersions.density_scale"),
    ("failed_off = [1, 4]", "failed_off = [1.5, 4]", "dispersions.faults.failed_off"),
    ("failed_off = [1, 4]", "failed_off = [1, 19]", "dispersions.faults.failed_off"),
    ("failed_off = [1, 4]", "failed_off = [1, 14]", "dispersions.faults.failed_off"),   # 14 + 2 + 3 > 18 jets
    ("degraded_eta = [0.3, 0.9]", "degraded_eta = [0.3, 1.0]", "dispersions.faults.degraded_eta"),
    ("fdir_delay_s = [0.0, 2.0]", "fdir_delay_s = [-1.0, 2.0]", "dispersions.fdir_delay_s"),
    ("master_seed = 20110808", "master_seed = -1", "campaign.master_seed"),
    ("runs = 1000", "runs = 0", "campaign.runs"),
    ("runs = 1000", "runz = 1000", "campaign.runs"),                  # required field missing
    ('name = "default"', 'name = "default"\nseed = 3', "campaign.seed"),  # unknown (misspelt) field
    ("bank_err_max_after_fault_deg = 5.0", "bank_err_max_after_fault_deg = 5.0\nbogus = 1", "success.bogus"),
    ("bank_err_max_after_fault_deg = 5.0", "bank_err_max_after_fault_deg = \"5\"", "success.bank_err_max_after_fault_deg"),
])
def test_bad_campaign_file_names_file_and_field(tmp_path, old, new, field):
    assert old in DEFAULT
    p = _camp(tmp_path, DEFAULT.replace(old, new))
    with pytest.raises(ConfigError) as e:
        load_campaign(p)
    assert e.value.field == field and e.value.file == str(p)


def test_bad_testing_section_is_rejected(tmp_path):
    p = _camp(tmp_path, DEFAULT + "\n[testing]\nbreak_runs = [-1]\n")
    with pytest.raises(ConfigError, match="testing.break_runs"):
        load_campaign(p)


def test_draw_is_a_function_of_master_seed_and_run_id_only(camp, base):
    a = [draw_run(camp, base, i) for i in (5, 0, 3)]
    b = [draw_run(camp, base, i) for i in (3, 0, 5)][::-1]   # other order, other calls before
    assert a == b
    assert draw_run(camp, base, 0) != draw_run(camp, base, 1)
    assert draw_run(camp, base, 0, master_seed=1) != draw_run(camp, base, 0, master_seed=2)
    with pytest.raises(ValueError):
        draw_run(camp, base, -1)


def test_draws_cover_the_ranges_with_uniform_statistics(camp, base):
    n = 1500
    draws = [draw_run(camp, base, i)[1] for i in range(n)]
    seeds = {draw_run(camp, base, i)[0] for i in range(200)}
    assert len(seeds) == 200                      # noise seeds differ run to run
    d = camp.dispersions
    for key, (lo, hi) in [*((f"inertia_scale_{k}", d.inertia_scale) for k in INERTIA_KEYS),
                          ("density_scale", d.density_scale), ("C_lbeta_scale", d.aero_scale),
                          ("C_malpha_scale", d.aero_scale), ("C_nbeta_scale", d.aero_scale),
                          ("bank0_err_deg", d.bank0_err_deg), ("flight_path_offset_deg", d.flight_path_offset_deg),
                          ("fault_t_s", d.fault_t_s), ("fdir_delay_s", d.fdir_delay_s)]:
        x = np.array([r[key] for r in draws])
        assert x.min() >= lo and x.max() <= hi, key
        # uniform on [lo, hi]: mean (lo+hi)/2, sd (hi-lo)/sqrt(12); 5 standard errors of the mean
        sd = (hi - lo) / math.sqrt(12)
        assert abs(x.mean() - (lo + hi) / 2) < 5 * sd / math.sqrt(n), key
        assert abs(x.std() - sd) < 0.1 * sd, key
    counts = {k: np.array([len(r[k]) for r in draws]) for k in ("jets_failed_off", "jets_stuck_on", "jets_degraded")}
    for k, (lo, hi) in (("jets_failed_off", d.n_failed_off), ("jets_stuck_on", d.n_stuck_on),
                        ("jets_degraded", d.n_degraded)):
        freq = np.bincount(counts[k], minlength=hi + 1)[lo:hi + 1] / n
        assert counts[k].min() == lo and counts[k].max() == hi
        assert np.all(np.abs(freq - 1 / (hi - lo + 1)) < 0.05), (k, freq)
    for r in draws:
        jets = r["jets_failed_off"] + r["jets_stuck_on"] + r["jets_degraded"]
        assert len(set(jets)) == len(jets) and all(1 <= j <= 18 for j in jets)
        assert len(r["degraded_eta"]) == len(r["jets_degraded"])
        assert all(0.3 <= e <= 0.9 for e in r["degraded_eta"])


def test_applied_dispersion_sets_truth_initial_state_faults_and_delay(camp, base):
    seed, disp = draw_run(camp, base, 7)
    fsw_before = json.dumps(base.fsw, sort_keys=True)
    s = apply_dispersion(base, disp, seed, "x-7")
    assert json.dumps(base.fsw, sort_keys=True) == fsw_before          # base untouched
    assert s.seed == seed and s.name == "x-7"
    np.testing.assert_array_equal(s.truth.inertia_scale, [disp[f"inertia_scale_{k}"] for k in INERTIA_KEYS])
    assert s.truth.density_scale == disp["density_scale"] and s.truth.C_nbeta_scale == disp["C_nbeta_scale"]
    assert math.isclose(math.degrees(s.bank0_rad - base.bank_schedule[0][1]), disp["bank0_err_deg"], abs_tol=1e-12)
    assert math.isclose(math.degrees(s.flight_path_rad - base.flight_path_rad), disp["flight_path_offset_deg"],
                        abs_tol=1e-12)
    assert s.fsw["fdir"]["delay_s"] == disp["fdir_delay_s"]
    by_kind = {}
    for f in s.faults:
        assert f.t_s == disp["fault_t_s"]
        for j in f.jets:
            by_kind.setdefault(f.kind, []).append((j, f.eta))
    assert sorted(j for j, _ in by_kind.get("failed_off", [])) == list(disp["jets_failed_off"])
    assert sorted(j for j, _ in by_kind.get("stuck_on", [])) == list(disp["jets_stuck_on"])
    assert sorted(by_kind.get("degraded", [])) == sorted(zip(disp["jets_degraded"], disp["degraded_eta"]))
    # the truth inertia the plant will use stays positive definite
    from common.model import inertia_matrix
    assert np.linalg.eigvalsh(inertia_matrix(inertia_vector(s.vehicle.inertia_kgm2) * s.truth.inertia_scale))[0] > 0


def test_record_columns_round_trip_exactly(camp, base):
    seed, disp = draw_run(camp, base, 11)
    cols = dispersion_columns(disp)
    assert cols["disp.n_failed_off"] == len(disp["jets_failed_off"])
    back = dispersion_from_columns(json.loads(json.dumps(cols)))
    assert back == disp
    with pytest.raises(ValueError, match="lacks"):
        apply_dispersion(base, {k: v for k, v in disp.items() if k != "fault_t_s"}, seed, "x")
    bad = dict(disp, density_scale=float("nan"))
    with pytest.raises(ValueError, match="non-finite"):
        apply_dispersion(base, bad, seed, "x")


def test_criteria_judge_each_condition(camp):
    c = camp.success
    good = {"completed": True, "nonfinite": False, "bank_err_max_after_fault_deg": 4.9, "cycle_slips": 0,
            "fault_t_s": 3.0, "t_end_s": 10.0}
    assert c.failures(good) == []
    assert c.failures(dict(good, completed=False)) == ["completed"]
    assert c.failures(dict(good, nonfinite=True)) == ["finite"]
    assert c.failures(dict(good, bank_err_max_after_fault_deg=5.1)) == ["bank_err_max_after_fault_deg"]
    assert c.failures(dict(good, bank_err_max_after_fault_deg=None)) == ["bank_err_max_after_fault_deg"]
    assert c.failures(dict(good, cycle_slips=7)) == []        # a host figure in batch, not a criterion
    # the run ended before the fault: the error bound is vacuous
    assert c.failures(dict(good, bank_err_max_after_fault_deg=None, fault_t_s=50.0)) == []


def test_broken_run_is_a_failed_row_with_its_error_and_seed(tmp_path, base):
    camp = load_campaign(_camp(tmp_path, DEFAULT + "\n[testing]\nbreak_runs = [4]\n"))
    task = make_task(camp, base, 4, camp.master_seed, 1.0)
    row = execute_run(task)
    assert row["status"] == "failed" and row["success"] is False
    assert "fdir.delay_s" in row["error"] and row["seed"] == task.seed and row["run_id"] == 4
    assert row["disp.fdir_delay_s"] < 0                       # the applied dispersion is on record


def test_flatten_nests_and_serialises_lists():
    f = flatten({"a": 1, "b": {"c": 2.5, "d": {"e": None}}, "det": [{"jet": 1}], "v": [1, 2]})
    assert f == {"a": 1, "b.c": 2.5, "b.d.e": None, "det": '[{"jet": 1}]', "v": "[1, 2]"}


def test_store_appends_whole_parts_and_unifies_types(tmp_path):
    st = ResultStore(tmp_path / "results.parquet")
    (st.root / ".tmp-part-dead.parquet").write_bytes(b"half a file")   # a writer that died
    st = ResultStore(tmp_path / "results.parquet")
    assert not list(st.root.glob(".tmp-*"))
    st.append([{"run_id": 1, "x": None, "s": "a"}, {"run_id": 0, "x": None, "status": "failed"}])
    st.append([{"run_id": 2, "x": 2.5, "n": 3, "flag": True}])
    st.append([])
    assert len(st.parts()) == 2
    assert sorted(st.run_ids()) == [0, 1, 2]
    rows = st.rows()
    assert [r["run_id"] for r in rows] == [0, 1, 2]
    assert rows[2]["x"] == 2.5 and rows[0]["x"] is None and rows[2]["n"] == 3 and rows[0]["n"] is None
    assert st.row(2)["flag"] is True
    with pytest.raises(ValueError, match="no record of run 9"):
        st.row(9)
    # any Parquet reader sees the folder as one dataset
    import pyarrow.dataset as ds
    assert ds.dataset(st.root, format="parquet").count_rows() == 3
    assert pq.read_table(st.parts()[0]).num_rows == 2


def test_campaign_folder_refuses_a_different_campaign(tmp_path, camp):
    out = tmp_path / "mc"
    base = prepare_out(out, camp, 5, 10.0)
    assert base.name == load_scenario(camp.scenario).name
    assert prepare_out(out, camp, 5, 10.0).name == base.name              # same campaign: resume
    with pytest.raises(ValueError, match="master_seed"):
        prepare_out(out, camp, 6, 10.0)
    with pytest.raises(ValueError, match="duration_s"):
        prepare_out(out, camp, 5, None)
    other = load_campaign(_camp(tmp_path, DEFAULT.replace("density_scale = [0.7, 1.3]", "density_scale = [0.8, 1.2]")))
    with pytest.raises(ValueError, match="dispersions"):
        prepare_out(out, other, 5, 10.0)
    assert os.path.exists(out / "scenario.toml")


def test_a_second_campaign_process_on_the_same_folder_is_refused(tmp_path):
    from ellipsled.montecarlo.engine import _exclusive
    with _exclusive(tmp_path):
        with pytest.raises(ValueError, match="another campaign process"):
            with _exclusive(tmp_path):
                pass
    with _exclusive(tmp_path):   # released
        pass


def test_summary_counts_success_over_all_and_over_controllable_runs(tmp_path, camp):
    from ellipsled.montecarlo.store import rows_to_table
    from ellipsled.montecarlo.summary import stats, write_summary

    def row(i, success, ctl, err, attrib=None, reason=""):
        return {"run_id": i, "seed": i, "status": "ok", "success": success, "completed": True,
                "failed_criteria": None if success else "bank_err_max_after_fault_deg",
                "bank_err_max_after_fault_deg": err, "bank_err_sched_max_after_fault_deg": err,
                "bank_err_fault_attrib_max_deg": attrib, "t_end_s": 600.0,
                "controllability.controllable": ctl, "controllability.reason": reason}
    rows = [row(0, True, True, 1.0, 0.2), row(1, True, True, 2.0, 0.5), row(2, False, True, 7.0, 6.0),
            row(3, False, False, 40.0, 39.0, "trim offset 19.5 deg needed to absorb 298 N m (limit 5 deg)"),
            {"run_id": 4, "seed": 4, "status": "failed", "success": False, "failed_criteria": "raised",
             "error": "ValueError: boom"}]
    st = stats(rows_to_table(rows), 5)
    assert st["runs_controllable"] == 3 and st["success_controllable"] == 2
    assert st["success_rate_all"] == pytest.approx(2 / 5)
    assert st["success_rate_controllable"] == pytest.approx(2 / 3)
    assert st["uncontrollable"] == [{"run_id": 3, "reason": rows[3]["controllability.reason"]}]
    assert st["fault_attrib_within_goal_controllable"]["fraction"] == pytest.approx(2 / 3)
    assert st["figures_controllable"]["bank_err_max_after_fault_deg"]["max"] == 7.0
    md = write_summary(tmp_path, camp, rows_to_table(rows), 5, plots=False).read_text()
    assert "success over controllable runs: 2 / 3" in md and "| 3 | trim offset 19.5 deg" in md
    assert "not controllable: trim offset" in md        # the worst run's one-line diagnosis
    saved = json.loads((tmp_path / "summary_stats.json").read_text())
    assert {"runs_controllable", "success_rate_controllable", "success_rate_all"} <= set(saved)
