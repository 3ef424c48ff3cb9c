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
           ("bank_err_rms_deg", "RMS bank error over the entry [deg]"))
N_WORST = 10


def _col(rows: list[dict], name: str) -> np.ndarray:
    return np.array([np.nan if r.get(name) is None else float(r[name]) for r in rows], float)


def stats(table: pa.Table, runs: int | None = None) -> dict:
    """Success rate, failures by criterion, percentiles of the figures of merit."""
    rows = table.to_pylist()
    ids = [r["run_id"] for r in rows]
    ok = [r for r in rows if r.get("status") == "ok"]
    out = {"runs_recorded": len(rows), "runs_planned": runs, "duplicates": len(ids) - len(set(ids)),
           "raised": len(rows) - len(ok), "success": sum(1 for r in rows if r.get("success")),
           "criteria_failed": {}, "figures": {}}
    out["success_rate"] = out["success"] / len(rows) if rows else None
    # batch cycle slips are wall-clock overruns: on a shared host they measure the host
    out["success_but_cycle_slips"] = sum(1 for r in ok if r.get("failed_criteria") == "max_cycle_slips")
    for r in ok:
        for c in (r.get("failed_criteria") or "").split(","):
            if c:
                out["criteria_failed"][c] = out["criteria_failed"].get(c, 0) + 1
    for name, _ in FIGURES:
        x = _col(ok, name)
        fin = x[np.isfinite(x)]
        out["figures"][name] = {"n": int(fin.size), "none": int(x.size - fin.size),
                                **{f"p{q}": (float(np.percentile(fin, q)) if fin.size else None) for q in PERCENTILES},
                                "max": float(fin.max()) if fin.size else None}
    return out


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
                             ("scatter_err_vs_failed_jets.png", n_jets + jitter, "faulty jets (off + stuck + degraded)")):
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
    lines = [f"# Monte Carlo campaign `{camp.name}`", "", camp.description, "",
             f"- runs recorded: {st['runs_recorded']}" + (f" of {runs}" if runs else "")
             + f"; raised: {st['raised']}; duplicates: {st['duplicates']}",
             f"- success: {st['success']} ({_fmt(None if st['success_rate'] is None else 100 * st['success_rate'], '{:.1f}')} %)"
             f" — criteria: completed, finite, max |e_phi| after fault <= {camp.success.bank_err_max_after_fault_deg} deg,"
             f" cycle slips <= {camp.success.max_cycle_slips}",
             f"- runs meeting every criterion but the cycle slips (wall-clock overruns, host load): "
             f"{st['success_but_cycle_slips']}",
             "- runs breaking each criterion: " + (", ".join(f"{k} {v}" for k, v in sorted(st["criteria_failed"].items()))
                                                   or "none"),
             "", "## Figures of merit (runs that flew)", "",
             "| figure | n | none | " + " | ".join(f"p{q}" for q in PERCENTILES) + " | max |",
             "|---|---|---|" + "---|" * (len(PERCENTILES) + 1)]
    for name, label in FIGURES:
        f = st["figures"][name]
        lines.append(f"| {label} | {f['n']} | {f['none']} | " + " | ".join(_fmt(f[f'p{q}']) for q in PERCENTILES)
                     + f" | {_fmt(f['max'])} |")
    lines += ["", "(none: the figure is undefined for the run, e.g. never settled, or no fault within the run)",
              "", f"## Worst {N_WORST} runs by max |bank error| after the fault", "",
              "| run | seed | max err [deg] | fault t [s] | off | stuck | degraded | FDIR delay [s] | success |",
              "|---|---|---|---|---|---|---|---|---|"]
    err = _col(ok, "bank_err_max_after_fault_deg")
    order = [i for i in np.argsort(-np.nan_to_num(err, nan=-1.0)) if np.isfinite(err[i])][:N_WORST]
    for i in order:
        r = ok[i]
        lines.append(f"| {r['run_id']} | {r['seed']} | {err[i]:.3f} | {_fmt(r.get('disp.fault_t_s'), '{:.1f}')} | "
                     f"{r.get('disp.jets_failed_off')} | {r.get('disp.jets_stuck_on')} | {r.get('disp.jets_degraded')} | "
                     f"{_fmt(r.get('disp.fdir_delay_s'), '{:.2f}')} | {r.get('success')} |")
    failed = [r for r in rows if r.get("status") != "ok"]
    if failed:
        lines += ["", "## Runs that raised", "", "| run | seed | error |", "|---|---|---|"]
        for r in failed[:50]:
            e = (r.get("error") or "").splitlines()[0][:200].replace("|", "\\|")
            lines.append(f"| {r['run_id']} | {r['seed']} | {e} |")
    lines += ["", f"Reproduce any run: `ellipsled batch --from-campaign {out} --run ID --out DIR`.", ""]
    if plots and ok:
        files = _plots(out, ok)
        lines += ["## Plots", ""] + [f"![{f}]({f})" for f in files] + [""]
    path = out / "summary.md"
    path.write_text("\n".join(lines))
    return path
