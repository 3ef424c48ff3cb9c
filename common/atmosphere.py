"""Mars atmosphere models (docs/plant.md). Pure functions of altitude; the plant uses
them with a dispersion factor as truth, the FSW uses them undispersed as its own model."""
from __future__ import annotations

import math


def density_exponential(h_m: float, rho0: float = 0.0158, H_m: float = 9354.5) -> float:
    """rho(h) = rho0 exp(-h/H) [kg/m^3]."""
    return rho0 * math.exp(-h_m / H_m)


def density_polynomial(h_m: float) -> float:
    """The smoother alternative: exp(-4.324 - 9.204e-5 h - 1.936e-11 h^2 - 7.507e-15 h^3 + 4.195e-20 h^4)."""
    h = h_m
    return math.exp(-4.324 - 9.204e-5 * h - 1.936e-11 * h * h - 7.507e-15 * h ** 3 + 4.195e-20 * h ** 4)


def speed_of_sound(h_m: float) -> float:
    """a(h) [m/s], held at its 80 km value above 80 km."""
    h = min(h_m, 80_000.0)
    return 223.8 - 2.004e-4 * h - 1.588e-8 * h * h + 1.404e-13 * h ** 3


DENSITY_MODELS = {"exponential": density_exponential, "polynomial": density_polynomial}
