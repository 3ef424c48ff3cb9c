"""Sphere geometry of the entry guidance on the FSW's spherical planet: the planet-fixed
state, great-circle angles, the heading error to the target and the crossrange off the
great circle to it.
"""
from __future__ import annotations

import math

import numpy as np


def central_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Great-circle angle between two position vectors [rad] (atan2 form: exact near 0)."""
    cr = np.cross(a, b)
    return math.atan2(math.sqrt(float(cr @ cr)), float(a @ b))


def unit_from_latlon(lat_rad: float, lon_rad: float) -> np.ndarray:
    """Unit position vector, planet-fixed, of a latitude and longitude [rad]."""
    return np.array([math.cos(lat_rad) * math.cos(lon_rad), math.cos(lat_rad) * math.sin(lon_rad),
                     math.sin(lat_rad)])


def planet_fixed(r_N: np.ndarray, v_N: np.ndarray, t_s: float, omega_radps: float) -> np.ndarray:
    """[r, v_rel] in the planet-fixed frame at t (N and the planet frame coincide at t = 0;
    longitude = atan2(y, x) - Omega t, as the plant reports it)."""
    a = omega_radps * t_s
    ca, sa = math.cos(a), math.sin(a)
    vr = np.array([v_N[0] + omega_radps * r_N[1], v_N[1] - omega_radps * r_N[0], v_N[2]])
    x = np.empty(6)
    x[0], x[1], x[2] = ca * r_N[0] + sa * r_N[1], -sa * r_N[0] + ca * r_N[1], r_N[2]
    x[3], x[4], x[5] = ca * vr[0] + sa * vr[1], -sa * vr[0] + ca * vr[1], vr[2]
    return x


def heading_error(x: np.ndarray, target_u: np.ndarray) -> tuple[float, float]:
    """(heading error to the target [rad] (positive: the target lies to the left), range
    to go [rad]) from a planet-fixed state. Heading clockwise from north."""
    r = x[:3]
    up = r / np.linalg.norm(r)
    east = np.array([-up[1], up[0], 0.0])
    en = np.linalg.norm(east)
    east = east / en if en > 1e-12 else np.array([0.0, 1.0, 0.0])
    north = np.cross(up, east)
    v = x[3:]
    psi = math.atan2(float(v @ east), float(v @ north))
    d = target_u - float(target_u @ up) * up          # direction to the target, in the local plane
    bearing = math.atan2(float(d @ east), float(d @ north))
    return math.remainder(psi - bearing, 2.0 * math.pi), central_angle(r, target_u)


def crossrange(r_now: np.ndarray, target_u: np.ndarray, r_f: np.ndarray, radius_m: float) -> float:
    """Signed distance [m] of the point r_f off the great circle from r_now to the target,
    positive to the left of that path (atan2 form of the angle off the circle's plane)."""
    n = np.cross(r_now, target_u)
    nn = math.sqrt(float(n @ n))
    if nn == 0.0:
        return 0.0
    rf = math.sqrt(float(r_f @ r_f))
    s = float(r_f @ n) / (nn * rf)
    return math.asin(min(1.0, max(-1.0, s))) * radius_m
