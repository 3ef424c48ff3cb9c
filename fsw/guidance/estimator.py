"""The entry guidance's density estimator: how far the sensed drag and lift depart from the
FSW's models, for the predictor's constants K_rho and K_LD.
"""
from __future__ import annotations

import math

import numpy as np


class DensityEstimator:
    """K_rho = sensed drag / modelled drag and K_LD = sensed L/D / model L/D, first-order
    low-pass filtered (time constant npc.k_tau_s), bounded to [k_min, k_max], held while
    the modelled drag is below npc.k_drag_min (too thin an atmosphere to measure)."""

    def __init__(self, params: dict, S_m2: float, mass_kg: float, C_L: float, C_D: float):
        self.tau_s = params["npc.k_tau_s"]
        self.k_min, self.k_max = params["npc.k_min"], params["npc.k_max"]
        self.drag_min_mps2 = params["npc.k_drag_min"]
        self.area_per_mass_m2pkg, self.C_L, self.C_D = S_m2 / mass_kg, C_L, C_D
        self.k_rho = 1.0
        self.k_ld = 1.0
        self.updates = 0
        self.drag_sensed_mps2 = 0.0
        self.lift_sensed_mps2 = 0.0

    def update(self, dt_s: float, accel_B: np.ndarray, C_BN: np.ndarray, vrel_N: np.ndarray,
               rho_model_kgpm3: float) -> None:
        """One control period: sensed acceleration (body axes) rotated to N, split into drag
        along and lift across the planet-relative velocity, against the model's drag."""
        V = math.sqrt(float(vrel_N @ vrel_N))
        if V <= 0.0:
            return
        a_N = C_BN.T @ accel_B
        drag = -float(a_N @ vrel_N) / V
        lift_v = a_N + drag * vrel_N / V
        lift = math.sqrt(float(lift_v @ lift_v))
        self.drag_sensed_mps2, self.lift_sensed_mps2 = drag, lift
        d_model = 0.5 * rho_model_kgpm3 * V * V * self.area_per_mass_m2pkg * self.C_D
        if d_model < self.drag_min_mps2 or drag <= 0.0:
            return
        a = min(1.0, dt_s / self.tau_s)
        k = min(self.k_max, max(self.k_min, drag / d_model))
        kl = min(self.k_max, max(self.k_min, (lift / drag) / (self.C_L / self.C_D))) if self.C_L != 0 else 1.0
        self.k_rho += a * (k - self.k_rho)
        self.k_ld += a * (kl - self.k_ld)
        self.updates += 1
