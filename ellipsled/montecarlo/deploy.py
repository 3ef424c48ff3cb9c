"""Deploy-point statistics of a guided campaign: miss percentiles and the 99 % ellipse,
beside the flown Mars landers (spec 60-guidance.md).

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


def deploy_stats(rows: dict) -> dict:
    """From columns deploy_miss_km, downrange_err_km, crossrange_err_km, completed (runs
    without a deploy figure are counted, not used)."""
    miss = np.asarray(rows["deploy_miss_km"], dtype=float)
    ok = np.isfinite(miss)
    down = np.asarray(rows["downrange_err_km"], dtype=float)[ok]
    cross = np.asarray(rows["crossrange_err_km"], dtype=float)[ok]
    m = miss[ok]
    out = {"runs": int(len(miss)), "with_deploy": int(ok.sum())}
    if ok.sum() >= 3:
        out.update({f"miss_p{q}_km": float(np.percentile(m, q)) for q in (50, 90, 99)})
        out["miss_max_km"] = float(m.max())
        out["within_msl_requirement"] = float(np.mean(m <= MSL_REQUIREMENT_KM))
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
        f"| requirement | {100 * st['within_msl_requirement']:.1f} % within 12.5 km | deploy within "
        f"{MSL_REQUIREMENT_KM} km | |",
        f"| 99 % ellipse (full axes) [km] | {st['ellipse99_major_km']:.2f} x {st['ellipse99_minor_km']:.2f} | "
        f"| {M2020_ELLIPSE_KM[0]} x {M2020_ELLIPSE_KM[1]} (landing) |",
        f"| runs with a deploy point | {st['with_deploy']} of {st['runs']} | | |",
    ])


def main(argv: list[str] | None = None) -> int:
    import pyarrow.dataset as ds
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m ellipsled.montecarlo.deploy CAMPAIGN_DIR", file=sys.stderr)
        return 2
    d = Path(args[0])
    t = ds.dataset(d / "results.parquet").to_table(
        columns=["deploy_miss_km", "downrange_err_km", "crossrange_err_km"]).to_pydict()
    t = {k: [math.nan if v is None else v for v in col] for k, col in t.items()}
    st = deploy_stats(t)
    text = table(st)
    (d / "deploy.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
