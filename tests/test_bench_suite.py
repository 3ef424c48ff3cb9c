"""Benchmark suite smoke tests: JSON shape, the null + reason path, cyclictest histogram
parsing against hand-built histograms, and a one-second real-time loop child.
Timing figures are never asserted here (they go to the benchmark JSON)."""
from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest

from ellipsled.bench import jitter, sil, suite


def _boom(quick):
    raise RuntimeError("no HiGHS here")


def test_failing_section_nulls_only_its_figures(tmp_path):
    out = tmp_path / "b.json"
    res = suite.run_suite(True, out, sections={
        "allocator": _boom,
        "batch": lambda q: {"realtime_factor": float("nan"), "wall_s": 1.0},
        "codec": suite.SECTIONS["codec"],
    }, say=lambda m: None)
    a = res["allocator"]
    for k in suite.REQUIRED["allocator"]:
        assert a[k] is None
        assert "RuntimeError: no HiGHS here" in a[f"{k}_reason"]
    # a NaN is never passed on as a number: null with a reason
    assert res["batch"]["realtime_factor"] is None and res["batch"]["realtime_factor_reason"]
    assert res["batch"]["wall_s"] == 1.0
    # the healthy section measured real numbers
    c = res["codec"]
    assert c["rejected"] == 0
    for k in suite.REQUIRED["codec"]:
        assert isinstance(c[k], float) and c[k] > 0 and f"{k}_reason" not in c
    # the file is strict JSON (no NaN) and equals the returned result
    on_disk = json.loads(out.read_text(), parse_constant=lambda x: pytest.fail(f"non-JSON constant {x}"))
    assert on_disk["allocator"]["p99_us"] is None
    assert on_disk["codec"]["sensors"]["bytes"] == 328
    # derived tables exist with reasons when their sources did not run
    assert res["rt"]["sched_fifo"] is None and res["rt"]["sched_fifo_reason"]


def test_table_shows_not_measured_with_reason():
    res = {"quick": True, "machine": suite.machine(True),
           "allocator": {}, "jitter": {"idle": {}, "load": {}}, "bridge": {"cpu_pct": 1.5, "mem_growth_mb": 0.2}}
    suite.fill_required(res, "allocator", "section failed: X")
    suite.fill_required(res, "jitter", "cyclictest missing")
    md = suite.table(res)
    assert "| allocator solve, each configuration's own box p50 / p99 / max [us] | n/m / n/m / n/m |" in md
    assert "`allocator.p99_us`: section failed: X" in md
    assert "`jitter.idle.cyclictest_p99_us`: cyclictest missing" in md
    bridge_row = next(ln for ln in md.splitlines() if ln.startswith("| Rerun bridge"))
    assert "1.50 / 0.20" in bridge_row and bridge_row.rstrip().endswith("| pass |")


def test_required_keys_of_the_issue_are_declared():
    need = {"allocator": {"p50_us", "p99_us", "max_us", "highs_p99_us", "speedup", "mismatches"},
            "cycle": {"compute_p50_us", "compute_p99_us", "compute_max_us"},
            "jitter.idle": {"p50_us", "p99_us", "max_us", "slips", "cyclictest_p99_us", "cyclictest_max_us"},
            "jitter.load": {"p50_us", "p99_us", "max_us", "slips", "cyclictest_p99_us", "cyclictest_max_us"},
            "latency": {"p50_us", "p99_us", "udp_p99_us"}, "sil_lockstep": {"realtime_factor"},
            "batch": {"realtime_factor"}, "bridge": {"cpu_pct", "mem_growth_mb"},
            "rt": {"sched_fifo", "affinity", "mlockall", "messages"},
            "machine": {"nproc", "load", "python", "versions"}}
    for sec, keys in need.items():
        assert keys <= set(suite.REQUIRED[sec]), sec
    assert set(suite.ORDER) == set(suite.SECTIONS)


