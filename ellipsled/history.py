"""Run history: preallocated per-control-step arrays shared by the batch runner and the SIL.

One row per control step k. The batch runner fills it in-process; the SIL launcher fills
it from the truth and FSW-state records the processes publish. Figures of merit
(ellipsled/metrics.py) and plots read only this, so batch and SIL are judged alike.
"""
from __future__ import annotations

import numpy as np

N_JETS = 18

# name -> trailing shape; all float64 except where noted in _DTYPES
FIELDS: dict[str, tuple[int, ...]] = {
    "t_s": (),
    # truth (plant)
    "bank_rad": (), "alpha_rad": (), "beta_rad": (), "omega_BN_B": (3,), "sigma_BN": (3,),
    "h_m": (), "V_rel_mps": (), "gamma_rad": (), "psi_rad": (), "lat_rad": (), "lon_rad": (),
    "mach": (), "qbar_pa": (), "decel_g": (), "tau_jets_B": (3,),
    # flight software
    "bank_ref_rad": (), "bankdot_ref_radps": (), "sigma_RN": (3,), "u_cal_B": (3,), "tau_alloc_B": (3,),
    "theta_hat": (9,), "jets_cmd": (N_JETS,), "health": (N_JETS,), "mode": (),
    "alloc_degraded": (), "compute_us": (), "alloc_us": (),
}
_DTYPES = {"jets_cmd": np.uint8, "health": np.int8, "mode": np.int8, "alloc_degraded": np.uint8}


class History:
    def __init__(self, n_max: int):
        self.n = 0
        self.n_max = n_max
        self.a = {k: np.zeros((n_max,) + shp, dtype=_DTYPES.get(k, np.float64)) for k, shp in FIELDS.items()}

    def __getitem__(self, name: str) -> np.ndarray:
        return self.a[name][: self.n]

    def row(self) -> int:
        """Index of a new row (grows by doubling if a run outlives its estimate)."""
        if self.n >= self.n_max:
            for k, v in self.a.items():
                self.a[k] = np.concatenate((v, np.zeros_like(v)))
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
