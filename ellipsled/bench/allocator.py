"""Allocator benchmark (docs/benchmarks.md): solve time of fsw.allocation.Allocator
against a plain HiGHS MILP of the same problem in the same run, with optimality checked on
every demand against HiGHS (mip_rel_gap = 0) and exhaustive enumeration.

The jet-health configurations and the demand generator are shared with the tests
(tests/test_allocation_*.py) so that both exercise the same cases.

    python -m ellipsled.bench.allocator [--quick] [--out runs/bench_allocator.json]
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from common.model import load_vehicle
from fsw.allocation import Allocator, effective_model
from fsw.allocation.model import spill_of
from fsw.allocation.reference import solve_enumeration_many, solve_highs
from fsw.allocation.tables import Workspace, build_tables
from fsw.health import DEGRADED, FAILED_OFF, STUCK_ON, JetHealth
from fsw.params import load_params

from .rows import Row, fmt, ge, row, speed

TARGETS = {"p99_us_max": 100.0, "speedup_min": 200.0, "mismatches": 0}


@dataclass(frozen=True)
class Case:
    """One allocation configuration: jet health plus the objective's parameters."""
    name: str
    health: JetHealth
    w: tuple[float, float, float] = (1.0, 1.0, 1.0)
    penalty_per_N: float = 0.01
    fault_tolerance: bool = True
    spill_jets: float = 0.0   # box's wrong-sign allowance in largest single-jet torques; 0: sign box




def cases() -> list[Case]:
    """The ≥ 20 configurations of the tests and the benchmark: nominal, the paper's cases
    1-3 sets, single and mixed faults, identical columns split by degradation, and
    objective variants (weights, zero penalty = maximal ties, a zero weight)."""
    out = [
        Case("nominal", JetHealth.of()),
        Case("case1-failed_off-1-2-17-18", JetHealth.of(failed_off=(1, 2, 17, 18))),
        Case("case2-stuck_on-2-3-4-5-8-9-10", JetHealth.of(stuck_on=(2, 3, 4, 5, 8, 9, 10))),
        Case("case3-degraded-3-7-14-15", JetHealth.of(degraded=((3, .5), (7, .5), (14, .5), (15, .5)))),
        Case("failed_off-1", JetHealth.of(failed_off=(1,))),
        Case("failed_off-13", JetHealth.of(failed_off=(13,))),
        Case("failed_off-1-6", JetHealth.of(failed_off=(1, 2, 3, 4, 5, 6))),
        Case("stuck_on-1", JetHealth.of(stuck_on=(1,))),
        Case("stuck_on-13", JetHealth.of(stuck_on=(13,))),
        Case("stuck_on-13-16", JetHealth.of(stuck_on=(13, 16))),
        Case("stuck_on-1-7", JetHealth.of(stuck_on=(1, 7))),
        Case("degraded-2-0.3", JetHealth.of(degraded=((2, .3),))),
        Case("degraded-13-0.7", JetHealth.of(degraded=((13, .7),))),
        Case("degraded-1-7-0.5-identical", JetHealth.of(degraded=((1, .5), (7, .5)))),
        Case("inhibited-4-10", JetHealth.of(inhibited=(4, 10))),
        Case("mixed-f1-s8-d14-i6", JetHealth.of(failed_off=(1,), stuck_on=(8,), degraded=((14, .5),), inhibited=(6,))),
        Case("mixed-f13-14-s15", JetHealth.of(failed_off=(13, 14), stuck_on=(15,))),
        Case("mixed-s5-d11-0.4-f18", JetHealth.of(stuck_on=(5,), degraded=((11, .4),), failed_off=(18,))),
        Case("nominal-weights-1-2-0.5", JetHealth.of(), w=(1.0, 2.0, 0.5), penalty_per_N=0.05),
        Case("nominal-zero-penalty", JetHealth.of(), penalty_per_N=0.0),
        Case("case1-zero-yaw-weight", JetHealth.of(failed_off=(1, 2, 17, 18)), w=(1.0, 1.0, 0.0)),
        Case("case2-heavy-penalty", JetHealth.of(stuck_on=(2, 3, 4, 5, 8, 9, 10)), penalty_per_N=1.0),
        Case("ft-off-with-case1-health", JetHealth.of(failed_off=(1, 2, 17, 18)), fault_tolerance=False),
        # the spill box (wrong-sign torque within one largest jet per axis), nominal and after faults
        # that remove the exactly cancelling pairs
        Case("nominal-spill", JetHealth.of(), w=(3.0, 1.0, 1.0), spill_jets=1.0),
        Case("case2-spill", JetHealth.of(stuck_on=(2, 3, 4, 5, 8, 9, 10)), w=(3.0, 1.0, 1.0), spill_jets=1.0),
        Case("failed_off-7-16-18-degraded-1-3-8-spill",
             JetHealth.of(failed_off=(7, 16, 18), degraded=((1, .5), (3, .6), (8, .8))),
             w=(3.0, 1.0, 1.0), spill_jets=1.0),
        Case("mixed-f13-14-s15-spill-half", JetHealth.of(failed_off=(13, 14), stuck_on=(15,)), spill_jets=0.5),
    ]
    rng = np.random.default_rng(20110807)
    for i in range(3):                      # seeded random mixed faults
        h = JetHealth()
        for k in rng.choice(18, size=5, replace=False):
            kind = rng.integers(4)
            if kind == 0:
                h.set(k + 1, FAILED_OFF)
            elif kind == 1:
                h.set(k + 1, STUCK_ON)
            elif kind == 2:
                h.set(k + 1, DEGRADED, float(np.round(rng.uniform(0.2, 0.9), 2)))
            else:
                h.inhibited[k] = True
        out.append(Case(f"random-mixed-{i}", h))
    return out


