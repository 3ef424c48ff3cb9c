"""Frame rotations and the wind/aerodynamic angles (docs/plant.md, frames).

R1, R2, R3 are frame-rotation matrices (they map components in the old frame to the
new frame). W: w1 along v_rel, w2 = (v_rel x r)/|.| (right), w3 = w1 x w2 (down).
C_BN = R2(alpha) R3(-beta) R1(bank) C_WN.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


def R1(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def R2(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def R3(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


@njit(cache=True)
def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b for 3-vectors (np.cross's per-call dispatch outweighs the arithmetic on small arrays)."""
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


def v_rel_N(r_N: np.ndarray, v_N: np.ndarray, omega_planet: float) -> np.ndarray:
    """Planet-relative velocity v - Omega x r, Omega along N3."""
    return np.array([v_N[0] + omega_planet * r_N[1], v_N[1] - omega_planet * r_N[0], v_N[2]])


@njit(cache=True)
def wind_dcm(r_N: np.ndarray, vrel_N: np.ndarray) -> np.ndarray:
    """C_WN: rows are w1, w2, w3 in N components."""
    C = np.empty((3, 3))
    w1 = vrel_N / math.sqrt(vrel_N[0] ** 2 + vrel_N[1] ** 2 + vrel_N[2] ** 2)
    h = cross3(vrel_N, r_N)
    w2 = h / math.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2)
    w3 = cross3(w1, w2)
    C[0, :] = w1
    C[1, :] = w2
    C[2, :] = w3
    return C


def local_axes(r_N: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(north, east, up) unit vectors in N at position r_N (spherical planet)."""
    up = r_N / math.sqrt(r_N[0] ** 2 + r_N[1] ** 2 + r_N[2] ** 2)
    lam = math.atan2(r_N[1], r_N[0])
    east = np.array([-math.sin(lam), math.cos(lam), 0.0])
    return cross3(up, east), east, up


@njit(cache=True)
def aero_angles(C_BN: np.ndarray, C_WN: np.ndarray) -> tuple[float, float, float]:
    """(alpha, beta, bank) [rad] from the body attitude and the wind frame.

    v_rel in B is V [cos a cos b, sin b, sin a cos b]; the bank is what remains of
    C_BW after removing R2(alpha) R3(-beta).
    """
    C_BW = C_BN @ C_WN.T
    beta = math.asin(max(-1.0, min(1.0, C_BW[1, 0])))
    alpha = math.atan2(C_BW[2, 0], C_BW[0, 0])
    # C_AW = (R2(alpha) R3(-beta))^T C_BW; only row 2 (index 1) is needed for the bank
    ca, sa, cb, sb = math.cos(alpha), math.sin(alpha), math.cos(beta), math.sin(beta)
    # (R2(a) R3(-b))^T row 1 = column 1 of R2(a) R3(-b) = [-sb*ca... ] written out:
    m10 = -ca * sb
    m11 = cb
    m12 = -sa * sb
    c_aw_11 = m10 * C_BW[0, 1] + m11 * C_BW[1, 1] + m12 * C_BW[2, 1]
    c_aw_12 = m10 * C_BW[0, 2] + m11 * C_BW[1, 2] + m12 * C_BW[2, 2]
    bank = math.atan2(c_aw_12, c_aw_11)
    return alpha, beta, bank


def wrap_pi(a: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))
