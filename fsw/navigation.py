"""Navigation processing: from a sensor frame to what guidance and control need
(spec 20-fsw.md, RG1 step 1). Uses only the FSW's own nominal models."""
from __future__ import annotations

import math

import numpy as np

from common import atmosphere, frames, mrp
from common.model import Planet, Vehicle


class NavState:
    """The FSW's estimate of the flight condition at one control cycle.

    Attributes (updated in place each cycle):
      t_s, sigma_BN (3), omega_BN_B (3) [rad/s], r_N (3) [m], v_N (3) [m/s],
      vrel_N (3), V_rel_mps, h_m, C_WN (3x3), C_BN (3x3), alpha_rad, beta_rad, bank_rad,
      rho_kgpm3 (FSW model, undispersed), qbar_pa, mach, accel_B (3) [m/s^2].
    """

    def __init__(self):
        self.t_s = 0.0
        self.sigma_BN = np.zeros(3)
        self.omega_BN_B = np.zeros(3)
        self.r_N = np.zeros(3)
        self.v_N = np.zeros(3)
        self.vrel_N = np.zeros(3)
        self.accel_B = np.zeros(3)
        self.C_WN = np.eye(3)
        self.C_BN = np.eye(3)
        self.V_rel_mps = 0.0
        self.h_m = 0.0
        self.alpha_rad = 0.0
        self.beta_rad = 0.0
        self.bank_rad = 0.0
        self.rho_kgpm3 = 0.0
        self.qbar_pa = 0.0
        self.mach = 0.0


class Navigation:
    """Derives the flight condition from gyro, attitude and navigation sensors."""

    def __init__(self, planet: Planet, vehicle: Vehicle):
        self.planet = planet
        self.vehicle = vehicle
        self._density = atmosphere.DENSITY_MODELS[planet.density_model]
        self.state = NavState()

    def density(self, h_m: float) -> float:
        if self.planet.density_model == "exponential":
            return atmosphere.density_exponential(h_m, self.planet.rho0_kgpm3, self.planet.scale_height_m)
        return self._density(h_m)

    def update(self, t_s: float, sigma_BN, omega_BN_B, r_N, v_N, accel_B) -> NavState:
        n = self.state
        n.t_s = t_s
        n.sigma_BN[:] = sigma_BN
        n.omega_BN_B[:] = omega_BN_B
        n.r_N[:] = r_N
        n.v_N[:] = v_N
        n.accel_B[:] = accel_B
        n.vrel_N[:] = frames.v_rel_N(n.r_N, n.v_N, self.planet.omega_radps)
        n.V_rel_mps = float(np.linalg.norm(n.vrel_N))
        n.h_m = float(np.linalg.norm(n.r_N)) - self.planet.radius_m
        n.C_WN[:] = frames.wind_dcm(n.r_N, n.vrel_N)
        n.C_BN[:] = mrp.to_dcm(n.sigma_BN)
        n.alpha_rad, n.beta_rad, n.bank_rad = frames.aero_angles(n.C_BN, n.C_WN)
        n.rho_kgpm3 = self.density(n.h_m)
        n.qbar_pa = 0.5 * n.rho_kgpm3 * n.V_rel_mps ** 2
        n.mach = n.V_rel_mps / atmosphere.speed_of_sound(n.h_m)
        return n
