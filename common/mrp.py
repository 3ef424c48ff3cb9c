"""Modified Rodrigues parameters (MRPs): the one set of attitude kernels the plant, the
flight software and the ground tools use.

Conventions (docs/plant.md): sigma_BN is the attitude of B relative to N, C_BN maps
N components to B components, omega is expressed in B. sigma_dot = 1/4 B(sigma) omega.

The numba kernels (``*_into`` write into caller-owned arrays, no allocation) are what
flies; the matrix forms at the end (tilde, B_matrix, B_dot, sigma_dot) are written from
the definitions with NumPy, for tests and offline checks.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


# ---------------------------------------------------------------- direction-cosine matrices
@njit(cache=True)
def _dcm_off_diagonal(s1, s2, s3, d, f, C):
    """The off-diagonal terms d (8 s_i s_j -+ f s_k), f = 4 (1 - s.s), of C(sigma)."""
    C[0, 1] = d * (8.0 * s1 * s2 + f * s3)
    C[0, 2] = d * (8.0 * s1 * s3 - f * s2)
    C[1, 0] = d * (8.0 * s2 * s1 - f * s3)
    C[1, 2] = d * (8.0 * s2 * s3 + f * s1)
    C[2, 0] = d * (8.0 * s3 * s1 + f * s2)
    C[2, 1] = d * (8.0 * s3 * s2 - f * s1)


@njit(cache=True)
def dcm_into(s1, s2, s3, C):
    """C_BN (3x3, written into C) from sigma_BN = (s1, s2, s3):
    I + (8[s x]^2 - 4(1 - s.s)[s x]) / (1 + s.s)^2, written out (the plant's form)."""
    ss = s1 * s1 + s2 * s2 + s3 * s3
    d = 1.0 / ((1.0 + ss) * (1.0 + ss))
    C[0, 0] = 1.0 + d * (8.0 * s1 * s1 - 8.0 * ss)
    C[1, 1] = 1.0 + d * (8.0 * s2 * s2 - 8.0 * ss)
    C[2, 2] = 1.0 + d * (8.0 * s3 * s3 - 8.0 * ss)
    _dcm_off_diagonal(s1, s2, s3, d, 4.0 * (1.0 - ss), C)


@njit(cache=True)
def to_dcm(sigma: np.ndarray) -> np.ndarray:
    """C_BN from sigma_BN, a new array (the flight software's form). The diagonal is
    summed as 8 (-s_j^2 - s_k^2) where ``dcm_into`` takes 8 s_i^2 - 8 s.s: equal
    algebraically, not in the last bit. The FSW and the plant each keep the form their
    recorded runs were flown with (history arrays compared bit for bit across releases)."""
    s1, s2, s3 = sigma[0], sigma[1], sigma[2]
    ss = s1 * s1 + s2 * s2 + s3 * s3
    d = 1.0 / (1.0 + ss) ** 2
    C = np.empty((3, 3))
    C[0, 0] = 1.0 + d * (8.0 * (-s2 * s2 - s3 * s3))
    C[1, 1] = 1.0 + d * (8.0 * (-s1 * s1 - s3 * s3))
    C[2, 2] = 1.0 + d * (8.0 * (-s1 * s1 - s2 * s2))
    _dcm_off_diagonal(s1, s2, s3, d, 4.0 * (1.0 - ss), C)
    return C


@njit(cache=True)
def _quat_of_dcm(C):
    """Scalar-first unit quaternion (q0 >= 0) of a DCM by Shepperd's method."""
    tr = C[0, 0] + C[1, 1] + C[2, 2]
    b0 = (1.0 + tr) / 4.0
    b1 = (1.0 + 2.0 * C[0, 0] - tr) / 4.0
    b2 = (1.0 + 2.0 * C[1, 1] - tr) / 4.0
    b3 = (1.0 + 2.0 * C[2, 2] - tr) / 4.0
    if b0 >= b1 and b0 >= b2 and b0 >= b3:
        q0 = math.sqrt(b0)
        q1 = (C[1, 2] - C[2, 1]) / (4 * q0)
        q2 = (C[2, 0] - C[0, 2]) / (4 * q0)
        q3 = (C[0, 1] - C[1, 0]) / (4 * q0)
    elif b1 >= b2 and b1 >= b3:
        q1 = math.sqrt(b1)
        q0 = (C[1, 2] - C[2, 1]) / (4 * q1)
        q2 = (C[0, 1] + C[1, 0]) / (4 * q1)
        q3 = (C[2, 0] + C[0, 2]) / (4 * q1)
    elif b2 >= b3:
        q2 = math.sqrt(b2)
        q0 = (C[2, 0] - C[0, 2]) / (4 * q2)
        q1 = (C[0, 1] + C[1, 0]) / (4 * q2)
        q3 = (C[1, 2] + C[2, 1]) / (4 * q2)
    else:
        q3 = math.sqrt(b3)
        q0 = (C[0, 1] - C[1, 0]) / (4 * q3)
        q1 = (C[2, 0] + C[0, 2]) / (4 * q3)
        q2 = (C[1, 2] + C[2, 1]) / (4 * q3)
    if q0 < 0.0:
        q0, q1, q2, q3 = -q0, -q1, -q2, -q3
    return q0, q1, q2, q3


@njit(cache=True)
def from_dcm_into(C, out):
    """sigma (|sigma| <= 1) of a DCM, written into out, via the quaternion (Shepperd)."""
    q0, q1, q2, q3 = _quat_of_dcm(C)
    out[0] = q1 / (1.0 + q0)
    out[1] = q2 / (1.0 + q0)
    out[2] = q3 / (1.0 + q0)


def from_dcm(C: np.ndarray) -> np.ndarray:
    """sigma (|sigma| <= 1) from a direction-cosine matrix, via the quaternion (Shepperd)."""
    out = np.empty(3)
    from_dcm_into(np.ascontiguousarray(C, dtype=np.float64), out)
    return out


def dcm_to_quat(C: np.ndarray) -> np.ndarray:
    """Scalar-first unit quaternion [q0, q1, q2, q3], q0 >= 0, of a DCM (Shepperd's method)."""
    return np.array(_quat_of_dcm(np.ascontiguousarray(C, dtype=np.float64)))


def sigma_to_quat(sigma: np.ndarray) -> np.ndarray:
    """Scalar-first quaternion of an MRP."""
    s2 = float(sigma @ sigma)
    return np.concatenate(([(1.0 - s2) / (1.0 + s2)], 2.0 * sigma / (1.0 + s2)))


# ---------------------------------------------------------------- kinematics
@njit(cache=True)
def B_mul(s, x, out):
    """out = B(s) x, B = (1 - s.s) I + 2[s x] + 2 s s^T (docs/plant.md)."""
    s2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2]
    sx = s[0] * x[0] + s[1] * x[1] + s[2] * x[2]
    c0 = s[1] * x[2] - s[2] * x[1]
    c1 = s[2] * x[0] - s[0] * x[2]
    c2 = s[0] * x[1] - s[1] * x[0]
    out[0] = (1.0 - s2) * x[0] + 2.0 * c0 + 2.0 * s[0] * sx
    out[1] = (1.0 - s2) * x[1] + 2.0 * c1 + 2.0 * s[1] * sx
    out[2] = (1.0 - s2) * x[2] + 2.0 * c2 + 2.0 * s[2] * sx


