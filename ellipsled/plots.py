"""PNG plots of a run and of case comparisons (the figures the paper shows)."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .history import History  # noqa: E402
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
              extent=(t[0], t[-1] if len(t) else 1, 18.5, 0.5))
    ax.set_ylabel("jet"); ax.set_xlabel("t [s]"); ax.set_title(f"{title}: jet commands (black = on)")
    files.append(_save(fig, out / "jets.png"))
    return files


def plot_compare(runs: dict[str, History], out: Path, name: str, key: str = "bank_err") -> str:
    """Bank error (or another series) of several runs on one plot."""
    fig, ax = plt.subplots(figsize=(9, 4))
    for label, h in runs.items():
        y = bank_error_deg(h) if key == "bank_err" else h[key]
        ax.plot(h["t_s"], y, lw=0.8, label=label)
    ax.set_xlabel("t [s]"); ax.set_ylabel("bank error [deg]" if key == "bank_err" else key); ax.legend()
    return _save(fig, Path(out) / name)