def _hist(counts: dict[int, int], overflow: int = 0, mx: int | None = None) -> str:
    lines = ["# /dev/cpu_dma_latency set to 0us", "# Histogram"]
    lines += [f"{b:06d} {counts.get(b, 0):06d}" for b in range(0, 100)]
    n = sum(counts.values()) + overflow
    lines += [f"# Total: {n:09d}", "# Min Latencies: 00003", "# Avg Latencies: 00012",
              f"# Max Latencies: {mx if mx is not None else max(counts):05d}",
              f"# Histogram Overflows: {overflow:05d}", "# Histogram Overflow at cycle number:", "# Thread 0:"]
    return "\n".join(lines) + "\n"


def test_cyclictest_histogram_percentiles():
    # 1000 samples: 500 at 5 us, 490 at 10 us, 10 at 40 us -> p50 = 5, p99 = 10 (990th), max 40
    r = jitter.parse_cyclictest(_hist({5: 500, 10: 490, 40: 10}))
    assert (r["n"], r["p50_us"], r["p99_us"], r["max_us"], r["avg_us"]) == (1000, 5.0, 10.0, 40.0, 12.0)
    # one more sample at 40 us moves the 99th percentile there (991 <= 0.99 * 1001 = 990.99 fails)
    r = jitter.parse_cyclictest(_hist({5: 500, 10: 490, 40: 11}))
    assert r["p99_us"] == 40.0
    # p99 inside the overflow: unknown, not a made-up number
    r = jitter.parse_cyclictest(_hist({5: 900}, overflow=100, mx=25000))
    assert r["p50_us"] == 5.0 and r["p99_us"] is None and r["overflows"] == 100 and r["max_us"] == 25000.0
    with pytest.raises(ValueError):
        jitter.parse_cyclictest("cyclictest: command failed\n")


def test_sil_absent_gives_null_and_reason():
    r = sil.lockstep(True, available=(False, "`ellipsled run` not available"))
    assert r["realtime_factor"] is None and "not available" in r["realtime_factor_reason"]
    rt = sil.realtime(True, available=(False, "nope"))
    for regime in ("idle", "load", "footprint"):
        for k in suite.REQUIRED["sil_realtime." + regime]:
            assert rt[regime][k] is None and rt[regime][f"{k}_reason"] == "nope"


def test_footprint_sets_the_locked_run_beside_the_unlocked_one():
    def run(rss_fsw, rss_sim, mode):
        return {"extra": {"memory": {"fsw": {"vm_rss_kb": rss_fsw, "locked_kb": rss_fsw if mode else 0,
                                             "mlock_mode": mode},
                                     "sim": {"vm_rss_kb": rss_sim, "locked_kb": rss_sim if mode else 0,
                                             "mlock_mode": mode}}}}
    f = sil.footprint(run(400 * 1024, 300 * 1024, "onfault"), run(380 * 1024, 200 * 1024, None))
    assert f["fsw_rss_mb"] == 400 and f["fsw_unlocked_rss_mb"] == 380 and f["fsw_locked_mb"] == 400
    assert f["fsw_ratio"] == pytest.approx(400 / 380) and f["sim_ratio"] == pytest.approx(1.5)
    rows = sil.footprint_rows({"sil_realtime": {"footprint": f}})
    assert [r[-1] for r in rows] == ["pass", "**FAIL**"]            # 1.05x and 1.5x against 1.2x
    assert rows[0][0].startswith("real-time SIL flight software") and "onfault" in rows[0][0]
    broken = sil.footprint(run(1, 1, "onfault"), {"latency_p50_us": None, "latency_p50_us_reason": "timed out"})
    assert broken["fsw_unlocked_rss_mb"] is None and broken["fsw_unlocked_rss_mb_reason"] == "timed out"
    assert [r[-1] for r in sil.footprint_rows({"sil_realtime": {"footprint": broken}})] == ["n/m", "n/m"]


