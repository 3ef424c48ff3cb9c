"""Modified Rodrigues parameters (MRPs) and the small rotation helpers around them.

Conventions (spec 10-plant.md): sigma_BN is the attitude of B relative to N, C_BN maps
N components to B components, omega is expressed in B. sigma_dot = 1/4 B(sigma) omega.
"""
from __future__ import annotations

import numpy as np
from numba import njit


def tilde(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v x] so that tilde(v) @ w == np.cross(v, w)."""
    return np.array([[0.0, -v[2], v[1]],
                     [v[2], 0.0, -v[0]],
                     [-v[1], v[0], 0.0]])


def B_matrix(sigma: np.ndarray) -> np.ndarray:
    """B(sigma) = (1 - s.s) I + 2[s x] + 2 s s^T (spec 10-plant.md, kinematics)."""
    s2 = float(sigma @ sigma)
    return (1.0 - s2) * np.eye(3) + 2.0 * tilde(sigma) + 2.0 * np.outer(sigma, sigma)


def B_dot(sigma: np.ndarray, sigma_dot: np.ndarray) -> np.ndarray:
    """Time derivative of B(sigma) (spec 20-fsw.md, SAMI notation)."""
    return (-2.0 * float(sigma @ sigma_dot) * np.eye(3) + 2.0 * tilde(sigma_dot)
            + 2.0 * (np.outer(sigma_dot, sigma) + np.outer(sigma, sigma_dot)))


def sigma_dot(sigma: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """MRP kinematics sigma_dot = 1/4 B(sigma) omega."""
    return 0.25 * B_matrix(sigma) @ omega


def omega_from_sigma_dot(sigma: np.ndarray, sdot: np.ndarray) -> np.ndarray:
    """Inverse kinematics omega = 4 B^T sigma_dot / (1 + s.s)^2 (B^T B = (1+s.s)^2 I)."""
    s2 = float(sigma @ sigma)
    return 4.0 * B_matrix(sigma).T @ sdot / (1.0 + s2) ** 2


def shadow(sigma: np.ndarray) -> np.ndarray:
    """The shadow set -sigma/|sigma|^2 (same attitude)."""
    return -sigma / float(sigma @ sigma)


def switch_shadow(sigma: np.ndarray) -> np.ndarray:
    """Return sigma with |sigma| <= 1, switching to the shadow set when |sigma| > 1."""
    s2 = float(sigma @ sigma)
    return -sigma / s2 if s2 > 1.0 else sigma


@njit(cache=True)
def to_dcm(sigma: np.ndarray) -> np.ndarray:
    """C_BN from sigma_BN: I + (8[s x]^2 - 4(1 - s.s)[s x]) / (1 + s.s)^2, written out."""
    s1, s2_, s3 = sigma[0], sigma[1], sigma[2]
    ss = s1 * s1 + s2_ * s2_ + s3 * s3
    d = 1.0 / (1.0 + ss) ** 2
    a = 1.0 - ss
    C = np.empty((3, 3))
    C[0, 0] = 1.0 + d * (8.0 * (-s2_ * s2_ - s3 * s3))
    C[1, 1] = 1.0 + d * (8.0 * (-s1 * s1 - s3 * s3))
    C[2, 2] = 1.0 + d * (8.0 * (-s1 * s1 - s2_ * s2_))
    C[0, 1] = d * (8.0 * s1 * s2_ + 4.0 * a * s3)
    C[0, 2] = d * (8.0 * s1 * s3 - 4.0 * a * s2_)
    C[1, 0] = d * (8.0 * s1 * s2_ - 4.0 * a * s3)
    C[1, 2] = d * (8.0 * s2_ * s3 + 4.0 * a * s1)
    C[2, 0] = d * (8.0 * s1 * s3 + 4.0 * a * s2_)
    C[2, 1] = d * (8.0 * s2_ * s3 - 4.0 * a * s1)
    return C


def from_dcm(C: np.ndarray) -> np.ndarray:
    """sigma (|sigma| <= 1) from a direction-cosine matrix, via the quaternion (Shepperd)."""
    q = dcm_to_quat(C)
    if q[0] < 0.0:
        q = -q
    return q[1:] / (1.0 + q[0])


def dcm_to_quat(C: np.ndarray) -> np.ndarray:
    """Scalar-first unit quaternion [q0, q1, q2, q3] of a DCM (Shepperd's method)."""
    tr = C[0, 0] + C[1, 1] + C[2, 2]
    b2 = np.array([(1 + tr), (1 + 2 * C[0, 0] - tr), (1 + 2 * C[1, 1] - tr),
                   (1 + 2 * C[2, 2] - tr)]) / 4.0
    i = int(np.argmax(b2))
    q = np.empty(4)
    if i == 0:
        q[0] = np.sqrt(b2[0])
        q[1] = (C[1, 2] - C[2, 1]) / (4 * q[0])
        q[2] = (C[2, 0] - C[0, 2]) / (4 * q[0])
        q[3] = (C[0, 1] - C[1, 0]) / (4 * q[0])
    elif i == 1:
        q[1] = np.sqrt(b2[1])
        q[0] = (C[1, 2] - C[2, 1]) / (4 * q[1])
        q[2] = (C[0, 1] + C[1, 0]) / (4 * q[1])
        q[3] = (C[2, 0] + C[0, 2]) / (4 * q[1])
    elif i == 2:
        q[2] = np.sqrt(b2[2])
        q[0] = (C[2, 0] - C[0, 2]) / (4 * q[2])
        q[1] = (C[0, 1] + C[1, 0]) / (4 * q[2])
        q[3] = (C[1, 2] + C[2, 1]) / (4 * q[2])
    else:
        q[3] = np.sqrt(b2[3])
        q[0] = (C[0, 1] - C[1, 0]) / (4 * q[3])
        q[1] = (C[2, 0] + C[0, 2]) / (4 * q[3])
        q[2] = (C[1, 2] + C[2, 1]) / (4 * q[3])
    if q[0] < 0.0:
        q = -q
    return q


def sigma_to_quat(sigma: np.ndarray) -> np.ndarray:
    """Scalar-first quaternion of an MRP."""
    s2 = float(sigma @ sigma)
    return np.concatenate(([(1.0 - s2) / (1.0 + s2)], 2.0 * sigma / (1.0 + s2)))


@njit(cache=True)
def nearest_set_into(sigma_ref: np.ndarray, sigma: np.ndarray) -> None:
    """Replace sigma_ref (in place) by its shadow set when that is closer to sigma, so that
    sigma - sigma_ref never jumps. Callable from compiled kernels and from Python."""
    s2 = sigma_ref[0] ** 2 + sigma_ref[1] ** 2 + sigma_ref[2] ** 2
    if s2 > 1e-300:
        d0 = 0.0
        d1 = 0.0
        for i in range(3):
            d0 += (sigma[i] - sigma_ref[i]) ** 2
            d1 += (sigma[i] + sigma_ref[i] / s2) ** 2
        if d1 < d0:
            for i in range(3):
                sigma_ref[i] = -sigma_ref[i] / s2


def nearest_set(sigma_ref: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """The MRP set (sigma_ref or its shadow) closest to sigma, so sigma - sigma_ref never jumps."""
    out = np.array(sigma_ref, dtype=float)
    nearest_set_into(out, np.asarray(sigma, dtype=float))
    return out
