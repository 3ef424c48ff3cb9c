"""Run history: preallocated per-control-step arrays shared by the batch runner and the SIL.

One row per control step k. The batch runner fills it in-process; in the SIL each process
fills its half (sim_history.npz, fsw_history.npz) and the launcher merges them on k.
Figures of merit (ellipsled/metrics.py) and plots read only this, so batch and SIL are
judged alike.
"""
from __future__ import annotations

import math

import numpy as np

from interfaces.records import GUID_NPC, GUID_PREDICTION, GUID_TARGET, TRUTH
from interfaces.vocabulary import N_JETS


# name -> trailing shape; all float64 except where noted in _DTYPES
FIELDS: dict[str, tuple[int, ...]] = {
    "k": (), "t_s": (),
    # truth (plant)
    "bank_rad": (), "alpha_rad": (), "beta_rad": (), "omega_BN_B": (3,), "sigma_BN": (3,),
    "h_m": (), "V_rel_mps": (), "gamma_rad": (), "psi_rad": (), "lat_rad": (), "lon_rad": (),
    "mach": (), "qbar_pa": (), "decel_g": (), "tau_jets_B": (3,),
    # flight software
    "bank_ref_rad": (), "bankdot_ref_radps": (), "sigma_RN": (3,), "u_cal_B": (3,), "tau_alloc_B": (3,),
    "theta_hat": (9,), "jets_cmd": (N_JETS,), "health": (N_JETS,), "mode": (),
    "alloc_degraded": (), "alloc_short": (), "compute_us": (), "alloc_us": (),
    # entry guidance (FSW_STATE's guidance fields: 0 where guid_flags says not available)
    "guid_cycles": (), "guid_flags": (), "target_lat_rad": (), "target_lon_rad": (), "pred_lat_rad": (),
    "pred_lon_rad": (), "bank_cmd_rad": (),
}
# Which side of the SIL records each field (the batch runner records both).
TRUTH_FIELDS = ("k", "t_s", "bank_rad", "alpha_rad", "beta_rad", "omega_BN_B", "sigma_BN", "h_m", "V_rel_mps",
                "gamma_rad", "psi_rad", "lat_rad", "lon_rad", "mach", "qbar_pa", "decel_g", "tau_jets_B")
FSW_FIELDS = tuple(k for k in FIELDS if k not in TRUTH_FIELDS)

_DTYPES = {"k": np.int64, "guid_cycles": np.int64, "guid_flags": np.uint8, "jets_cmd": np.uint8, "health": np.int8, "mode": np.int8, "alloc_degraded": np.uint8, "alloc_short": np.uint8}

# Every process preallocates its run's history (nothing grows while flying; the pages are
# locked under --rt). A run whose history would not fit this budget is refused before it
# starts (sil.variant.prepare) instead of failing, or swapping, mid-flight.
HISTORY_BUDGET_BYTES = 2 * 1024**3


def row_bytes() -> int:
    """Bytes of one history row (every field, both sides)."""
    return sum(int(np.dtype(_DTYPES.get(k, np.float64)).itemsize * math.prod(shp))
               for k, shp in FIELDS.items() if k not in TRUTH_FIELDS) + TRUTH.itemsize


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
        self.a = {k: np.zeros((n_max,) + shp, dtype=_DTYPES.get(k, np.float64)) for k, shp in FIELDS.items()
                  if k not in TRUTH_FIELDS}
        self._truth_rows(np.zeros(n_max, dtype=TRUTH))

    def _truth_rows(self, rows: np.ndarray) -> None:
        """The truth half lives in one TRUTH-record array; a[name] are views of its fields."""
        self.truth_rows = rows
        for k in TRUTH_FIELDS:
            self.a[k] = rows[k]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.a[name][: self.n]

    def row(self) -> int:
        """Index of a new row (grows by doubling if a run outlives its estimate)."""
        if self.n >= self.n_max:
            for k, v in self.a.items():
                if k not in TRUTH_FIELDS:
                    self.a[k] = np.concatenate((v, np.zeros_like(v)))
            self._truth_rows(np.concatenate((self.truth_rows, np.zeros_like(self.truth_rows))))
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


def record_fsw(h: History, i: int, fsw, u: np.ndarray, compute_ns: int) -> None:
    """The flight software's half of row i, after its control cycle for that step."""
    a = h.a
    a["k"][i] = fsw.k          # the same step index as the truth half: merge() aligns on it
    g = fsw.guidance
    a["bank_ref_rad"][i] = g.phi_r
    a["bankdot_ref_radps"][i] = g.phidot_r
    a["sigma_RN"][i] = g.sigma_RN
    a["u_cal_B"][i] = fsw.u_cal_B
    a["tau_alloc_B"][i] = fsw.tau_alloc_B
    a["theta_hat"][i] = fsw.control.theta_hat
    a["jets_cmd"][i] = u
    a["health"][i] = fsw.health.state
    a["mode"][i] = int(fsw.modes.mode)
    a["alloc_degraded"][i] = fsw.allocator.degraded
    a["alloc_short"][i] = fsw.alloc_short
    a["compute_us"][i] = compute_ns * 1e-3
    a["alloc_us"][i] = fsw.alloc_ns * 1e-3
    (a["guid_cycles"][i], a["guid_flags"][i], a["target_lat_rad"][i], a["target_lon_rad"][i],
     a["pred_lat_rad"][i], a["pred_lon_rad"][i], a["bank_cmd_rad"][i]) = guidance_fields(fsw)


def guidance_fields(fsw) -> tuple:
    """(guid_cycles, guid_flags, target lat, lon, predicted deploy lat, lon [rad], bank command
    [rad]) of the FSW now, as FSW_STATE carries them: a value not available (no target, no
    answer yet, profile mode, non-finite) is 0 with its guid_flags bit clear."""
    scn, e = fsw.scenario, fsw.entry
    flags, tlat, tlon, plat, plon, bank, cycles = 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0
    if scn.target_lat_rad is not None and math.isfinite(scn.target_lat_rad) and math.isfinite(scn.target_lon_rad):
        flags, tlat, tlon = GUID_TARGET, scn.target_lat_rad, scn.target_lon_rad
    if e is not None:
        flags |= GUID_NPC
        cycles = e.cycles
        bank = e.bank_cmd if math.isfinite(e.bank_cmd) else 0.0
        p = e.pred_impact
        if cycles > 0 and math.isfinite(p[0]) and math.isfinite(p[1]):
            flags |= GUID_PREDICTION
            plat, plon = float(p[0]), float(p[1])
    return cycles, flags, tlat, tlon, plat, plon, bank


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