@pytest.mark.realtime
def test_realtime_loop_child_reports_shape():
    r = jitter.run_child(1.0, priority=jitter.PRIORITY, cpu=None)
    assert 40 <= r["cycles"] <= 51
    assert isinstance(r["slips"], int) and r["slips"] >= 0
    for k in ("p50_us", "p99_us", "max_us", "compute_p99_us"):
        assert math.isfinite(r[k]) and r[k] >= 0
    assert r["p50_us"] <= r["p99_us"] <= r["max_us"]
    assert set(r["tasks"]) == {"input", "control", "fdir_slow", "controllability", "plant"}
    assert set(r["rt"]) >= {"sched_fifo", "affinity", "mlockall", "messages"}
    assert r["gc"]["enabled_in_loop"] is False          # GC kept out of the cycle
    assert r["threads"]["env"]["OPENBLAS_NUM_THREADS"] == "1"
    assert r["threads"]["numpy_imported_first"] is False


def test_bench_parser_wiring(tmp_path):
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd")
    suite.add_bench_parser(sub)
    a = ap.parse_args(["bench", "--quick", "--out", str(tmp_path / "x.json"), "--only", "machine"])
    assert a.quick and a.func is suite.main_args
    assert a.func(a) == 0
    assert json.loads((tmp_path / "x.json").read_text())["machine"]["nproc"] >= 1
    assert (tmp_path / "x.md").read_text().startswith("Benchmark (quick)")
    a = ap.parse_args(["bench", "--out", str(tmp_path / "x.json"), "--only", "nosuch"])
    assert a.func(a) == 2


def test_reconfig_fault_sets_cover_every_single_jet_and_the_paper_cases():
    from ellipsled.bench import reconfig
    single = reconfig.single_fault_sets()
    assert len(single) == 3 * 18
    assert {s["failed_off"][0][0] for n, s in single if "failed_off" in s} == set(range(1, 19))
    paper = {name: s for n, s in reconfig.paper_fault_sets() for name in n.split("+")}
    assert len(reconfig.paper_fault_sets()) == 3    # cases 1, 4 and 1 with fault tolerance off: one set
    assert paper["case4"] == paper["case1-ft-off"] == paper["case1"]
    assert paper["case1"] == {"failed_off": [(1, 1.0), (2, 1.0), (17, 1.0), (18, 1.0)], "stuck_on": [], "degraded": []}
    assert [j for j, _ in paper["case2"]["stuck_on"]] == [2, 3, 4, 5, 8, 9, 10]
    assert paper["case3"]["degraded"] == [(3, 0.5), (7, 0.5), (14, 0.5), (15, 0.5)]


def test_first_reconfiguration_after_start_sanity_bound():
    """A fresh process builds the allocator as the real-time FSW does and at once requests
    the paper's case 2 fault set: the new tables are in use within a generous bound (the
    20-ms target is the benchmark's; the bound catches kernels compiled or caches built at
    the first request, which cost hundreds of ms)."""
    from ellipsled.bench import reconfig
    spec = {"stuck_on": [(j, 1.0) for j in (2, 3, 4, 5, 8, 9, 10)]}       # paper case 2
    r = reconfig._first_in_subprocess(spec)
    assert not r["from_cache"]
    assert 0.0 < r["reconfig_ms"] < 200.0, r


def _row(res, start):
    return next(r for r in suite.rows(res) if r[0].startswith(start))


