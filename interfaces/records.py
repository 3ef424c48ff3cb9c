"""Payload records that cross a process boundary: the one definition of each layout.

Each record is a fixed-layout little-endian NumPy structured dtype. In-process code (the
batch runner) passes the same records without encoding; the SIL encodes them with a
header (schema id, version, sequence, timestamp) in interfaces/codec.py.
Jets are numbered 1..18 in text and 0..17 in arrays.
"""
from __future__ import annotations

import numpy as np

N_JETS = 18

# sim -> fsw, once per control period: the sensor frame for step k (time t_k).
SENSORS = np.dtype([
    ("k", "<i8"),                  # step index
    ("t_ns", "<i8"),               # simulated time of the sample [ns]
    ("omega_BN_B", "<f8", (3,)),   # rate gyro [rad/s], body axes
    ("sigma_BN", "<f8", (3,)),     # attitude MRP, |sigma| <= 1
    ("r_N", "<f8", (3,)),          # position, Mars-centred inertial [m]
    ("v_N", "<f8", (3,)),          # inertial velocity [m/s]
    ("accel_B", "<f8", (3,)),      # sensed (non-gravitational) acceleration, body [m/s^2]
    ("chamber", "<f8", (N_JETS,)), # normalised chamber pressure per jet [-]
])

# fsw -> sim: the jet command answering sensor frame k, held for [t_k, t_k+1).
JETS = np.dtype([
    ("k", "<i8"),                  # step index of the sensor frame this answers
    ("t_release_ns", "<i8"),       # FSW cycle release (monotonic clock of the FSW) [ns]
    ("t_publish_ns", "<i8"),       # FSW publication time [ns]
    ("u", "u1", (N_JETS,)),        # 1 = open valve, 0 = closed
])


def new(dtype: np.dtype) -> np.ndarray:
    """A zeroed 0-d record; fields are views (``rec['omega_BN_B'][:] = ...``)."""
    return np.zeros((), dtype=dtype)