def demands(T: np.ndarray, thrust: np.ndarray, case: Case, n: int, seed: int) -> np.ndarray:
    """n demands [N m] of every kind: random at three scales, zeros on some axes, exactly
    achievable torques (and their negatives), huge, tiny, pure-axis."""
    rng = np.random.default_rng(seed)
    usable, cols, b, _ = effective_model(T, thrust, case.health, case.penalty_per_N,
                                         case.fault_tolerance)
    kinds = 8
    k = np.arange(n) % kinds
    D = np.empty((n, 3))
    for i in range(n):
        if k[i] == 0:
            D[i] = rng.normal(0.0, 100.0, 3)
        elif k[i] == 1:
            D[i] = rng.normal(0.0, 600.0, 3)
        elif k[i] == 2:                         # zeros on one or two axes
            D[i] = rng.normal(0.0, 300.0, 3)
            D[i, rng.choice(3, size=rng.integers(1, 3), replace=False)] = 0.0
        elif k[i] == 3:                         # exactly achievable (incl. the stuck bias)
            u = (rng.random(T.shape[1]) < rng.uniform(0.1, 0.6)) & usable
            D[i] = b + cols @ u
        elif k[i] == 4:                         # achievable, negated, or achievable + tiny
            u = (rng.random(T.shape[1]) < 0.3) & usable
            D[i] = (cols @ u) * rng.choice([-1.0, 1.0]) + rng.choice([0.0, 1e-7, -1e-7], 3)
        elif k[i] == 5:                         # huge
            D[i] = rng.normal(0.0, 1.0, 3) * 10.0 ** rng.uniform(4, 6)
        elif k[i] == 6:                         # tiny
            D[i] = rng.normal(0.0, 1.0, 3) * 10.0 ** rng.uniform(-9, -2)
        else:                                   # pure axis
            D[i] = 0.0
            D[i, rng.integers(3)] = rng.choice([-1.0, 1.0]) * 10.0 ** rng.uniform(0, 3.5)
    return D


def params_for(case: Case) -> dict[str, float]:
    return {"allocator.w_roll": case.w[0], "allocator.w_pitch": case.w[1],
            "allocator.w_yaw": case.w[2], "allocator.penalty_per_N": case.penalty_per_N,
            "allocator.fault_tolerance": float(case.fault_tolerance),
            "allocator.spill_jets": case.spill_jets}


