"""PNG plots of a run and of case comparisons (the figures the paper shows)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from interfaces.vocabulary import N_JETS  # noqa: E402

from .sil.history import History  # noqa: E402
from .metrics import THETA_NAMES, bank_error_deg  # noqa: E402

AXES = ("roll", "pitch", "yaw")


def _save(fig, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path.name


def plot_run(h: History, out: Path, title: str) -> list[str]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t = h["t_s"]
    files = []

    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax[0].plot(t, np.degrees(h["bank_rad"]), label="bank")
    ax[0].plot(t, np.degrees(h["bank_ref_rad"]), "--", label="reference")
    ax[0].set_ylabel("bank [deg]"); ax[0].legend(); ax[0].set_title(f"{title}: bank angle")
    ax[1].plot(t, bank_error_deg(h)); ax[1].set_ylabel("bank error [deg]"); ax[1].set_xlabel("t [s]")
    ax[1].axhline(5, color="r", lw=0.5); ax[1].axhline(-5, color="r", lw=0.5)
    files.append(_save(fig, out / "bank.png"))

    fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for i in range(3):
        ax[i].plot(t, h["u_cal_B"][:, i], lw=0.8, label="commanded u_cal")
        ax[i].plot(t, h["tau_jets_B"][:, i], lw=0.6, alpha=0.7, label="applied (jets)")
        ax[i].set_ylabel(f"{AXES[i]} [N m]")
    ax[0].legend(); ax[0].set_title(f"{title}: commanded vs applied torque"); ax[2].set_xlabel("t [s]")
    files.append(_save(fig, out / "torque.png"))

    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax[0].plot(t, np.degrees(h["alpha_rad"]), label="alpha"); ax[0].plot(t, np.degrees(h["beta_rad"]), label="beta")
    ax[0].set_ylabel("[deg]"); ax[0].legend(); ax[0].set_title(f"{title}: aerodynamic angles and body rates")
    for i in range(3):
        ax[1].plot(t, np.degrees(h["omega_BN_B"][:, i]), label=f"omega {'pqr'[i]}")
    ax[1].set_ylabel("[deg/s]"); ax[1].legend(); ax[1].set_xlabel("t [s]")
    files.append(_save(fig, out / "angles_rates.png"))

    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    th = h["theta_hat"]
    for i in range(6):
        ax[0].plot(t, th[:, i], label=THETA_NAMES[i])
    ax[0].set_ylabel("inertia estimate [kg m^2]"); ax[0].legend(ncol=3, fontsize=7)
    ax[0].set_title(f"{title}: adaptive parameters")
    for i in range(6, 9):
        ax[1].plot(t, th[:, i], label=THETA_NAMES[i])
    ax[1].set_ylabel("aero factor d [-]"); ax[1].legend(); ax[1].set_xlabel("t [s]")
    files.append(_save(fig, out / "adaptive.png"))

    fig, ax = plt.subplots(3, 2, figsize=(10, 7), sharex=True)
    series = [("h_m", 1e-3, "altitude [km]"), ("V_rel_mps", 1e-3, "speed [km/s]"),
              ("gamma_rad", 180 / np.pi, "flight-path angle [deg]"), ("mach", 1, "Mach"),
              ("qbar_pa", 1e-3, "dynamic pressure [kPa]"), ("psi_rad", 180 / np.pi, "heading [deg]")]
    for a, (k, f, lab) in zip(ax.flat, series):
        a.plot(t, h[k] * f); a.set_ylabel(lab)
    ax[0, 0].set_title(f"{title}: translational states")
    files.append(_save(fig, out / "trajectory.png"))

    fig, ax = plt.subplots(figsize=(9, 4))
    jets = h["jets_cmd"]
    step = max(1, len(t) // 4000)
    ax.imshow(jets[::step].T, aspect="auto", interpolation="nearest", cmap="Greys",
              extent=(t[0], t[-1] if len(t) else 1, N_JETS + 0.5, 0.5))
    ax.set_ylabel("jet"); ax.set_xlabel("t [s]"); ax.set_title(f"{title}: jet commands (black = on)")
    files.append(_save(fig, out / "jets.png"))
    return files


def _err(h) -> np.ndarray:
    return bank_error_deg(h)


def _downrange_km(h, radius_m: float) -> np.ndarray:
    """Great-circle distance from the entry point [km] (haversine)."""
    la, lo = h["lat_rad"], h["lon_rad"]
    a = np.sin((la - la[0]) / 2) ** 2 + np.cos(la[0]) * np.cos(la) * np.sin((lo - lo[0]) / 2) ** 2
    return 2 * radius_m * np.arcsin(np.sqrt(np.clip(a, 0.0, 1.0))) / 1e3


def _series(ax, runs: dict, key: str, f, styles: dict) -> None:
    for label, h in runs.items():
        ax.plot(h["t_s"], f(h), lw=0.8, label=label, **styles.get(label, {}))


def paper_figures(H: dict, out: Path, trans: dict, radius_m: float = 3.3895e6) -> list[tuple[str, str]]:
    """One PNG per paper figure 4-14, the same quantities on the same axes. ``H[(case, set-up,
    mode)]`` are the report's runs; the paper's set-up with oracle identification (the paper's
    assumption) is drawn solid, the product's detect mode dashed where it differs."""
    out = Path(out)
    P, D = ("paper", "oracle"), ("paper", "detect")
    g = lambda c, v=P: H[(c,) + v]          # noqa: E731
    figs: list[tuple[str, str]] = []

    def save(fig, name, title):
        figs.append((title, _save(fig, out / name)))

    def error_fig(num, case, title, zoom=None, extra=()):
        fig, ax = plt.subplots(2, 1, figsize=(9, 6))
        runs = {"nominal": g("nominal"), f"{case} (oracle)": g(case), f"{case} (detect)": g(case, D)}
        for c in extra:
            runs[f"{c} (oracle)"] = g(c)
        sty = {f"{case} (detect)": {"ls": "--"}}
        for a, lim in zip(ax, (None, zoom or (0, 30))):
            _series(a, runs, "e", _err, sty)
            a.set_ylabel("bank error [deg]")
            if lim:
                a.set_xlim(*lim)
        ax[0].set_title(f"Figure {num}: {title}")
        ax[0].legend(fontsize=7)
        ax[1].axvline(2.5, color="r", lw=0.5)
        ax[1].set_xlabel("t [s] (lower: first 30 s; red line: faults at 2.5 s)")
        save(fig, f"fig{num:02d}.png", f"Figure {num}: {title}")

    # 4: bank angle, case 1 vs nominal
    fig, ax = plt.subplots(figsize=(9, 4))
    for c, kw in (("nominal", {}), ("case1", {"ls": "--"})):
        h = g(c)
        ax.plot(h["t_s"], np.degrees(h["bank_rad"]), lw=0.8, label=f"{c} bank", **kw)
    ax.plot(g("nominal")["t_s"], np.degrees(g("nominal")["bank_ref_rad"]), "k:", lw=0.8, label="reference")
    ax.set_xlabel("t [s]"); ax.set_ylabel("bank angle [deg]"); ax.legend(fontsize=7)
    ax.set_title("Figure 4: bank angle, case 1 vs nominal")
    save(fig, "fig04.png", "Figure 4: bank angle, case 1 vs nominal")
    # 5: bank error, case 1, nominal and fault tolerance off
    error_fig(5, "case1", "bank-angle error, case 1, nominal and fault tolerance off", extra=("case1-ft-off",))
    # 6: translational states
    fig, ax = plt.subplots(2, 2, figsize=(10, 7))
    for c, kw in (("nominal", {}), ("case1", {"ls": "--"})):
        h = g(c)
        ax[0, 0].plot(h["t_s"], np.degrees(h["gamma_rad"]), lw=0.8, label=c, **kw)
        ax[0, 1].plot(h["t_s"], h["V_rel_mps"] / 1e3, lw=0.8, label=c, **kw)
        ax[1, 0].plot(_downrange_km(h, radius_m), h["h_m"] / 1e3, lw=0.8, label=c, **kw)
        ax[1, 1].plot(h["t_s"], np.degrees(h["beta_rad"]), lw=0.8, label=c, **kw)
    ax[0, 0].axhline(0, color="k", lw=0.4)
    ax[0, 0].axvline(250, color="r", lw=0.5, ls=":")
    ax[0, 0].set_ylabel("flight-path angle γ [deg]")
    ax[0, 0].set_title(f"Figure 6: translational states (paper: γ turns positive near 250 s, red; here "
                       f"{trans['gamma_pos_t_s']:.0f} s)" if trans.get("gamma_pos_t_s") else "Figure 6",
                       fontsize=8)
    ax[0, 1].set_ylabel("speed [km/s]")
    ax[1, 0].set_xlabel("downrange [km]"); ax[1, 0].set_ylabel("altitude [km]")
    ax[1, 1].set_ylabel("sideslip β [deg]")
    for a in (ax[0, 0], ax[0, 1], ax[1, 1]):
        a.set_xlabel("t [s]")
    ax[0, 0].legend(fontsize=7)
    save(fig, "fig06.png", "Figure 6: translational states, case 1 vs nominal")
    # 7, 8: commanded and applied control
    for num, key, what in ((7, "u_cal_B", "commanded control u_cal"), (8, "tau_jets_B", "applied control (jet torque)")):
        fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
        for i in range(3):
            for c, kw in (("nominal", {}), ("case1", {"alpha": 0.6})):
                ax[i].plot(g(c)["t_s"], g(c)[key][:, i], lw=0.6, label=c, **kw)
            ax[i].set_ylabel(f"{AXES[i]} [N m]")
        ax[0].legend(fontsize=7); ax[0].set_title(f"Figure {num}: {what}, case 1 vs nominal"); ax[2].set_xlabel("t [s]")
        save(fig, f"fig{num:02d}.png", f"Figure {num}: {what}, case 1 vs nominal")

    def effort_fig(num, case):
        fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
        for c, kw in (("nominal", {}), (case, {"alpha": 0.7})):
            h = g(c)
            ax[0].plot(h["t_s"], np.sum(h["tau_jets_B"] ** 2, axis=1), lw=0.6, label=c, **kw)
            ax[1].plot(h["t_s"], np.sum(h["u_cal_B"] ** 2, axis=1), lw=0.6, label=c, **kw)
        ax[0].set_ylabel("applied τᵀτ [N² m²]"); ax[1].set_ylabel("commanded uᵀu [N² m²]")
        ax[0].set_yscale("symlog", linthresh=1e2); ax[1].set_yscale("symlog", linthresh=1e2)
        ax[0].legend(fontsize=7); ax[0].set_title(f"Figure {num}: control effort, {case} vs nominal")
        ax[1].set_xlabel("t [s]")
        save(fig, f"fig{num:02d}.png", f"Figure {num}: control effort, {case} vs nominal")

    effort_fig(9, "case1")
    error_fig(10, "case2", "bank-angle error, case 2")
    # 11: bank angle case 2 with its re-shaped reference beside nominal's
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for c, kw in (("nominal", {}), ("case2", {"ls": "--"})):
        h = g(c)
        ax[0].plot(h["t_s"], np.degrees(h["bank_rad"]), lw=0.8, label=f"{c} bank", **kw)
        ax[1].plot(h["t_s"], np.degrees(h["bank_ref_rad"]), lw=0.8, label=f"{c} reference", **kw)
    ax[0].set_ylabel("bank angle [deg]"); ax[1].set_ylabel("bank reference [deg]"); ax[1].set_xlabel("t [s]")
    ax[0].legend(fontsize=7); ax[1].legend(fontsize=7)
    ax[0].set_title("Figure 11: bank angle, case 2 vs nominal (case 2's reference re-shaped after reconfiguration)")
    save(fig, "fig11.png", "Figure 11: bank angle and reference, case 2 vs nominal")
    effort_fig(12, "case2")
    error_fig(13, "case3", "bank-angle error, case 3")
    error_fig(14, "case4", "bank-angle error, case 4 (correction at 4.0 s), with case 1", zoom=(0, 12),
              extra=("case1",))
    # not in the paper: the same errors with no initial error, and the fault-attributable part
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    for c in ("case1", "case2", "case3", "case4", "case1-ft-off"):
        h = H[(c, "no-init-err", "oracle")]
        ax[0].plot(h["t_s"], _err(h), lw=0.7, label=c)
        h = g(c)
        ax[1].plot(h["t_s"], _err(h) - np.interp(h["t_s"], g("nominal")["t_s"], _err(g("nominal"))), lw=0.7, label=c)
    ax[0].set_ylabel("bank error [deg]"); ax[0].set_title("No initial error (oracle): bank error", fontsize=9)
    ax[1].set_ylabel("e − e_nominal [deg]")
    ax[1].set_title("Paper set-up (oracle): error relative to nominal (case 4's own twin differs only in its delay)",
                    fontsize=9)
    ax[1].set_xlabel("t [s]"); ax[0].legend(fontsize=7)
    save(fig, "no_initial_error.png", "Not in the paper: no initial error, and the error the faults add")
    return figs
