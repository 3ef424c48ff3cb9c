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


ALT_FLOOR_KM = 6.0                         # the guided campaign's deploy-altitude criterion
ALT_PCT = (1, 5, 50)                      # deploy altitude percentiles (the low tail is what matters)
MACH_PCT = (5, 50, 95)


def _col(rows: dict, name: str, n: int, fill=math.nan) -> np.ndarray:
    v = rows.get(name)
    if v is None:
        return np.full(n, fill, dtype=float)
    return np.array([fill if x is None else x for x in v], dtype=float)


def deploy_stats(rows: dict) -> dict:
    """From columns deploy_miss_km, downrange_err_km, crossrange_err_km and, when present,
    end_reason, run_id, deploy_alt_km, deploy.mach, deploy.ok and skip. Only a run that reached
    a deploy (end reason mach, speed, deploy or box_edge) has a deploy point: the figures of a
    run that skipped out, ran out of time or reached the end altitude first are where it
    stopped, not a deploy (a skip-out's is thousands of km away and would make the ellipse),
    so such runs are counted and listed, not used; the requirement's share is also given over
    all runs (a run that never deployed is outside it). Deploy altitude and Mach percentiles,
    the share at or above ALT_FLOOR_KM and the share the FSW deployed inside the box (deploy.ok)
    are over all runs given (a run with no deploy is neither high enough nor in the box)."""
    miss = np.asarray(rows["deploy_miss_km"], dtype=float)
    n = len(miss)
    ok = np.isfinite(miss)
    reasons = rows.get("end_reason")
    if reasons is not None:
        ok &= np.array([r in DEPLOY_REASONS for r in reasons], dtype=bool)
    down = np.asarray(rows["downrange_err_km"], dtype=float)[ok]
    cross = np.asarray(rows["crossrange_err_km"], dtype=float)[ok]
    m = miss[ok]
    ids = rows.get("run_id", range(n))
    out = {"runs": int(n), "with_deploy": int(ok.sum()),
           "no_deploy": [{"run": int(i), "end_reason": (reasons[k] if reasons is not None else "no figure")}
                         for k, i in enumerate(ids) if not ok[k]]}
    if "skip" in rows:
        out["skip_outs"] = int(sum(bool(x) for x in rows["skip"]))
    if ok.sum() >= 3:
        out.update({f"miss_p{q}_km": float(np.percentile(m, q)) for q in (50, 90, 99)})
        out["miss_max_km"] = float(m.max())
        out["within_msl_requirement"] = float(np.mean(m <= MSL_REQUIREMENT_KM))
        out["within_msl_requirement_all"] = float(np.sum(m <= MSL_REQUIREMENT_KM) / len(miss))
        out["ellipse99_major_km"], out["ellipse99_minor_km"], out["ellipse99_angle_deg"] = ellipse_99(down, cross)
        out["downrange_mean_km"], out["crossrange_mean_km"] = float(down.mean()), float(cross.mean())
        alt = _col(rows, "deploy_alt_km", n)
        if np.isfinite(alt[ok]).all():
            a = alt[ok]
            out.update({f"alt_p{q}_km": float(np.percentile(a, q)) for q in ALT_PCT})
            out["alt_min_km"] = float(a.min())
            out["alt_at_floor_all"] = float(np.sum(a >= ALT_FLOOR_KM) / n)
        mach = _col(rows, "deploy.mach", n)
        if np.isfinite(mach[ok]).all():
            out.update({f"mach_p{q}": float(np.percentile(mach[ok], q)) for q in MACH_PCT})
        if "deploy.ok" in rows:
            out["in_box_all"] = float(sum(bool(x) for x in rows["deploy.ok"]) / n)
    return out


def _cell(st: dict, key: str, fmt: str = "{:.2f}", scale: float = 1.0) -> str:
    v = st.get(key)
    return "n/a" if v is None else fmt.format(scale * v)