def rebuild_figures(T: np.ndarray, thrust: np.ndarray, reps: int = 9) -> dict:
    """Table rebuild time per configuration (``reps`` builds each, one work buffer set, as
    a building thread has; CPU time of this thread, so other processes' load is not
    counted, and wall time), then the asynchronous mode: from the nominal tables, each
    configuration is requested with set_health and solve() runs back to back until the
    switch; the longest solve() meanwhile is the figure ("async interim solve max")."""
    ws = Workspace()
    per_case = []
    for case in cases():
        health = case.health if case.fault_tolerance else JetHealth()
        usable, cols, bias, c = effective_model(T, thrust, health, case.penalty_per_N)
        cpu, wall = [], []
        for _ in range(reps):
            t0, c0 = time.perf_counter(), time.thread_time()
            t = build_tables(usable, cols, bias, c, np.array(case.w), spill_of(T, case.spill_jets), ws)
            cpu.append(time.thread_time() - c0)
            wall.append(time.perf_counter() - t0)
        per_case.append({"case": case.name, "candidates": len(t.pen), "raw": t.n_raw,
                         "rebuild_ms": {"p50": float(np.median(wall) * 1e3), "max": float(max(wall) * 1e3),
                                        "min": float(min(wall) * 1e3)},
                         "rebuild_cpu_ms": {"p50": float(np.median(cpu) * 1e3), "max": float(max(cpu) * 1e3),
                                            "min": float(min(cpu) * 1e3)},
                         "table_MB": t.nbytes / 2**20})
    rng = np.random.default_rng(7)
    al = Allocator(T, thrust, load_params(Allocator.PARAMS), async_rebuild=True, prebuild_single_faults=True)
    al.wait_idle(30.0)
    al.poll()
    prebuilt_mb = al.tables_nbytes["prebuilt"] / 2**20
    workspace_mb = al.tables_nbytes["workspace"] / 2**20
    for case, rec in zip(cases(), per_case):
        al.set_params(params_for(case))          # previous tables serve meanwhile
        al.wait_idle(30.0)
        al.solve(np.zeros(3))
        al.set_health(case.health)
        solve_us, n_interim = [], 0
        t_end = time.perf_counter() + 10.0
        while al.reconfig_pending and time.perf_counter() < t_end:
            d = rng.normal(0.0, 300.0, 3)
            t0 = time.perf_counter_ns()
            al.solve(d)
            solve_us.append((time.perf_counter_ns() - t0) / 1e3)
            n_interim += al.interim
        rec["async"] = {"interim_solves": n_interim,
                        "interim_solve_max_us": float(max(solve_us)) if solve_us else 0.0,
                        "switch_latency_ms": al.reconfig_latency_s * 1e3,
                        "from_cache": bool(al.tables_from_cache)}
        al.wait_idle(30.0)
    al.close()
    wall_max = [r["rebuild_ms"]["max"] for r in per_case]
    cpu_p50 = [r["rebuild_cpu_ms"]["p50"] for r in per_case]
    interim = [r["async"]["interim_solve_max_us"] for r in per_case]
    return {"per_case": per_case,
            "rebuild_ms_p50_worst_case": float(max(r["rebuild_ms"]["p50"] for r in per_case)),
            "rebuild_ms_max": float(max(wall_max)),
            "rebuild_cpu_ms_p50_worst_case": float(max(cpu_p50)),
            "async_interim_solve_max_us": float(max(interim)),
            "async_interim_solves": int(sum(r["async"]["interim_solves"] for r in per_case)),
            "prebuilt_single_faults_MB": prebuilt_mb, "workspace_MB": workspace_mb}


