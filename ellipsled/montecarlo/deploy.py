"""Deploy-point statistics of a guided campaign: miss percentiles and the 99 % ellipse,
beside the flown Mars landers (docs/fsw/entry-guidance.md).

``python -m ellipsled.montecarlo.deploy runs/mc-guided`` reads the campaign's
results.parquet and prints (and writes deploy.md) the table.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

CHI2_2DOF_99 = -2.0 * math.log(0.01)     # 9.21: P(chi^2 with 2 dof <= x) = 0.99
MSL_REQUIREMENT_KM = 12.5                # deploy within 12.5 km of target (requirement)
MSL_FLOWN_KM = 2.4                       # landed 2.4 km from target
M2020_ELLIPSE_KM = (7.7, 6.6)            # landing ellipse, full axes


def ellipse_99(down_km: np.ndarray, cross_km: np.ndarray) -> tuple[float, float, float]:
    """Full axes (major, minor) [km] of the 99 % ellipse of a bivariate normal fitted to
    the (downrange, crossrange) errors, and the major axis's angle from downrange [deg]."""
    cov = np.cov(np.vstack([down_km, cross_km]))
    w, v = np.linalg.eigh(cov)
    major, minor = 2.0 * math.sqrt(CHI2_2DOF_99 * max(w[1], 0.0)), 2.0 * math.sqrt(CHI2_2DOF_99 * max(w[0], 0.0))
    return major, minor, math.degrees(math.atan2(v[1, 1], v[0, 1]))


# end reasons with a deploy point (sim/plant.py done()): the plant's own end condition, the FSW's
# command, or the box's edge (deployed, but a failure of the run)
DEPLOY_REASONS = ("mach", "speed", "deploy", "box_edge")


def deploy_stats(rows: dict) -> dict:
    """From columns deploy_miss_km, downrange_err_km, crossrange_err_km and, when present,
    end_reason and run_id. Only a run that reached the deploy condition (end reason Mach or
    speed) has a deploy point: the figures of a run that skipped out, ran out of time or
    reached the end altitude first are where it stopped, not a deploy (a skip-out's is
    thousands of km away and would make the ellipse), so such runs are counted and listed,
    not used; the requirement's share is also given over all runs (a run that never
    deployed is outside it)."""
    miss = np.asarray(rows["deploy_miss_km"], dtype=float)
    ok = np.isfinite(miss)
    reasons = rows.get("end_reason")
    if reasons is not None:
        ok &= np.array([r in DEPLOY_REASONS for r in reasons], dtype=bool)
    down = np.asarray(rows["downrange_err_km"], dtype=float)[ok]
    cross = np.asarray(rows["crossrange_err_km"], dtype=float)[ok]
    m = miss[ok]
    ids = rows.get("run_id", range(len(miss)))
    out = {"runs": int(len(miss)), "with_deploy": int(ok.sum()),
           "no_deploy": [{"run": int(i), "end_reason": (reasons[k] if reasons is not None else "no figure")}
                         for k, i in enumerate(ids) if not ok[k]]}
    if ok.sum() >= 3:
        out.update({f"miss_p{q}_km": float(np.percentile(m, q)) for q in (50, 90, 99)})
        out["miss_max_km"] = float(m.max())
        out["within_msl_requirement"] = float(np.mean(m <= MSL_REQUIREMENT_KM))
        out["within_msl_requirement_all"] = float(np.sum(m <= MSL_REQUIREMENT_KM) / len(miss))
        out["ellipse99_major_km"], out["ellipse99_minor_km"], out["ellipse99_angle_deg"] = ellipse_99(down, cross)
        out["downrange_mean_km"], out["crossrange_mean_km"] = float(down.mean()), float(cross.mean())
    return out


def table(st: dict) -> str:
    if "miss_p50_km" not in st:
        return f"{st['with_deploy']} of {st['runs']} runs reached the deploy condition: too few for statistics"
    return "\n".join([
        "| | this campaign | MSL (2012) | Mars 2020 |",
        "|---|---|---|---|",
        f"| deploy miss p50 / p90 / p99 [km] | {st['miss_p50_km']:.2f} / {st['miss_p90_km']:.2f} / "
        f"{st['miss_p99_km']:.2f} | flown {MSL_FLOWN_KM} | |",
        f"| requirement | {100 * st['within_msl_requirement']:.1f} % of deploys within 12.5 km "
        f"({100 * st['within_msl_requirement_all']:.1f} % of all runs) | deploy within {MSL_REQUIREMENT_KM} km | |",
        f"| 99 % ellipse (full axes) [km] | {st['ellipse99_major_km']:.2f} x {st['ellipse99_minor_km']:.2f} | "
        f"| {M2020_ELLIPSE_KM[0]} x {M2020_ELLIPSE_KM[1]} (landing) |",
        f"| runs with a deploy point | {st['with_deploy']} of {st['runs']}"
        + (" (not deployed: " + ", ".join(f"run {r['run']} {r['end_reason']}" for r in st["no_deploy"]) + ")"
           if st["no_deploy"] else "") + " | | |",
    ])


def main(argv: list[str] | None = None) -> int:
    import pyarrow.dataset as ds
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m ellipsled.montecarlo.deploy CAMPAIGN_DIR", file=sys.stderr)
        return 2
    d = Path(args[0])
    t = ds.dataset(d / "results.parquet").to_table(
        columns=["run_id", "end_reason", "deploy_miss_km", "downrange_err_km", "crossrange_err_km"]).to_pydict()
    t = {k: ([math.nan if v is None else v for v in col] if k.endswith("_km") else col) for k, col in t.items()}
    st = deploy_stats(t)
    text = table(st)
    (d / "deploy.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
