"""Navigation processing: from a sensor frame to what guidance and control need
(docs/fsw/index.md, RG1 step 1). Uses only the FSW's own nominal models."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from common import atmosphere, frames, mrp
from common.model import Planet, Vehicle
from interfaces.records import SENSORS

_rho_exp = njit(cache=True)(atmosphere.density_exponential)
_rho_poly = njit(cache=True)(atmosphere.density_polynomial)
_speed_of_sound = njit(cache=True)(atmosphere.speed_of_sound)
_MODEL_FLAG = {"exponential": 0, "polynomial": 1}


# one frame's vectors, packed as the SENSORS record holds them (interfaces/records.py):
# omega_BN_B, sigma_BN, r_N, v_N, accel_B, 3 floats each from the record's omega_BN_B
_IN_FIELDS = ("omega_BN_B", "sigma_BN", "r_N", "v_N", "accel_B")
_IN0 = SENSORS.fields["omega_BN_B"][1]
assert all(SENSORS.fields[f][1] == _IN0 + 24 * i for i, f in enumerate(_IN_FIELDS))
N_IN = 15
# the NavState arrays, views of one buffer the kernel writes: sigma, omega, r, v, accel, vrel
# (3 each), C_WN, C_BN (9 each, row-major); then the scalars, for the compiled law that reads
# them from here (fsw/law.py ``law_cycle``): t, V_rel, h, alpha, beta, bank, rho, qbar, mach
_S_SIGMA, _S_OMEGA, _S_R, _S_V, _S_ACC, _S_VREL, _S_CWN, _S_CBN = 0, 3, 6, 9, 12, 15, 18, 27
_S_T, _S_VR, _S_H, _S_ALPHA, _S_BETA, _S_BANK, _S_RHO, _S_QBAR, _S_MACH, _S_N = 36, 37, 38, 39, 40, 41, 42, 43, 44, 45


def frame_vectors(frame: np.ndarray) -> np.ndarray:
    """The packed input of ``Navigation.update_packed``: a float64 view of one SENSORS
    record's omega_BN_B, sigma_BN, r_N, v_N and accel_B (made once per record object)."""
    return np.ndarray((N_IN,), dtype=np.float64, buffer=frame, offset=_IN0)


class NavState:
    """The FSW's estimate of the flight condition at one control cycle.

    Attributes (updated in place each cycle):
      t_s, sigma_BN (3), omega_BN_B (3) [rad/s], r_N (3) [m], v_N (3) [m/s],
      vrel_N (3), V_rel_mps, h_m, C_WN (3x3), C_BN (3x3), alpha_rad, beta_rad, bank_rad,
      rho_kgpm3 (FSW model, undispersed), qbar_pa, mach, accel_B (3) [m/s^2].
    The arrays are views of one buffer (``buf``), which the compiled update writes; it also
    holds a copy of the scalars (``_S_T`` on), the compiled law's (the attributes are Python's).
    """

    def __init__(self):
        self.buf = b = np.zeros(_S_N)
        self.t_s = 0.0
        self.sigma_BN = b[_S_SIGMA:_S_SIGMA + 3]
        self.omega_BN_B = b[_S_OMEGA:_S_OMEGA + 3]
        self.r_N = b[_S_R:_S_R + 3]
        self.v_N = b[_S_V:_S_V + 3]
        self.vrel_N = b[_S_VREL:_S_VREL + 3]
        self.accel_B = b[_S_ACC:_S_ACC + 3]
        self.C_WN = b[_S_CWN:_S_CWN + 9].reshape(3, 3)
        self.C_BN = b[_S_CBN:_S_CBN + 9].reshape(3, 3)
        self.C_WN[:] = np.eye(3)
        self.C_BN[:] = np.eye(3)
        self.V_rel_mps = 0.0
        self.h_m = 0.0
        self.alpha_rad = 0.0
        self.beta_rad = 0.0
        self.bank_rad = 0.0
        self.rho_kgpm3 = 0.0
        self.qbar_pa = 0.0
        self.mach = 0.0


@njit(cache=True)
def _nav_kernel(x, omega_planet, radius_m, model, rho0, H_m, b):
    """One navigation update from the packed frame vectors ``x`` (frame_vectors' order) into
    the NavState buffer ``b`` (the scalars too, after the arrays: not the time, the caller's);
    returns (V_rel, h, alpha, beta, bank, rho, qbar, mach). Same
    steps as the NumPy code it replaced: copy the inputs, v_rel = v - Omega x r, |v_rel|,
    h = |r| - R, C_WN, C_BN, aerodynamic angles, model density (0 exponential, 1
    polynomial), dynamic pressure, Mach."""
    n_sigma = b[_S_SIGMA:_S_SIGMA + 3]
    n_r = b[_S_R:_S_R + 3]
    n_v = b[_S_V:_S_V + 3]
    n_vrel = b[_S_VREL:_S_VREL + 3]
    n_C_WN = b[_S_CWN:_S_CWN + 9].reshape((3, 3))
    n_C_BN = b[_S_CBN:_S_CBN + 9].reshape((3, 3))
    for j in range(3):
        b[_S_OMEGA + j] = x[j]
        b[_S_SIGMA + j] = x[3 + j]
        b[_S_R + j] = x[6 + j]
        b[_S_V + j] = x[9 + j]
        b[_S_ACC + j] = x[12 + j]
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
    b[_S_VR] = V
    b[_S_H] = h
    b[_S_ALPHA] = alpha
    b[_S_BETA] = beta
    b[_S_BANK] = bank
    b[_S_RHO] = rho
    b[_S_QBAR] = qbar
    b[_S_MACH] = mach
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
        self._x = np.zeros(N_IN)            # update's inputs, packed
        self._r_buf = np.zeros(_S_N)        # rehearse's copy of the state's buffer

    def update(self, t_s: float, sigma_BN, omega_BN_B, r_N, v_N, accel_B) -> NavState:
        """The flight condition at t_s from one frame's attitude, rate, position, velocity
        and sensed acceleration (anything that fills a 3-vector, broadcast and converted as
        NumPy does); returns the NavState, updated in place."""
        x = self._x
        x[0:3] = omega_BN_B
        x[3:6] = sigma_BN
        x[6:9] = r_N
        x[9:12] = v_N
        x[12:15] = accel_B
        return self.update_packed(t_s, x)

    def update_packed(self, t_s: float, x: np.ndarray) -> NavState:
        """``update`` from the packed vectors (``frame_vectors`` of a SENSORS record, or any
        float64 array of 15 in its order): one compiled call."""
        n = self.state
        n.t_s = t_s
        n.buf[_S_T] = t_s
        om, R, model, rho0, H = self._consts
        (n.V_rel_mps, n.h_m, n.alpha_rad, n.beta_rad, n.bank_rad, n.rho_kgpm3, n.qbar_pa,
         n.mach) = _nav_kernel(x, om, R, model, rho0, H, n.buf)
        return n

    def kernel_args(self, buf: np.ndarray | None = None) -> tuple:
        """``_nav_kernel``'s arguments after the packed frame: the planet's constants and the
        buffer it writes (the state's, or ``buf``)."""
        return (*self._consts, self.state.buf if buf is None else buf)

    def rehearsal_copy(self) -> np.ndarray:
        """The rehearsal's copy of the state's buffer, refreshed (its update writes there)."""
        np.copyto(self._r_buf, self.state.buf)
        return self._r_buf