@njit(cache=True)
def Bdot_mul(s, sd, x, out):
    """out = Bdot(s, sd) x, Bdot = -2 (s.sd) I + 2[sd x] + 2 (sd s^T + s sd^T) (docs/fsw/index.md)."""
    ssd = s[0] * sd[0] + s[1] * sd[1] + s[2] * sd[2]
    sx = s[0] * x[0] + s[1] * x[1] + s[2] * x[2]
    sdx = sd[0] * x[0] + sd[1] * x[1] + sd[2] * x[2]
    c0 = sd[1] * x[2] - sd[2] * x[1]
    c1 = sd[2] * x[0] - sd[0] * x[2]
    c2 = sd[0] * x[1] - sd[1] * x[0]
    out[0] = -2.0 * ssd * x[0] + 2.0 * c0 + 2.0 * (sd[0] * sx + s[0] * sdx)
    out[1] = -2.0 * ssd * x[1] + 2.0 * c1 + 2.0 * (sd[1] * sx + s[1] * sdx)
    out[2] = -2.0 * ssd * x[2] + 2.0 * c2 + 2.0 * (sd[2] * sx + s[2] * sdx)


@njit(cache=True)
def sigma_dot_into(s, omega, out):
    """out = sigma_dot = 1/4 B(s) omega."""
    B_mul(s, omega, out)
    for i in range(3):
        out[i] *= 0.25


