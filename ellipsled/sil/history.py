"""Run history: preallocated per-control-step arrays shared by the batch runner and the SIL.

One row per control step k. The batch runner fills it in-process; in the SIL each process
fills its half (sim_history.npz, fsw_history.npz) and the launcher merges them on k.
Figures of merit (ellipsled/metrics.py) and plots read only this, so batch and SIL are
judged alike.
"""
from __future__ import annotations

import math

import numpy as np

from interfaces.records import FSW_STATE, FSW_STATE_LIVE, TRUTH, field_shapes

# Which side of the SIL records each field (the batch runner records both): the plant's
# (from its TRUTH record) and the flight software's (its output record FSW_STATE, every field
# but the live-only loop timing). Both sides carry the step index k: merge() aligns on it.
TRUTH_FIELDS = ("k", "t_s", "bank_rad", "alpha_rad", "beta_rad", "omega_BN_B", "sigma_BN", "h_m", "V_rel_mps",
                "gamma_rad", "psi_rad", "lat_rad", "lon_rad", "mach", "qbar_pa", "decel_g", "tau_jets_B")
FSW_FIELDS = tuple(n for n in field_shapes(FSW_STATE) if n not in FSW_STATE_LIVE and n not in TRUTH_FIELDS)
# name -> trailing shape of every column
FIELDS: dict[str, tuple[int, ...]] = {**{n: TRUTH[n].shape for n in TRUTH_FIELDS},
                                      **{n: FSW_STATE[n].shape for n in FSW_FIELDS}}

# Every process preallocates its run's history (nothing grows while flying; the pages are
# locked under --rt). A run whose history would not fit this budget is refused before it
# starts (sil.variant.prepare) instead of failing, or swapping, mid-flight.
HISTORY_BUDGET_BYTES = 2 * 1024**3


def row_bytes() -> int:
    """Bytes of one history row (both sides' records)."""
    return FSW_STATE.itemsize + TRUTH.itemsize


def rows_for(duration_s: float, dt_s: float) -> int:
    """Rows a run of ``duration_s`` at control step ``dt_s`` preallocates."""
    return int(math.ceil(duration_s / dt_s)) + 2


def budget_refusal(duration_s: float, dt_s: float, budget_bytes: int | None = None) -> str | None:
    """Why a run of ``duration_s`` at step ``dt_s`` is refused (its history beyond the
    memory budget, default HISTORY_BUDGET_BYTES), or None when it fits."""
    budget_bytes = HISTORY_BUDGET_BYTES if budget_bytes is None else budget_bytes
    need = rows_for(duration_s, dt_s) * row_bytes()
    if need <= budget_bytes:
        return None
    longest = (budget_bytes // row_bytes() - 2) * dt_s
    return (f"{duration_s:g} s at a {dt_s:g}-s control step needs {need / 1e9:.3g} GB of run history per "
            f"process, beyond the memory budget of {budget_bytes / 1024**3:g} GiB "
            f"(ellipsled.sil.history.HISTORY_BUDGET_BYTES): at most {longest:.0f} s")


class History:
    def __init__(self, n_max: int):
        self.n = 0
        self.n_max = n_max
        self.a: dict[str, np.ndarray] = {}
        self._rows(np.zeros(n_max, dtype=TRUTH), np.zeros(n_max, dtype=FSW_STATE))

    def _rows(self, truth_rows: np.ndarray, fsw_rows: np.ndarray) -> None:
        """Each half lives in one array of its record (TRUTH, FSW_STATE); a[name] are views
        of their fields."""
        self.truth_rows, self.fsw_rows = truth_rows, fsw_rows
        for k in FSW_FIELDS:
            self.a[k] = fsw_rows[k]
        for k in TRUTH_FIELDS:
            self.a[k] = truth_rows[k]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.a[name][: self.n]

    def row(self) -> int:
        """Index of a new row (grows by doubling if a run outlives its estimate)."""
        if self.n >= self.n_max:
            self._rows(np.concatenate((self.truth_rows, np.zeros_like(self.truth_rows))),
                       np.concatenate((self.fsw_rows, np.zeros_like(self.fsw_rows))))
            self.n_max *= 2
        i = self.n
        self.n += 1
        return i

    def save(self, path) -> None:
        np.savez_compressed(path, **{k: v[: self.n] for k, v in self.a.items()})

    @classmethod
    def load(cls, path) -> "History":
        z = np.load(path)
        n = len(z["t_s"])
        h = cls(max(n, 1))
        for k in FIELDS:
            if k in z:
                h.a[k][:n] = z[k]
        h.n = n
        return h


def record_truth(h: History, i: int, truth: dict) -> None:
    """The plant's half of row i (from sim.plant.Plant.truth() or a TRUTH record)."""
    if type(truth) is np.ndarray and truth.dtype == TRUTH:
        h.truth_rows[i] = truth
        return
    a = h.a
    for k in TRUTH_FIELDS:
        a[k][i] = truth[k]


def record_fsw(h: History, i: int, out: np.ndarray) -> None:
    """The flight software's half of row i: its output record (FlightSoftware.output, an
    FSW_STATE) after its control cycle for that step."""
    h.fsw_rows[i] = out
    h.a["k"][i] = out["k"]      # the same step index as the truth half: merge() aligns on it


def merge(truth: History, fsw: History) -> History:
    """One History from the SIL's two halves, aligned on the step index k."""
    kt, kf = truth["k"], fsw["k"]
    common = np.intersect1d(kt, kf)
    it = np.searchsorted(kt, common)
    jf = np.searchsorted(kf, common)
    h = History(max(len(common), 1))
    h.n = len(common)
    for name in TRUTH_FIELDS:
        h.a[name][: h.n] = truth.a[name][it]
    for name in FSW_FIELDS:
        h.a[name][: h.n] = fsw.a[name][jf]
    h.a["k"][: h.n] = common
    return h
