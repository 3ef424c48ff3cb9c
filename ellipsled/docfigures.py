"""Figures of the documentation's dashboards page, drawn with matplotlib from one run's
``history.npz`` and ``summary.json`` (an ``ellipsled batch`` or ``ellipsled run`` output
folder): the quantities the Rerun dashboards show, as still images. They are plots of the
run, not screenshots of the viewer (docs/dashboards.md says why).

    python -m ellipsled.docsgen --figures RUN_DIR     # writes docs/img/dashboards/*.png

- ``attitude.png``: bank angle against its reference over the entry, and the bank error;
- ``jets.png``: the 18 jets' commands and their health as FDIR holds it;
- ``fdir.png``: the first seconds after the fault — bank error, jets on, FDIR's detections
  and the reconfiguration.
"""
from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from interfaces.vocabulary import HEALTH_NAMES, N_JETS  # noqa: E402

from .metrics import bank_error_deg  # noqa: E402
from .sil.history import History  # noqa: E402

FILES = ("attitude.png", "jets.png", "fdir.png")
NEED = ("t_s", "bank_rad", "bank_ref_rad", "jets_cmd", "health")
FDIR_WINDOW_S = 20.0      # fdir.png spans the fault and this long after it
DPI = 80
# No creation date or library version in the files: the same run gives the same images.
METADATA = {"Software": None}


class FigureInputError(ValueError):
    """The run folder lacks what the figures are drawn from."""


def _load(run_dir: Path) -> tuple[History, dict]:
    run_dir = Path(run_dir)
    hist, summ = run_dir / "history.npz", run_dir / "summary.json"
    missing = [p.name for p in (hist, summ) if not p.exists()]
    if missing:
        raise FigureInputError(f"{run_dir}: no {' or '.join(missing)} (an `ellipsled batch` output folder has both)")
    try:
        with np.load(hist) as z:
            absent = [k for k in NEED if k not in z.files]
        h = History.load(hist)
        s = json.loads(summ.read_text())
    except (OSError, ValueError, KeyError, EOFError) as e:
        raise FigureInputError(f"{run_dir}: unreadable run output: {e}") from e
    if absent:
        raise FigureInputError(f"{hist}: lacks {', '.join(absent)}")
    if not isinstance(s, dict):
        raise FigureInputError(f"{summ}: not a run summary")
    return h, s


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=DPI, metadata=METADATA)
    plt.close(fig)
    return path


def _events(ax, s: dict, label: bool) -> None:
    """FDIR detections (dotted) and the reconfiguration (dashed) as vertical lines."""
    for i, d in enumerate((s.get("fdir") or {}).get("detections") or []):
        ax.axvline(d["t_s"], color="tab:red", ls=":", lw=1.0,
                   label="FDIR detection" if label and i == 0 else None)
    if s.get("reconfig_t_s") is not None:
        ax.axvline(s["reconfig_t_s"], color="tab:green", ls="--", lw=1.0, label="reconfiguration" if label else None)
    if s.get("fault_t_s") is not None:
        ax.axvline(s["fault_t_s"], color="k", ls="-", lw=0.6, label="fault" if label else None)


def render(run_dir: Path, out_dir: Path) -> list[Path]:
    """Draw the figures of the run in ``run_dir`` into ``out_dir``; returns the files written."""
    h, s = _load(run_dir)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    name = s.get("scenario", Path(run_dir).name)
    t = np.asarray(h["t_s"])
    e = bank_error_deg(h)
    files = []

    fig, ax = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    ax[0].plot(t, np.degrees(h["bank_ref_rad"]), "--", lw=1.0, label="reference")
    ax[0].plot(t, np.degrees(h["bank_rad"]), lw=0.9, label="bank")
    ax[0].set_ylabel("bank [deg]")
    ax[0].legend(loc="upper right")
    ax[0].set_title(f"{name}: bank angle against its reference (Attitude tab)")
    ax[1].plot(t, e, lw=0.8)
    ax[1].axhspan(-5, 5, color="tab:green", alpha=0.08, label="±5° (the paper's band)")
    ax[1].set_ylabel("bank error [deg]")
    ax[1].set_xlabel("t [s]")
    ax[1].legend(loc="upper right")
    files.append(_save(fig, out_dir / "attitude.png"))

    jets = np.asarray(h["jets_cmd"], dtype=float)
    health = np.asarray(h["health"], dtype=float)
    step = max(1, len(t) // 600)          # about one bin per pixel column
    extent = (float(t[0]), float(t[-1]), N_JETS + 0.5, 0.5)
    fig, ax = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    bins = np.arange(0, len(t), step)
    fired = np.maximum.reduceat(jets, bins, axis=0) if len(t) else jets   # a firing anywhere in a bin shows
    ax[0].imshow(fired.T, aspect="auto", interpolation="nearest", cmap="Greys", extent=extent)
    ax[0].set_ylabel("jet")
    ax[0].set_title(f"{name}: jets fired (black: on at least once in the pixel's time bin) and their health "
                    "as FDIR holds it (Jets tab)", fontsize=10)
    codes = sorted(HEALTH_NAMES)
    cmap = matplotlib.colors.ListedColormap(plt.get_cmap("tab10").colors[2:2 + len(codes)])
    im = ax[1].imshow(health[::step].T, aspect="auto", interpolation="nearest", cmap=cmap,
                      vmin=codes[0] - 0.5, vmax=codes[-1] + 0.5, extent=extent)
    ax[1].set_ylabel("jet")
    ax[1].set_xlabel("t [s]")
    bar = fig.colorbar(im, ax=ax[1], fraction=0.03, ticks=codes)
    bar.ax.set_yticklabels([HEALTH_NAMES[c].replace("_", " ") for c in codes], fontsize=7)
    files.append(_save(fig, out_dir / "jets.png"))

    t0 = s.get("fault_t_s") or 0.0
    w = (t >= max(0.0, t0 - 2.0)) & (t <= t0 + FDIR_WINDOW_S)
    fig, ax = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True)
    ax[0].plot(t[w], e[w], lw=0.9)
    ax[0].set_ylabel("bank error [deg]")
    _events(ax[0], s, label=True)
    ax[0].legend(loc="upper right")
    dets = ", ".join(f"jet {d['jet']} {d['kind'].replace('_', ' ')} at {d['t_s']:.2f} s"
                     for d in (s.get("fdir") or {}).get("detections") or [])
    ax[0].set_title(f"{name}: the fault and FDIR (Events tab)" + (f"\n{dets}" if dets else ""), fontsize=9)
    ax[1].step(t[w], jets[w].sum(axis=1), where="post", lw=0.8)
    _events(ax[1], s, label=False)
    ax[1].set_ylabel("jets on")
    ax[1].set_xlabel("t [s]")
    files.append(_save(fig, out_dir / "fdir.png"))
    return files