@njit(cache=True)
def sigma_derivatives(s, omega, domega, sdot, sddot):
    """sdot = 1/4 B omega; sddot = 1/4 (Bdot omega + B domega) (docs/fsw/index.md)."""
    tmp = np.empty(3)
    sigma_dot_into(s, omega, sdot)
    Bdot_mul(s, sdot, omega, sddot)
    B_mul(s, domega, tmp)
    for i in range(3):
        sddot[i] = 0.25 * (sddot[i] + tmp[i])


@njit(cache=True)
def omega_from_sigma_dot_into(s, x, out):
    """out = 4 B(s)^T x / (1 + s.s)^2 (the inverse of sigma_dot = 1/4 B omega, as
    B^T B = (1 + s.s)^2 I), using B(s)^T = B(-s). SAMI's P_a (docs/fsw/index.md)."""
    ns = np.empty(3)
    ns[0], ns[1], ns[2] = -s[0], -s[1], -s[2]
    B_mul(ns, x, out)
    f = 4.0 / (1.0 + s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) ** 2
    for i in range(3):
        out[i] *= f


# ---------------------------------------------------------------- sets and composition
@njit(cache=True)
def shadow_switched(s1, s2, s3):
    """(s1, s2, s3), or its shadow set -s/|s|^2 (same attitude) when |s| > 1."""
    ss = s1 * s1 + s2 * s2 + s3 * s3
    if ss > 1.0:
        return -s1 / ss, -s2 / ss, -s3 / ss
    return s1, s2, s3


@njit(cache=True)
def switch_shadow_into(s):
    """s (in place) with |s| <= 1: the shadow set when |s| > 1."""
    s[0], s[1], s[2] = shadow_switched(s[0], s[1], s[2])


def switch_shadow(sigma: np.ndarray) -> np.ndarray:
    """sigma with |sigma| <= 1 (a new array), switched to the shadow set when |sigma| > 1."""
    out = np.array(sigma, dtype=np.float64)
    switch_shadow_into(out)
    return out


def shadow(sigma: np.ndarray) -> np.ndarray:
    """The shadow set -sigma/|sigma|^2 (same attitude)."""
    return -sigma / float(sigma @ sigma)


@njit(cache=True)
def compose(d1, d2, d3, s1, s2, s3):
    """The MRP of C(d) C(s): rotation s followed by rotation d (no shadow switch)."""
    ss = s1 * s1 + s2 * s2 + s3 * s3
    dd = d1 * d1 + d2 * d2 + d3 * d3
    den = 1.0 + ss * dd - 2.0 * (s1 * d1 + s2 * d2 + s3 * d3)
    c1, c2, c3 = d2 * s3 - d3 * s2, d3 * s1 - d1 * s3, d1 * s2 - d2 * s1
    return (((1.0 - ss) * d1 + (1.0 - dd) * s1 - 2.0 * c1) / den,
            ((1.0 - ss) * d2 + (1.0 - dd) * s2 - 2.0 * c2) / den,
            ((1.0 - ss) * d3 + (1.0 - dd) * s3 - 2.0 * c3) / den)


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


# ---------------------------------------------------------------- matrix forms (tests, offline)
def tilde(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix [v x] so that tilde(v) @ w == np.cross(v, w)."""
    return np.array([[0.0, -v[2], v[1]],
                     [v[2], 0.0, -v[0]],
                     [-v[1], v[0], 0.0]])


def B_matrix(sigma: np.ndarray) -> np.ndarray:
    """B(sigma) = (1 - s.s) I + 2[s x] + 2 s s^T (docs/plant.md, kinematics)."""
    s2 = float(sigma @ sigma)
    return (1.0 - s2) * np.eye(3) + 2.0 * tilde(sigma) + 2.0 * np.outer(sigma, sigma)


def B_dot(sigma: np.ndarray, sigma_dot: np.ndarray) -> np.ndarray:
    """Time derivative of B(sigma) (docs/fsw/index.md, SAMI notation)."""
    return (-2.0 * float(sigma @ sigma_dot) * np.eye(3) + 2.0 * tilde(sigma_dot)
            + 2.0 * (np.outer(sigma_dot, sigma) + np.outer(sigma, sigma_dot)))


def sigma_dot(sigma: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """MRP kinematics sigma_dot = 1/4 B(sigma) omega."""
    return 0.25 * B_matrix(sigma) @ omega
