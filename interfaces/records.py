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


# fsw or test harness -> sim: inject or clear a jet fault (spec 40-interfaces.md, MAVLink
# MAV_CMD_INJECT_FAILURE mapping). Jet numbering follows the command: 1..18, 0 = all jets.
FAULT_CLEAR = 0        # MAVLink FAILURE_TYPE_OK
FAULT_OFF = 1          # FAILURE_TYPE_OFF: failed off
FAULT_STUCK = 2        # FAILURE_TYPE_STUCK: stuck on
FAULT_DEGRADED = 4     # FAILURE_TYPE_WRONG: degraded, eta in (0, 1)
FAULT_KINDS = (FAULT_CLEAR, FAULT_OFF, FAULT_STUCK, FAULT_DEGRADED)

FAULT = np.dtype([
    ("t_apply_ns", "<i8"),         # simulated time at which to apply [ns]; < 0 = at the next step
    ("eta", "<f8"),                # thrust efficiency for FAULT_DEGRADED, in (0, 1) [-]
    ("request_id", "<u4"),         # echoed in the acknowledgement
    ("jet", "u1"),                 # 1..18, 0 = all jets
    ("kind", "u1"),                # one of FAULT_KINDS
    ("_pad", "u1", (2,)),          # keeps the record a multiple of 8 bytes
])

# fsw -> viewers, ground: one event (fsw/events.py Event), fixed width. Strings are
# UTF-8, NUL-padded; text <= 50 bytes fits one MAVLink STATUSTEXT.
EVENT = np.dtype([
    ("t_ns", "<i8"),               # event time [ns] (FSW time)
    ("severity", "u1"),            # MAVLink MAV_SEVERITY 0..7
    ("source", "S15"),             # module, e.g. b"fdir"
    ("code", "S32"),               # stable machine-readable id, e.g. b"jet_failed_off"
    ("text", "S50"),               # human-readable
    ("_pad", "u1", (6,)),          # keeps the record a multiple of 8 bytes
])