def test_absolute_targets_judged_also_at_machine_speed_and_verdict_names_the_failure():
    """Absolute targets are also judged on the figure scaled by the same run's machine speed
    (bytes() p50 against the README machine's); the verdict names what failed."""
    def res(factor, p99, speedup, rtf):
        return {"machine": {"speed_factor": factor},
                "allocator": {"p50_us": 10.0, "p99_us": p99, "max_us": 300.0, "speedup": speedup, "mismatches": 0},
                "batch": {"realtime_factor": rtf}}
    slow = res(2.0, 150.0, 300.0, 150.0)          # 2x slow machine: 150 us is 75 at reference speed
    r = _row(slow, "allocator solve")
    assert r[5] == "**FAIL** (absolute)" and "at reference speed 75.0 (machine x2.00)" in r[3]
    assert _row(slow, "batch real-time")[5] == "**FAIL** (absolute)"        # 150x is 300x at speed
    both = res(2.0, 250.0, 300.0, 90.0)
    assert _row(both, "allocator solve")[5] == "**FAIL** (absolute, machine-scaled)"
    assert _row(both, "batch real-time")[5] == "**FAIL** (absolute, machine-scaled)"
    fast = res(0.5, 80.0, 100.0, 250.0)           # a fast machine does not hide a regression
    assert _row(fast, "allocator solve")[5] == "**FAIL** (ratio, machine-scaled)"
    assert _row(fast, "batch real-time")[5] == "**FAIL** (machine-scaled)"
    assert _row(res(1.0, 50.0, 300.0, 250.0), "allocator solve")[5] == "pass"
    unknown = res(None, 50.0, 300.0, 250.0)
    assert _row(unknown, "allocator solve")[5] == "pass (machine-scaled n/m)"
    assert "machine speed n/m" in _row(unknown, "allocator solve")[3]


def test_machine_section_measures_its_speed_baseline():
    m = suite.machine(True)
    assert m["speed_bytes_p50_us"] > 0 and m["speed_factor"] == m["speed_bytes_p50_us"] / suite.REFERENCE_BYTES_P50_US


def test_latency_shows_the_udp_round_trip_of_the_sil_placement_and_is_judged_by_1_ms_not_by_it():
    """The UDP round trip beside the latency is the one measured with the SIL's own placement
    when there is one (else the default one), for scale: a multiple of it is no target (the
    ratio target is the floor's, ``floor_rows``); 1 ms on the absolute scale is."""
    s = {"latency_p50_us": 500.0, "latency_p99_us": 700.0,
         "extra": {"latency_split_us": {"command_p50_us": 150.0, "command_p99_us": 200.0},
                   "fsw_frame_age_p50_us": 200.0, "fsw_frame_age_p99_us": 250.0,
                   "fsw_control_us": {"p50": 160.0, "p99": 220.0}}}
    res = {"machine": {"speed_factor": 1.0},
           "latency": {"udp_p99_us": 100.0, "sil_udp_p99_us": 200.0, "sil_zenoh_p50_us": 300.0,
                       "sil_zenoh_p99_us": 450.0}}
    rows = sil.latency_rows(res, "idle", s)
    assert "(SIL placement) 200.0" in rows[0][2] and rows[0][3].startswith("3.50x")
    assert rows[0][5] == "pass"                              # 3.5x UDP, within 1 ms
    assert "200.0 / 250.0; 160.0 / 220.0; 150.0 / 200.0" in rows[1][1]
    s["latency_p99_us"] = 1200.0                             # over 1 ms
    assert sil.latency_rows(res, "idle", s)[0][5] == "**FAIL** (absolute, machine-scaled)"
    del res["latency"]["sil_udp_p99_us"]                     # no SIL placement: the default one
    r = sil.latency_rows(res, "idle", s)[0]
    assert r[2] == "UDP round trip p99 100.0" and r[3].startswith("12.0x")


def test_shared_memory_variant_sends_every_frame_through_shared_memory_and_the_default_none():
    """The payload variants measure what they name: with ``shm`` every frame each way
    arrives as a Zenoh shared-memory reference; without it none does (two real processes
    on loopback, a short paced run)."""
    from ellipsled.bench import latency
    n = 20
    shm = latency.zenoh_roundtrip(n, 200.0, "default", shm=True, lowlatency=True)
    plain = latency.zenoh_roundtrip(n, 200.0, "default", shm=False, lowlatency=False)
    assert shm["n"] == n and plain["n"] == n
    assert shm["shm_rx_client"] >= n and shm["shm_rx_echo"] >= n
    assert plain["shm_rx_client"] == 0 and plain["shm_rx_echo"] == 0


