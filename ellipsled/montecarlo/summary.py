"""The campaign's report: DIR/summary.md and PNG plots, from the result store alone."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa

from .campaign import Campaign

PERCENTILES = (5, 50, 95, 99)
FIGURES = (("bank_err_max_after_fault_deg", "max |bank error| after the fault [deg]"),
           ("propellant_kg", "propellant used [kg]"),
           ("settle_time_after_reconfig_s", "settle time within 1 deg after reconfiguration [s]"),
           ("bank_err_rms_deg", "RMS bank error over the entry [deg]"),
           ("bank_err_sched_max_after_fault_deg", "max |bank - scenario's schedule| after the fault [deg]"),
           ("bank_err_fault_attrib_max_deg", "fault-attributable bank error (vs the same run without faults) [deg]"),
           ("control_cycle.compute_overruns", "control cycles over the period (host figure) [-]"))
N_WORST = 10
FAULT_ATTRIB = "bank_err_fault_attrib_max_deg"
ATTRIB_GOAL_DEG = 1.0      # the product's goal: fault-attributable error <= 1 deg in >= 95 % of controllable runs


def _col(rows: list[dict], name: str) -> np.ndarray:
    return np.array([np.nan if r.get(name) is None else float(r[name]) for r in rows], float)


def controllable(r: dict) -> bool | None:
    """The run's label (None when the run raised before it was judged)."""
    v = r.get("controllability.controllable")
    return None if v is None else bool(v)


def _figures(rows: list[dict]) -> dict:
    out = {}
    for name, _ in FIGURES:
        x = _col(rows, name)
        fin = x[np.isfinite(x)]
        out[name] = {"n": int(fin.size), "none": int(x.size - fin.size),
                     **{f"p{q}": (float(np.percentile(fin, q)) if fin.size else None) for q in PERCENTILES},
                     "max": float(fin.max()) if fin.size else None}
    return out


def stats(table: pa.Table, runs: int | None = None) -> dict:
    """Success over all runs and over controllable runs, failures by criterion, the runs no
    controller could fly (with their reason), percentiles of the figures of merit."""
    rows = table.to_pylist()
    ids = [r["run_id"] for r in rows]
    ok = [r for r in rows if r.get("status") == "ok"]
    ctl = [r for r in ok if controllable(r) is not False]
    out = {"runs_recorded": len(rows), "runs_planned": runs, "duplicates": len(ids) - len(set(ids)),
           "raised": len(rows) - len(ok), "success": sum(1 for r in rows if r.get("success")),
           "runs_controllable": len(ctl), "success_controllable": sum(1 for r in ctl if r.get("success")),
           "criteria_failed": {}, "criteria_failed_controllable": {}, "figures": {}}
    out["success_rate_all"] = out["success"] / len(rows) if rows else None
    out["success_rate"] = out["success_rate_all"]
    out["success_rate_controllable"] = out["success_controllable"] / len(ctl) if ctl else None
    out["uncontrollable"] = [{"run_id": r["run_id"], "reason": r.get("controllability.reason")}
                             for r in ok if controllable(r) is False]
    for group, key in ((ok, "criteria_failed"), (ctl, "criteria_failed_controllable")):
        for r in group:
            for c in (r.get("failed_criteria") or "").split(","):
                if c:
                    out[key][c] = out[key].get(c, 0) + 1
    out["figures"] = _figures(ok)
    out["figures_controllable"] = _figures(ctl)
    fa = _col(ctl, FAULT_ATTRIB)
    fa = fa[np.isfinite(fa)]
    out["fault_attrib_within_goal_controllable"] = (
        {"goal_deg": ATTRIB_GOAL_DEG, "n": int(fa.size), "fraction": float(np.mean(fa <= ATTRIB_GOAL_DEG))}
        if fa.size else None)
    return out