def table(st: dict | list[dict], labels: list[str] | None = None) -> str:
    """The deploy table, one column per campaign (``labels``: their headings, e.g. the
    trigger mode), beside MSL's requirement and flown miss and Mars 2020's ellipse."""
    sts = st if isinstance(st, list) else [st]
    labels = labels or ["this campaign"] * len(sts)
    if not any("miss_p50_km" in s for s in sts):
        return "; ".join(f"{s['with_deploy']} of {s['runs']} runs reached a deploy" for s in sts) \
            + ": too few for statistics"

    def row(name: str, cells: list[str], msl: str = "", m2020: str = "") -> str:
        return f"| {name} | " + " | ".join(cells) + f" | {msl} | {m2020} |"
    pct = lambda k: [_cell(s, k, "{:.1f} %", 100.0) for s in sts]   # noqa: E731
    lines = ["| | " + " | ".join(labels) + " | MSL (2012) | Mars 2020 |", "|---|" + "---|" * (len(sts) + 2),
             row("deploy miss p50 / p90 / p99 [km]",
                 [" / ".join(_cell(s, f"miss_p{q}_km") for q in (50, 90, 99)) for s in sts],
                 f"flown {MSL_FLOWN_KM}", ""),
             row("deploys within 12.5 km (of all runs)",
                 [f"{_cell(s, 'within_msl_requirement', '{:.1f}', 100.0)} % "
                  f"({_cell(s, 'within_msl_requirement_all', '{:.1f}', 100.0)} %)" for s in sts],
                 f"requirement: within {MSL_REQUIREMENT_KM} km", ""),
             row("99 % ellipse (full axes) [km]",
                 [f"{_cell(s, 'ellipse99_major_km')} x {_cell(s, 'ellipse99_minor_km')}" for s in sts],
                 "", f"{M2020_ELLIPSE_KM[0]} x {M2020_ELLIPSE_KM[1]} (landing)"),
             row("deploy altitude p" + " / p".join(map(str, ALT_PCT)) + ", min [km]",
                 [" / ".join(_cell(s, f"alt_p{q}_km") for q in ALT_PCT) + f", {_cell(s, 'alt_min_km')}"
                  for s in sts]),
             row(f"runs deploying at >= {ALT_FLOOR_KM:g} km", pct("alt_at_floor_all")),
             row("deploy Mach p" + " / p".join(map(str, MACH_PCT)),
                 [" / ".join(_cell(s, f"mach_p{q}") for q in MACH_PCT) for s in sts], "velocity trigger",
                 "range trigger"),
             row("runs deployed by the FSW inside the box", pct("in_box_all")),
             row("skip-outs", [str(s.get("skip_outs", "n/a")) for s in sts]),
             row("runs with a deploy point",
                 [f"{s['with_deploy']} of {s['runs']}" + (" (not deployed: " + ", ".join(
                     f"run {r['run']} {r['end_reason']}" for r in s["no_deploy"]) + ")" if s["no_deploy"] else "")
                  for s in sts])]
    return "\n".join(lines)


COLUMNS = ["run_id", "end_reason", "deploy_miss_km", "downrange_err_km", "crossrange_err_km", "deploy_alt_km",
           "deploy.mach", "deploy.ok", "skip", "controllability.controllable"]


def campaign_rows(d: Path, controllable_only: bool = False) -> dict:
    """The deploy columns of a campaign folder's results (those it has), as plain lists."""
    import pyarrow.dataset as ds
    data = ds.dataset(d / "results.parquet")
    t = data.to_table(columns=[c for c in COLUMNS if c in data.schema.names]).to_pydict()
    if controllable_only and "controllability.controllable" in t:
        keep = [bool(x) for x in t["controllability.controllable"]]
        t = {k: [x for x, c in zip(col, keep) if c] for k, col in t.items()}
    return {k: ([math.nan if v is None else v for v in col] if k.endswith("_km") else col) for k, col in t.items()}


def trigger_of(d: Path) -> str:
    """The deploy trigger a campaign folder's runs flew (its recorded FSW overrides), or ''."""
    import json
    try:
        meta = json.loads((d / "campaign.json").read_text())
    except (OSError, ValueError):
        return ""
    return ((meta.get("campaign", {}).get("fsw") or {}).get("deploy") or {}).get("trigger", "")


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    ctl = "--controllable" in args
    dirs = [Path(a) for a in args if a != "--controllable"]
    if not dirs:
        print("usage: python -m ellipsled.montecarlo.deploy [--controllable] CAMPAIGN_DIR [CAMPAIGN_DIR ...]\n"
              "  one column per campaign (e.g. one per deploy trigger); --controllable: controllable runs only",
              file=sys.stderr)
        return 2
    sts = [deploy_stats(campaign_rows(d, ctl)) for d in dirs]
    labels = [f"{d.name} ({trigger_of(d) or 'default trigger'})" for d in dirs]
    text = table(sts, labels) + ("\n\n(controllable runs only)" if ctl else "")
    if len(dirs) == 1:
        (dirs[0] / "deploy.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