def test_rate_rows_set_200_hz_beside_50_hz():
    def run(slips, missed, n, p99, own=None):
        return {"slips": slips, "jitter_p50_us": 1.0, "jitter_p99_us": p99, "jitter_max_us": 50.0,
                "extra": {"sim_counts": {"missed_commands": missed, "unanswered_at_start": 10},
                          "latency_samples": n, "own_slips": own,
                          "fsw_control_us": {"p50": 80.0, "p99": 160.0}}}
    res = {"sil_realtime": {"idle": run(0, 0, 500, 3.0), "idle_200hz": run(0, 0, 2000, 6.0)},
           "jitter": {"idle_200hz": {"cyclictest_p99_us": 4.0}}}
    rows = sil.rate_rows(res)
    assert rows[0][1] == "0 (0); 0 of 2000 (+10 before the first command)"
    assert rows[0][2] == "50 Hz 0 (0); 0 of 500 (+10 before the first command)" and rows[0][-1] == "pass"
    assert rows[1][3].startswith("1.50x") and rows[1][-1].startswith("pass")       # 6 us against cyclictest's 4
    res["sil_realtime"]["idle_200hz"] = run(0, 3, 1997, 6.0)         # three commands missed: fails
    assert sil.rate_rows(res)[0][-1] == "**FAIL**"
    res["sil_realtime"]["idle_200hz"] = run(2, 0, 2000, 6.0, own=0)  # two slips, both the host's: passes
    assert sil.rate_rows(res)[0][1].startswith("0 (2)") and sil.rate_rows(res)[0][-1] == "pass"
    res["sil_realtime"]["idle_200hz"] = run(2, 0, 2000, 6.0, own=1)
    assert sil.rate_rows(res)[0][-1] == "**FAIL**"
    res["sil_realtime"]["idle_200hz"] = run(0, 0, 1999, 6.0)         # the plant past its own deadline once:
    res["sil_realtime"]["idle_200hz"]["extra"]["sim_counts"]["missed_plant_late"] = 1   # not the FSW's miss
    assert sil.rate_rows(res)[0][1] == ("0 (0); 0 of 2000 (+1 the plant reached past its deadline) "
                                        "(+10 before the first command)") and sil.rate_rows(res)[0][-1] == "pass"
    assert sil.rate_rows({"sil_realtime": {"idle": run(0, 0, 1, 1.0)}}) == []


def test_latency_floor_is_the_same_runs_round_trip_at_the_runs_rate_plus_the_control_task():
    def run(p99, ctl99):
        return {"latency_p99_us": p99, "extra": {"fsw_control_us": {"p50": 50.0, "p99": ctl99},
                                                 "latency_split_us": {}}}
    def part(p99):
        return {"p50_us": 1.0, "p99_us": p99, "samples_us": [p99] * 100, "n": 100, "lost": 0}
    res = {"sil_realtime": {"idle": run(800.0, 200.0), "idle_200hz": run(520.0, 100.0),
                            "floor_50hz": sil.pooled_floor(part(500.0), part(500.0), 50.0),
                            "floor_200hz": sil.pooled_floor(part(400.0), part(400.0), 200.0)},
           "latency": {"sil_zenoh_p99_us": 1.0}}                        # the 100-Hz figure is not the floor
    f = sil.latency_floor(res, "idle", 50.0)
    assert f["floor_p99_us"] == 700.0 and f["remainder_us"] == 100.0 and abs(f["over_floor"] - 800 / 700) < 1e-12
    rows = sil.floor_rows(res)
    assert [r[-1] for r in rows[::2]] == ["**FAIL**", "pass"]            # 800 / 700 = 1.14x; 520 / 500 = 1.04x
    assert rows[2][1] == "520.0 (20.0)" and "= Zenoh + codec round trip 400.0" in rows[2][2]
    assert "before / after the run 400.0 / 400.0) + FSW control task 100.0" in rows[2][2]
    assert sil.latency_floor({"sil_realtime": {"idle": run(800.0, 200.0)}}, "idle", 50.0)["floor_p99_us"] is None