def run(quick: bool) -> dict:
    """Solve time of the allocator vs HiGHS over ≥ 10,000 demands on all cases, objective
    mismatches against both references, and the table rebuild time per configuration."""
    v = load_vehicle("ellipsled")
    T, thrust = v.torque_matrix_Nm, v.thrust_N
    all_cases = cases()
    n_per_case = -(-10_000 // len(all_cases))          # ≥ 10,000 demands in total
    highs_per_case = 40 if quick else n_per_case
    al = Allocator(T, thrust, load_params(Allocator.PARAMS))
    ours_ns, highs_ns, rebuild_ms = [], [], []
    mism_enum = mism_highs = mism_u = n_deg = mism_flown = 0
    flown_ns, flown_cpu_ns = [], []     # wall; CPU time of this thread (what host preemption leaves out)
    n_dem = n_highs = 0
    gc.disable()
    try:
        for ci, case in enumerate(all_cases):
            al.set_params(params_for(case))
            t0 = time.perf_counter()
            al.set_health(case.health)
            rebuild_ms.append({"case": case.name, "set_health_ms": (time.perf_counter() - t0) * 1e3,
                               "rebuild_ms": al.rebuild_time_s * 1e3, "candidates": al.n_candidates})
            D = demands(T, thrust, case, n_per_case, seed=1000 + ci)
            U_e, obj_e, deg_e = solve_enumeration_many(T, thrust, case.health, np.array(case.w),
                                                       case.penalty_per_N, D, case.fault_tolerance,
                                                       spill_of(T, case.spill_jets))
            # the allocator's solves back to back, HiGHS's after them: a HiGHS MILP between two
            # solves leaves the next one on cold caches, and the full run (HiGHS on every demand)
            # would time that instead of the solve the quick run times
            ours = []
            for i, d in enumerate(D):
                t = time.perf_counter_ns()
                u = al.solve(d)
                ours_ns.append(time.perf_counter_ns() - t)
                n_dem += 1
                n_deg += al.degraded
                if abs(al.objective - obj_e[i]) > 1e-7 + 1e-12 * abs(obj_e[i]) or al.degraded != deg_e[i]:
                    mism_enum += 1
                if not np.array_equal(u, U_e[i]):
                    mism_u += 1
                if i < highs_per_case:
                    ours.append((al.objective, al.degraded))
            for d, (ours_obj, ours_deg) in zip(D, ours):
                t = time.perf_counter_ns()
                _, obj_h, deg_h = solve_highs(T, thrust, case.health, np.array(case.w),
                                              case.penalty_per_N, d, case.fault_tolerance,
                                              spill_of(T, case.spill_jets))
                highs_ns.append(time.perf_counter_ns() - t)
                n_highs += 1
                if abs(ours_obj - obj_h) > 1e-6 + 1e-9 * abs(obj_h) or ours_deg != deg_h:
                    mism_highs += 1
        # the box the FSW flies (allocator.spill_jets default), every configuration on the same demands
        spill_flown = load_params(Allocator.PARAMS)["allocator.spill_jets"]
        for ci, case in enumerate(all_cases):
            al.set_params({**params_for(case), "allocator.spill_jets": spill_flown})
            al.set_health(case.health)
            D = demands(T, thrust, case, n_per_case, seed=1000 + ci)
            _, obj_e, deg_e = solve_enumeration_many(T, thrust, case.health, np.array(case.w),
                                                     case.penalty_per_N, D, case.fault_tolerance,
                                                     spill_of(T, spill_flown))
            for i, d in enumerate(D):
                c, t = time.thread_time_ns(), time.perf_counter_ns()
                al.solve(d)
                flown_ns.append(time.perf_counter_ns() - t)
                flown_cpu_ns.append(time.thread_time_ns() - c)
                if abs(al.objective - obj_e[i]) > 1e-7 + 1e-12 * abs(obj_e[i]) or al.degraded != deg_e[i]:
                    mism_flown += 1
    finally:
        gc.enable()
    reb = rebuild_figures(T, thrust)
    flown_us = np.array(flown_ns) / 1e3
    f50, f99 = np.percentile(flown_us, [50, 99])
    fc50, fc99 = np.percentile(np.array(flown_cpu_ns) / 1e3, [50, 99])
    ours_us = np.array(ours_ns) / 1e3
    highs_us = np.array(highs_ns) / 1e3
    p50, p99 = np.percentile(ours_us, [50, 99])
    h50, h99 = np.percentile(highs_us, [50, 99])
    return {
        "figure": "allocator solve time per demand [us]",
        "p50_us": float(p50), "p99_us": float(p99), "max_us": float(ours_us.max()),
        "highs_p50_us": float(h50), "highs_p99_us": float(h99), "highs_max_us": float(highs_us.max()),
        "speedup": float(h50 / p50), "speedup_basis": "HiGHS p50 / allocator p50 (same run)",
        "speedup_p99": float(h99 / p99),
        "flown_spill_jets": float(spill_flown),
        "flown_p50_us": float(f50), "flown_p99_us": float(f99), "flown_max_us": float(flown_us.max()),
        "flown_cpu_p50_us": float(fc50), "flown_cpu_p99_us": float(fc99),
        "flown_speedup": float(h50 / f50),
        "flown_mismatches_vs_enumeration": int(mism_flown),
        "mismatches": int(mism_enum + mism_highs + mism_flown),
        "mismatches_vs_enumeration": int(mism_enum), "mismatches_vs_highs": int(mism_highs),
        "u_differs_from_enumeration_tiebreak": int(mism_u),
        "demands": int(n_dem), "highs_demands": int(n_highs),
        "highs_note": ("quick: HiGHS on the first %d demands of each configuration" % highs_per_case
                       if quick else "HiGHS on every demand"),
        "degraded_demands": int(n_deg),
        "configs": len(all_cases),
        "set_health_rebuild_ms_max": float(max(r["rebuild_ms"] for r in rebuild_ms)),
        "rebuild_ms_p50_worst_case": reb["rebuild_ms_p50_worst_case"],
        "rebuild_ms_max": reb["rebuild_ms_max"],
        "rebuild_cpu_ms_p50_worst_case": reb["rebuild_cpu_ms_p50_worst_case"],
        "async_interim_solve_max_us": reb["async_interim_solve_max_us"],
        "async_interim_solves": reb["async_interim_solves"],
        "prebuilt_single_faults_MB": reb["prebuilt_single_faults_MB"],
        "workspace_MB": reb["workspace_MB"],
        "load_avg_1min": float(os.getloadavg()[0]),
        "rebuild": reb["per_case"],
        "set_health": rebuild_ms,
        "targets": dict(TARGETS),
        "pass": bool(max(p99, f99) <= TARGETS["p99_us_max"] and h50 / max(p50, f50) >= TARGETS["speedup_min"]
                     and mism_enum + mism_highs + mism_flown == TARGETS["mismatches"]),
    }


def rows(res: dict) -> list[Row]:
    a = res.get("allocator") or {}
    if not a:
        return []
    t = TARGETS
    return [
        row("allocator solve, each configuration's own box p50 / p99 / max [us]",
            f"{fmt(a.get('p50_us'))} / {fmt(a.get('p99_us'))} / {fmt(a.get('max_us'))}",
            f"HiGHS {fmt(a.get('highs_p50_us'))} / {fmt(a.get('highs_p99_us'))}",
            f"{fmt(a.get('speedup'))}x (p50)", f"p99 <= {t['p99_us_max']:g} us, >= {t['speedup_min']:g}x",
            ge(a.get("speedup"), t["speedup_min"]), absolute=(a.get("p99_us"), t["p99_us_max"], "<="),
            machine=speed(res)),
        row(f"  the flown box (spill {fmt(a.get('flown_spill_jets'))} jet) on every configuration p50 / p99 / max [us]",
            f"{fmt(a.get('flown_p50_us'))} / {fmt(a.get('flown_p99_us'))} / {fmt(a.get('flown_max_us'))}",
            f"HiGHS {fmt(a.get('highs_p50_us'))} / {fmt(a.get('highs_p99_us'))}",
            f"{fmt(a.get('flown_speedup'))}x (p50); CPU time p50 / p99 {fmt(a.get('flown_cpu_p50_us'))} / "
            f"{fmt(a.get('flown_cpu_p99_us'))}", f"p99 <= {t['p99_us_max']:g} us, >= {t['speedup_min']:g}x",
            ge(a.get("flown_speedup"), t["speedup_min"]), absolute=(a.get("flown_p99_us"), t["p99_us_max"], "<="),
            machine=speed(res)),
        row(f"allocator optimality mismatches ({fmt(a.get('demands'))} demands)", fmt(a.get("mismatches")),
            f"HiGHS on {fmt(a.get('highs_demands'))}, enumeration on all (both boxes)", "", f"{t['mismatches']}",
            None if a.get("mismatches") is None else a.get("mismatches") == t["mismatches"]),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="HiGHS on a subset of demands only")
    ap.add_argument("--out", default="runs/bench_allocator.json")
    a = ap.parse_args(argv)
    res = run(a.quick)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=2))
    short = {k: v for k, v in res.items() if k not in ("rebuild", "set_health")}
    print(json.dumps(short, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
