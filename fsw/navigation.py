"""Navigation processing: from a sensor frame to what guidance and control need
(docs/fsw/index.md, RG1 step 1). Uses only the FSW's own nominal models."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from common import atmosphere, frames, mrp
from common.model import Planet, Vehicle

_rho_exp = njit(cache=True)(atmosphere.density_exponential)
_rho_poly = njit(cache=True)(atmosphere.density_polynomial)
_speed_of_sound = njit(cache=True)(atmosphere.speed_of_sound)
_F8 = np.dtype(np.float64)
_MODEL_FLAG = {"exponential": 0, "polynomial": 1}


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


@njit(cache=True)
def _nav_kernel(sigma_BN, omega_BN_B, r_N, v_N, accel_B, omega_planet, radius_m, model, rho0, H_m,
                n_sigma, n_omega, n_r, n_v, n_accel, n_vrel, n_C_WN, n_C_BN):
    """One navigation update into the NavState arrays n_*; returns (V_rel, h, alpha, beta,
    bank, rho, qbar, mach). Same steps as the NumPy code it replaced: copy the inputs,
    v_rel = v - Omega x r, |v_rel|, h = |r| - R, C_WN, C_BN, aerodynamic angles, model
    density (0 exponential, 1 polynomial), dynamic pressure, Mach."""
    for j in range(3):
        n_sigma[j] = sigma_BN[j]
        n_omega[j] = omega_BN_B[j]
        n_r[j] = r_N[j]
        n_v[j] = v_N[j]
        n_accel[j] = accel_B[j]
    n_vrel[0] = n_v[0] + omega_planet * n_r[1]
    n_vrel[1] = n_v[1] - omega_planet * n_r[0]
    n_vrel[2] = n_v[2]
    V = math.sqrt(n_vrel[0] * n_vrel[0] + n_vrel[1] * n_vrel[1] + n_vrel[2] * n_vrel[2])
    h = math.sqrt(n_r[0] * n_r[0] + n_r[1] * n_r[1] + n_r[2] * n_r[2]) - radius_m
    n_C_WN[:, :] = frames.wind_dcm(n_r, n_vrel)
    n_C_BN[:, :] = mrp.to_dcm(n_sigma)
    alpha, beta, bank = frames.aero_angles(n_C_BN, n_C_WN)
    if model == 0:
        rho = _rho_exp(h, rho0, H_m)
    else:
        rho = _rho_poly(h)
    qbar = 0.5 * rho * V ** 2
    mach = V / _speed_of_sound(h)
    return V, h, alpha, beta, bank, rho, qbar, mach


class Navigation:
    """Derives the flight condition from gyro, attitude and navigation sensors."""

    def __init__(self, planet: Planet, vehicle: Vehicle):
        self.planet = planet
        self.vehicle = vehicle
        self._model = _MODEL_FLAG[planet.density_model]
        self._consts = (float(planet.omega_radps), float(planet.radius_m), self._model,
                        float(planet.rho0_kgpm3), float(planet.scale_height_m))
        self.state = NavState()

    def update(self, t_s: float, sigma_BN, omega_BN_B, r_N, v_N, accel_B) -> NavState:
        """The flight condition at t_s from one frame's attitude, rate, position, velocity
        and sensed acceleration (anything that fills a 3-vector); returns the NavState,
        updated in place. One compiled call when the inputs are float64 3-vectors."""
        n = self.state
        n.t_s = t_s
        nd = np.ndarray
        if not (type(sigma_BN) is nd and sigma_BN.dtype == _F8 and sigma_BN.shape == (3,)
                and type(omega_BN_B) is nd and omega_BN_B.dtype == _F8 and omega_BN_B.shape == (3,)
                and type(r_N) is nd and r_N.dtype == _F8 and r_N.shape == (3,)
                and type(v_N) is nd and v_N.dtype == _F8 and v_N.shape == (3,)
                and type(accel_B) is nd and accel_B.dtype == _F8 and accel_B.shape == (3,)):
            n.sigma_BN[:] = sigma_BN           # broadcast / convert as NumPy does, then the same kernel
            n.omega_BN_B[:] = omega_BN_B
            n.r_N[:] = r_N
            n.v_N[:] = v_N
            n.accel_B[:] = accel_B
            sigma_BN, omega_BN_B, r_N, v_N, accel_B = n.sigma_BN, n.omega_BN_B, n.r_N, n.v_N, n.accel_B
        om, R, model, rho0, H = self._consts
        (n.V_rel_mps, n.h_m, n.alpha_rad, n.beta_rad, n.bank_rad, n.rho_kgpm3, n.qbar_pa,
         n.mach) = _nav_kernel(sigma_BN, omega_BN_B, r_N, v_N, accel_B, om, R, model, rho0, H,
                               n.sigma_BN, n.omega_BN_B, n.r_N, n.v_N, n.accel_B, n.vrel_N, n.C_WN, n.C_BN)
        return n