def diagnose(r: dict) -> str:
    """One line: the most telling reason this run's error is what it is, from its record."""
    if r.get("status") != "ok":
        return "raised: " + (r.get("error") or "").splitlines()[0][:120] if r.get("error") else "raised"
    if controllable(r) is False:
        return f"not controllable: {r.get('controllability.reason')}"
    parts = []
    if not r.get("completed"):
        parts.append(f"did not complete ({r.get('end_reason')} at {_fmt(r.get('t_end_s'), '{:.0f}')} s)")
    if r.get("nonfinite"):
        parts.append("non-finite values")
    fa, missed = r.get("fdir.false_alarms") or 0, json.loads(r.get("fdir.missed") or "[]")
    if fa or missed:
        parts.append(f"FDIR: {fa} false alarms, missed jets {missed}")
    t_end, degr = r.get("t_end_s") or 0.0, r.get("allocator.degraded") or 0
    if t_end > 0 and degr > 0.05 * t_end * 50:
        parts.append(f"allocation infeasible in {degr} cycles (stuck-on bias)")
    e, es = r.get("bank_err_max_after_fault_deg"), r.get("bank_err_sched_max_after_fault_deg")
    if e is not None and es is not None and es > e + 5.0:
        parts.append(f"re-planned reference lags the schedule (up to {es:.0f} deg off it)")
    ap, an, need = (r.get("controllability.authority_pos_degps2"), r.get("controllability.authority_neg_degps2"),
                    r.get("controllability.need_degps2"))
    if ap is not None and an is not None and need is not None and min(ap, an) < 3.0 * need:
        parts.append(f"little bank authority left (+{ap:.2f}/-{an:.2f} deg/s2 for {need:.2f} needed)")
    if not parts:
        rev = json.loads(r.get("reversals") or "[]")
        if rev:
            w = max(rev, key=lambda x: x["bank_err_max_deg"])
            parts.append(f"largest error after the bank step at {w['t_s']:.0f} s ({w['bank_err_max_deg']:.2f} deg)")
        else:
            parts.append("tracking error without a flagged cause")
    return "; ".join(parts)


def _fmt(x, f="{:.3g}") -> str:
    return "—" if x is None else f.format(x)


def _plots(out: Path, ok: list[dict]) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    files = []
    for name, label in FIGURES[:3]:
        x = _col(ok, name)
        x = x[np.isfinite(x)]
        fig, ax = plt.subplots(figsize=(6, 3.5))
        if x.size:
            ax.hist(x, bins=min(40, max(5, int(np.sqrt(x.size)) * 2)), color="tab:blue", edgecolor="white")
        ax.set_xlabel(label)
        ax.set_ylabel("runs")
        ax.set_title(f"{x.size} runs")
        fig.tight_layout()
        f = f"hist_{name}.png"
        fig.savefig(out / f, dpi=100)
        plt.close(fig)
        files.append(f)
    err = _col(ok, "bank_err_max_after_fault_deg")
    t_f = _col(ok, "disp.fault_t_s")
    n_jets = _col(ok, "disp.n_failed_off") + _col(ok, "disp.n_stuck_on") + _col(ok, "disp.n_degraded")
    stuck = _col(ok, "disp.n_stuck_on")
    jitter = np.random.default_rng(0).uniform(-0.15, 0.15, n_jets.size)
    for fname, x, xlabel in (("scatter_err_vs_fault_time.png", t_f, "fault time [s]"),
                             ("scatter_err_vs_failed_jets.png", n_jets + jitter,
                              "faulty jets (failed_off + stuck_on + degraded)")):
        fig, ax = plt.subplots(figsize=(6, 3.5))
        sc = ax.scatter(x, err, c=stuck, s=12, cmap="viridis", vmin=0, vmax=max(1.0, np.nanmax(stuck) if stuck.size else 1))
        fig.colorbar(sc, ax=ax, label="jets stuck on")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("max |bank error| after fault [deg]")
        fig.tight_layout()
        fig.savefig(out / fname, dpi=100)
        plt.close(fig)
        files.append(fname)
    return files