def test_the_floor_pools_the_round_trips_measured_on_both_sides_of_the_run():
    """Pooled, not averaged: the p99 over every round trip of both parts (independent truth:
    numpy's percentile over the concatenation); a failed part nulls the floor with its reason."""
    import numpy as np
    rng = np.random.default_rng(3)
    a, b = rng.gamma(4.0, 30.0, 1000), rng.gamma(4.0, 90.0, 1000)      # a quiet side and a noisy one
    before = {"p50_us": float(np.median(a)), "p99_us": float(np.percentile(a, 99)), "samples_us": list(a),
              "n": 1000, "lost": 1}
    after = {"p50_us": float(np.median(b)), "p99_us": float(np.percentile(b, 99)), "samples_us": list(b),
             "n": 1000, "lost": 0}
    f = sil.pooled_floor(before, after, 200.0)
    both = np.concatenate([a, b])
    assert f["p99_us"] == float(np.percentile(both, 99)) and f["n"] == 2000 and f["lost"] == 1
    assert before["p99_us"] < f["p99_us"] < after["p99_us"]
    assert f["parts"]["before"]["p99_us"] == before["p99_us"] and "samples_us" not in f["parts"]["after"]
    bad = sil.pooled_floor(before, {"p99_us": None, "p99_us_reason": "RuntimeError: echo died"}, 200.0)
    assert bad["p99_us"] is None and "after: RuntimeError: echo died" in bad["p99_us_reason"]
    assert sil.latency_floor({"sil_realtime": {"idle_200hz": {"latency_p99_us": 500.0,
                                                              "extra": {"fsw_control_us": {"p99": 50.0}}},
                                               "floor_200hz": bad}}, "idle_200hz", 200.0)["over_floor"] is None



def test_the_control_task_row_sets_the_sil_beside_batch_over_the_same_span_with_and_without_the_lp_cycles():
    def run(p99, rest):
        return {"extra": {"fsw_control_us": {"p50": 50.0, "p99": p99, "lp_cycles": 28, "p99_without_lp": rest}}}
    span = {"p50_us": 20.0, "p99_us": 60.0, "span_s": 10.0, "lp_cycles": 28, "p99_without_lp_us": 25.0}
    res = {"machine": {"speed_factor": 1.0},
           "cycle": {"control_p99_us": 40.0, "control_span_50hz": span, "control_span_200hz": dict(span, p99_us=50.0)},
           "sil_realtime": {"idle": run(150.0, 90.0), "idle_200hz": run(90.0, 45.0)}}
    rows = sil.control_rows(res)
    # 150 / 60 = 2.5x the same span's p99 (not 150 / 40, the whole entry's): fails; 90 / 50 = 1.8x passes
    assert rows[0][3].startswith("2.50x (p99; without the LP's cycles 3.60x)") and rows[0][-1].startswith("**FAIL** (ratio")
    assert "batch first 10.0 s 20.0 / 60.0 (25.0, 28 LP cycles); whole batch entry p99 40.0" == rows[0][2]
    assert rows[1][3].startswith("1.80x") and rows[1][-1] == "pass"
    assert rows[0][1].endswith("(90.0, 28 LP cycles)")                    # an older run: no tenths
    res["sil_realtime"]["idle"]["extra"]["fsw_control_us"]["p50_by_tenth"] = {"lowest": 18.0, "median": 20.0,
                                                                              "highest": 41.0}
    assert sil.control_rows(res)[0][1].endswith("(90.0, 28 LP cycles; tenths 18.0 / 20.0 / 41.0)")
    assert sil.control_rows({"cycle": {}}) == []                  # no SIL run, no row


def test_the_batch_span_is_the_first_cycles_of_the_entry_and_its_lp_cycles_are_counted_apart():
    from ellipsled.bench import cycle
    c = np.full(1000, 20.0)
    lp = np.zeros(1000, dtype=bool)
    c[1:29], lp[1:29] = 200.0, True          # the LP's cycles at the start: 28 of the first 500
    c[700:720] = 900.0                       # slow cycles after the span: not in it
    f = cycle.span_figures(c, lp, 10.0, 0.02)
    assert f["runs"] == 500 and f["lp_cycles"] == 28 and f["p99_us"] == 200.0 and f["max_us"] == 200.0
    assert f["p99_without_lp_us"] == 20.0


