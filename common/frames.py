"""Frame rotations and the wind/aerodynamic angles (spec 10-plant.md, frames).

R1, R2, R3 are frame-rotation matrices (they map components in the old frame to the
new frame). W: w1 along v_rel, w2 = (v_rel x r)/|.| (right), w3 = w1 x w2 (down).
C_BN = R2(alpha) R3(-beta) R1(bank) C_WN.
"""
from __future__ import annotations

import math

import numpy as np


def R1(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, s], [0.0, -s, c]])


def R2(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])


def R3(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def v_rel_N(r_N: np.ndarray, v_N: np.ndarray, omega_planet: float) -> np.ndarray:
    """Planet-relative velocity v - Omega x r, Omega along N3."""
    return np.array([v_N[0] + omega_planet * r_N[1], v_N[1] - omega_planet * r_N[0], v_N[2]])


def wind_dcm(r_N: np.ndarray, vrel_N: np.ndarray) -> np.ndarray:
    """C_WN: rows are w1, w2, w3 in N components."""
    w1 = vrel_N / np.linalg.norm(vrel_N)
    h = np.cross(vrel_N, r_N)
    w2 = h / np.linalg.norm(h)
    w3 = np.cross(w1, w2)
    return np.vstack((w1, w2, w3))


def aero_angles(C_BN: np.ndarray, C_WN: np.ndarray) -> tuple[float, float, float]:
    """(alpha, beta, bank) [rad] from the body attitude and the wind frame.

    v_rel in B is V [cos a cos b, sin b, sin a cos b]; the bank is what remains of
    C_BW after removing R2(alpha) R3(-beta).
    """
    C_BW = C_BN @ C_WN.T
    w1_B = C_BW[:, 0]
    beta = math.asin(max(-1.0, min(1.0, w1_B[1])))
    alpha = math.atan2(w1_B[2], w1_B[0])
    C_AW = (R2(alpha) @ R3(-beta)).T @ C_BW
    bank = math.atan2(C_AW[1, 2], C_AW[1, 1])
    return alpha, beta, bank


def wrap_pi(a: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))