def write_summary(out: str | Path, camp: Campaign, table: pa.Table, runs: int | None = None,
                  plots: bool = True) -> Path:
    out = Path(out)
    st = stats(table, runs)
    rows = table.to_pylist()
    ok = [r for r in rows if r.get("status") == "ok"]
    (out / "summary_stats.json").write_text(json.dumps(st, indent=2) + "\n")
    pct = lambda x: _fmt(None if x is None else 100 * x, "{:.1f}")   # noqa: E731
    goal = st["fault_attrib_within_goal_controllable"]
    lines = [f"# Monte Carlo campaign `{camp.name}`", "", camp.description, "",
             f"- runs recorded: {st['runs_recorded']}" + (f" of {runs}" if runs else "")
             + f"; raised: {st['raised']}; duplicates: {st['duplicates']}",
             f"- criteria: completed, finite, max |e_phi| after the fault <= "
             f"{camp.success.bank_err_max_after_fault_deg} deg"
             + (f", deploy within {camp.success.deploy_miss_km:g} km" if camp.success.deploy_miss_km else "")
             + (f", deploy at >= {camp.success.deploy_alt_min_km:g} km" if camp.success.deploy_alt_min_km else "")
             + (", deployed by the FSW inside the deploy box" if camp.success.deploy_in_box else "")
             + " (cycle slips are a host figure, not a criterion)",
             f"- success over all runs: {st['success']} / {st['runs_recorded']} ({pct(st['success_rate_all'])} %)",
             f"- success over controllable runs: {st['success_controllable']} / {st['runs_controllable']}"
             f" ({pct(st['success_rate_controllable'])} %)",
             "- runs breaking each criterion (controllable runs): "
             + (", ".join(f"{k} {v}" for k, v in sorted(st["criteria_failed_controllable"].items())) or "none"),
             "- fault-attributable bank error <= 1 deg (controllable runs): "
             + (f"{pct(goal['fraction'])} % of {goal['n']}" if goal else "not measured in these runs"),
             "", "## Runs no controller of these jets could fly", ""]
    if st["uncontrollable"]:
        lines += ["| run | reason |", "|---|---|"]
        lines += [f"| {u['run_id']} | {u['reason']} |" for u in st["uncontrollable"]]
    else:
        lines.append("none")
    for title, key in (("all runs that flew", "figures"), ("controllable runs", "figures_controllable")):
        lines += ["", f"## Figures of merit ({title})", "",
                  "| figure | n | none | " + " | ".join(f"p{q}" for q in PERCENTILES) + " | max |",
                  "|---|---|---|" + "---|" * (len(PERCENTILES) + 1)]
        for name, label in FIGURES:
            f = st[key][name]
            lines.append(f"| {label} | {f['n']} | {f['none']} | " + " | ".join(_fmt(f[f'p{q}']) for q in PERCENTILES)
                         + f" | {_fmt(f['max'])} |")
    lines += ["", "(none: the figure is undefined for the run, e.g. never settled, or no fault within the run)",
              "", f"## Worst {N_WORST} runs by max |bank error| after the fault", "",
              "| run | seed | max err [deg] | vs schedule [deg] | fault t [s] | failed_off | stuck_on | degraded "
              "| FDIR delay [s] | success | diagnosis |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    err = _col(ok, "bank_err_max_after_fault_deg")
    order = [i for i in np.argsort(-np.nan_to_num(err, nan=-1.0)) if np.isfinite(err[i])][:N_WORST]
    for i in order:
        r = ok[i]
        lines.append(f"| {r['run_id']} | {r['seed']} | {err[i]:.3f} | "
                     f"{_fmt(r.get('bank_err_sched_max_after_fault_deg'), '{:.1f}')} | "
                     f"{_fmt(r.get('disp.fault_t_s'), '{:.1f}')} | "
                     f"{r.get('disp.jets_failed_off')} | {r.get('disp.jets_stuck_on')} | {r.get('disp.jets_degraded')} | "
                     f"{_fmt(r.get('disp.fdir_delay_s'), '{:.2f}')} | {r.get('success')} | "
                     f"{diagnose(r).replace('|', '/')} |")
    failed = [r for r in rows if r.get("status") != "ok"]
    if failed:
        lines += ["", "## Runs that raised", "", "| run | seed | error |", "|---|---|---|"]
        for r in failed[:50]:
            e = (r.get("error") or "").splitlines()[0][:200].replace("|", "\\|")
            lines.append(f"| {r['run_id']} | {r['seed']} | {e} |")
    if any(r.get("deploy_miss_km") is not None for r in ok):
        from .deploy import campaign_rows, deploy_stats, table, trigger_of
        sts = [deploy_stats(campaign_rows(out, c)) for c in (False, True)]
        trig = trigger_of(out) or "the FSW's default"
        lines += ["", f"## Deploy (trigger: {trig})", "",
                  table(sts, ["all runs", "controllable runs"])]
    lines += ["", f"Reproduce any run: `ellipsled batch --from-campaign {out} --run ID --out DIR`.", ""]
    if plots and ok:
        files = _plots(out, ok)
        lines += ["## Plots", ""] + [f"![{f}]({f})" for f in files] + [""]
    path = out / "summary.md"
    path.write_text("\n".join(lines))
    return path