def test_the_rehearsal_row_sets_the_run_without_it_beside_the_idle_run():
    res = {"sil_realtime": {"idle": {"latency_p50_us": 800.0, "latency_p99_us": 1100.0},
                            "idle_no_rehearse": {"latency_p50_us": 920.0, "latency_p99_us": 1200.0}}}
    r = [x for x in sil.realtime_rows(res) if "--no-rehearse" in x[0]]
    assert len(r) == 1 and r[0][1] == "920.0 / 1200" and r[0][2] == "rehearsal on 800.0 / 1100"
    assert r[0][3].startswith("1.15x")


def test_settle_waits_for_the_probe_back_at_the_baseline_and_gives_up_at_its_bound():
    from ellipsled.bench import settle
    t = [0.0]

    def probe_of(values):
        it = iter(values)

        def probe():
            t[0] += 1.0                                    # each probe takes a second
            return next(it)
        return probe
    # slow, then two running within the tolerance (one in between is not enough)
    st = settle.settle(100.0, 30.0, probe_of([200.0, 120.0, 190.0, 110.0, 125.0, 500.0]), clock=lambda: t[0])
    assert st["settled"] and st["probes_us"] == [200.0, 120.0, 190.0, 110.0, 125.0] and st["waited_s"] == 5.0
    t[0] = 0.0
    st = settle.settle(100.0, 3.0, probe_of([200.0] * 10), clock=lambda: t[0])
    assert not st["settled"] and st["waited_s"] == 3.0 and st["last_over_baseline"] == 2.0


def test_the_probe_times_its_piece_right_after_each_sleep():
    from ellipsled.bench import settle
    log, t = [], [0]

    def sleep(s):
        log.append(("sleep", s))
        t[0] += 1_000_000_000

    prices = iter([999_000, 50_000, 90_000, 60_000])     # ns; the first call is not timed

    def piece():
        log.append("piece")
        t[0] += next(prices)
    p = settle.probe_us(3, sleep=sleep, clock_ns=lambda: t[0], piece=piece)
    assert log == ["piece"] + [("sleep", settle.SLEEP_S), "piece"] * 3
    assert p == 60.0                                     # the p50 of 50, 90, 60 us: the sleeps not in it


def test_real_time_sections_are_measured_after_a_settle_phase_recorded_beside_them(tmp_path):
    probes = iter([100.0, 100.0, 100.0, 300.0, 110.0, 105.0, 90.0, 95.0])
    order = []
    res = suite.run_suite(True, None, sections={
        "codec": lambda q: order.append("codec") or {},
        "jitter": lambda q: order.append("jitter") or {},
        "flood": lambda q: order.append("flood") or {},
    }, say=lambda m: order.append(m) if "settled" in m else None, probe=lambda: next(probes))
    assert res["settle_baseline"]["probe_us"] == 100.0
    assert "settle" not in res["codec"]
    assert res["jitter"]["settle"]["probes_us"] == [300.0, 110.0, 105.0] and res["jitter"]["settle"]["settled"]
    assert res["flood"]["settle"]["probes_us"] == [90.0, 95.0]
    assert all("steal_share_in_section" in res[n]["settle"] for n in ("jitter", "flood"))
    assert [x for x in order if not x.startswith("bench: host")] == ["codec", "jitter", "flood"]
    assert order.index("jitter") > next(i for i, x in enumerate(order) if x.startswith("bench: host settled"))
    row = next(r for r in suite.rows(res) if r[0].startswith("host state"))
    assert row[3] == "not settled: none"


def test_the_hosts_steal_share_is_what_it_took_of_the_cpu_time_between_two_readings():
    from ellipsled.bench import settle
    assert settle.steal_share((1000, 10), (1400, 30)) == pytest.approx(0.05)
    assert settle.steal_share(None, (1400, 30)) is None and settle.steal_share((1400, 30), (1400, 30)) is None
    now = settle.cpu_ticks()
    assert now is None or (now[0] >= now[1] >= 0)
