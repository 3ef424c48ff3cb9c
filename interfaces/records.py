"""Payload records that cross a process boundary: the one definition of each layout.

Each record is a fixed-layout little-endian NumPy structured dtype. In-process code (the
batch runner) passes the same records without encoding; the SIL encodes them with a
header (schema id, version, sequence, timestamp) in interfaces/codec.py.
Jets are numbered 1..N_JETS in text and 0..N_JETS-1 in arrays.
"""
from __future__ import annotations

import numpy as np

from .vocabulary import FAULT_KINDS, N_JETS, refuse_state_word

# sim -> fsw, once per control period: the sensor frame for step k (time t_k).
SENSORS = np.dtype([
    ("k", "<i8"),                  # step index
    ("t_ns", "<i8"),               # simulated time of the sample [ns]
    ("u_k", "<i8"),                # step index of the jet command held over the interval that
                                   # ended at this sample (JETS.k); -1: none (jets held off)
    ("omega_BN_B", "<f8", (3,)),   # rate gyro [rad/s], body axes
    ("sigma_BN", "<f8", (3,)),     # attitude MRP, |sigma| <= 1
    ("r_N", "<f8", (3,)),          # position, Mars-centred inertial [m]
    ("v_N", "<f8", (3,)),          # inertial velocity [m/s]
    ("accel_B", "<f8", (3,)),      # sensed (non-gravitational) acceleration, body [m/s^2]
    ("chamber", "<f8", (N_JETS,)), # normalised chamber pressure per jet [-]
])

# fsw -> sim: the jet command answering sensor frame k, held for [t_k, t_k+1), and the
# parachute deploy command (the FSW's deploy trigger; the plant deploys inside its box).
JETS = np.dtype([
    ("k", "<i8"),                  # step index of the sensor frame this answers
    ("t_release_ns", "<i8"),       # FSW cycle release (monotonic clock of the FSW) [ns]
    ("t_publish_ns", "<i8"),       # FSW publication time [ns]
    ("u", "u1", (N_JETS,)),        # 1 = open valve, 0 = closed
    ("deploy", "u1"),              # 1 = deploy the parachute (latched by the FSW), 0 = not yet
    ("_pad", "u1", (5,)),          # keeps the record a multiple of 8 bytes
])


def new(dtype: np.dtype) -> np.ndarray:
    """A zeroed 0-d record; fields are views (``rec['omega_BN_B'][:] = ...``)."""
    return np.zeros((), dtype=dtype)


# fsw or test harness -> sim: inject or remove a jet fault (docs/interfaces/index.md, MAVLink
# MAV_CMD_INJECT_FAILURE mapping; kinds and codes: interfaces/vocabulary.py FAULT_KINDS).
# Jet numbering follows the command: 1..N_JETS, 0 = all jets.
FAULT_NAMES = {code: kind for kind, code in FAULT_KINDS.items()}     # wire code -> kind


def check_fault_request(jet, kind: str, eta) -> None:
    """What the plant can apply: jet 0..N_JETS (0 = all), kind nominal|failed_off|stuck_on|degraded, eta
    in (0, 1) for degraded and 1 otherwise. ValueError with the reason if not. The plant
    and the FSW's ground link both judge requests with this one rule."""
    import math
    if isinstance(jet, bool) or not isinstance(jet, (int, np.integer)) or not 0 <= jet <= N_JETS:
        raise ValueError(f"jet must be an integer 0..{N_JETS} (0 = all), got {jet!r}")
    if kind not in FAULT_KINDS:
        raise ValueError(f"fault kind {refuse_state_word(kind, FAULT_KINDS)}")
    if isinstance(eta, bool) or not isinstance(eta, (int, float, np.floating, np.integer)) or not math.isfinite(eta):
        raise ValueError(f"eta must be a finite number, got {eta!r}")
    if kind == "degraded":
        if not 0.0 < eta < 1.0:
            raise ValueError(f"degraded needs 0 < eta < 1, got {eta}")
    elif eta != 1.0:
        raise ValueError(f"eta applies to kind 'degraded' only, got eta={eta} for {kind!r}")

FAULT = np.dtype([
    ("t_apply_ns", "<i8"),         # simulated time at which to apply [ns]; < 0 = at the next step
    ("eta", "<f8"),                # thrust efficiency for kind "degraded", in (0, 1) [-]
    ("request_id", "<u4"),         # echoed in the acknowledgement
    ("jet", "u1"),                 # 1..N_JETS, 0 = all jets
    ("kind", "u1"),                # a FAULT_KINDS code
    ("_pad", "u1", (2,)),          # keeps the record a multiple of 8 bytes
])

# sim -> fsw, oracle identification only (a test mode: the paper's perfect identification):
# one fault the plant applied (sim/plant.py fault_log), published before the sensor frame
# of the step it acts from. kind: FAULT_KINDS; jet 1..18.
FAULT_APPLIED = np.dtype([
    ("k", "<i8"),                  # step from which the fault acts
    ("t_ns", "<i8"),               # simulated time at which the plant applied it [ns]
    ("eta", "<f8"),                # thrust factor of a degraded jet, 1 otherwise [-]
    ("jet", "u1"),                 # 1..18
    ("kind", "u1"),                # one of FAULT_KINDS
    ("_pad", "u1", (6,)),          # keeps the record a multiple of 8 bytes
])

# fsw -> viewers, ground: one event (common/events.py Event), fixed width. Strings are
# UTF-8, NUL-padded; text <= 50 bytes fits one MAVLink STATUSTEXT.
EVENT = np.dtype([
    ("t_ns", "<i8"),               # event time [ns] (FSW time)
    ("severity", "u1"),            # MAVLink MAV_SEVERITY 0..7
    ("source", "S15"),             # module, e.g. b"fdir"
    ("code", "S32"),               # stable machine-readable id, e.g. b"jet_failed_off"
    ("text", "S50"),               # human-readable
    ("_pad", "u1", (6,)),          # keeps the record a multiple of 8 bytes
])

# sim -> viewers: the full truth at step k (sim/plant.py Plant.fill_truth; docs/interfaces/index.md).
# fault_state per jet: a jet health code (interfaces/vocabulary.py).
TRUTH = np.dtype([
    ("k", "<i8"),                      # step index
    ("t_ns", "<i8"),                   # simulated time [ns]
    ("t_s", "<f8"),                    # simulated time [s]
    ("h_m", "<f8"),                    # altitude above the spherical planet [m]
    ("V_rel_mps", "<f8"),              # planet-relative speed [m/s]
    ("gamma_rad", "<f8"),              # flight-path angle [rad]
    ("psi_rad", "<f8"),                # heading, clockwise from north [rad]
    ("lat_rad", "<f8"),                # latitude [rad]
    ("lon_rad", "<f8"),                # longitude, planet-fixed [rad]
    ("mach", "<f8"),                   # Mach number [-]
    ("qbar_pa", "<f8"),                # dynamic pressure [Pa]
    ("rho_kgpm3", "<f8"),              # truth density [kg/m^3]
    ("alpha_rad", "<f8"),              # angle of attack [rad]
    ("beta_rad", "<f8"),               # sideslip [rad]
    ("bank_rad", "<f8"),               # bank angle [rad]
    ("decel_g", "<f8"),                # aerodynamic deceleration [g0]
    ("propellant_kg", "<f8"),          # propellant used so far [kg]
    ("sigma_BN", "<f8", (3,)),         # attitude MRP, |sigma| <= 1
    ("omega_BN_B", "<f8", (3,)),       # body rate [rad/s]
    ("r_N", "<f8", (3,)),              # position, inertial [m]
    ("v_N", "<f8", (3,)),              # velocity, inertial [m/s]
    ("tau_jets_B", "<f8", (3,)),       # jet torque applied over the last period [N m]
    ("tau_ext_B", "<f8", (3,)),        # ideal external torque over the last period [N m]
    ("tau_aero_B", "<f8", (3,)),       # aerodynamic moment at t_k [N m]
    ("jet_thrust_frac", "<f8", (N_JETS,)),  # thrust produced over the last period / full thrust [-]
    ("fault_eta", "<f8", (N_JETS,)),   # thrust factor of degraded jets (1 otherwise) [-]
    ("fault_state", "i1", (N_JETS,)),  # per-jet fault state (see above)
    ("_pad", "u1", (6,)),              # keeps the record a multiple of 8 bytes
])

# fsw -> viewers, ground, run history, once per control cycle: the flight software's outputs,
# the one list of them. FlightSoftware.output is this record, filled at the end of every control
# cycle (fsw/output.py); the fields of FSW_STATE_SHELL are the loop timing the rate-group
# driver stamps (fsw/topology.py). Readers take their field lists from this dtype: the run
# history keeps every field but FSW_STATE_LIVE (ellipsled/sil/history.py), the SIL publishes
# the record as it is (fsw/state), the Rerun bridge buffers every field (gse/viz/logger.py).
FSW_STATE = np.dtype([
    ("k", "<i8"),                          # step index of the sensor frame answered
    ("t_ns", "<i8"),                       # simulated time of frame k [ns]
    ("t_release_ns", "<i8"),               # FSW cycle release (FSW monotonic clock) [ns]
    ("bank_ref_rad", "<f8"),               # guidance bank reference [rad]
    ("bankdot_ref_radps", "<f8"),          # its rate [rad/s]
    ("bank_err_rad", "<f8"),               # FSW bank (navigation) - reference, wrapped [rad]
    ("sigma_RN", "<f8", (3,)),             # reference attitude MRP
    ("u_cal_B", "<f8", (3,)),              # commanded (control) torque [N m]
    ("tau_alloc_B", "<f8", (3,)),          # torque of the allocated jet set [N m]
    ("theta_hat", "<f8", (9,)),            # adaptive parameter estimates [kg m^2 x6, d x3]
    ("eta_hat", "<f8", (N_JETS,)),         # estimated jet thrust factors [-]
    ("compute_us", "<f8"),                 # compute time of the last finished cycle [us] (published
                                           # during a cycle: the one before; in the run history: its own)
    ("alloc_us", "<f8"),                   # allocator time [us]
    ("jitter_us", "<f8"),                  # release time - scheduled release time [us]
    ("slips", "<i8"),                      # cycle slips so far
    # entry guidance (mode npc; 0 where guid_flags says not available: never NaN on the wire)
    ("guid_cycles", "<i8"),                # predictor-corrector answers applied so far
    ("target_lat_rad", "<f8"),             # deploy target, planet-fixed (GUID_TARGET)
    ("target_lon_rad", "<f8"),
    ("pred_lat_rad", "<f8"),               # predicted deploy point of the last answer (GUID_PREDICTION)
    ("pred_lon_rad", "<f8"),
    ("bank_cmd_rad", "<f8"),               # bank magnitude commanded (mode npc)
    ("jets_cmd", "u1", (N_JETS,)),         # 1 = open
    ("health", "i1", (N_JETS,)),           # jet health codes (interfaces/vocabulary.py)
    ("mode", "i1"),                        # Mode (interfaces/vocabulary.py)
    ("alloc_degraded", "u1"),              # 1 = allocation infeasible, degraded solution
    ("alloc_short", "u1"),                 # 1 = the allocated torque falls short on the bank axis
    ("guid_flags", "u1"),                  # GUID_TARGET | GUID_PREDICTION | GUID_NPC
    ("deploy", "u1"),                      # a DEPLOY_* code: the deploy command and its rule
])
# deploy codes of FSW_STATE (JETS.deploy is 1 for any of the commanded ones)
DEPLOY_NONE, DEPLOY_RANGE, DEPLOY_VELOCITY, DEPLOY_EDGE, DEPLOY_FLOOR = 0, 1, 2, 3, 4
# guid_flags bits of FSW_STATE
GUID_TARGET, GUID_PREDICTION, GUID_NPC = 1, 2, 4
# FSW_STATE fields the rate-group driver stamps (its loop timing); FlightSoftware fills the rest.
FSW_STATE_SHELL = ("t_release_ns", "compute_us", "jitter_us", "slips")
# FSW_STATE fields for live viewers only, not kept in the run history: wall-clock loop timing the
# SIL's FSW process records raw itself (fsw_timing.npz, fsw.json).
FSW_STATE_LIVE = ("t_release_ns", "jitter_us", "slips")


def field_shapes(dtype: np.dtype) -> dict[str, tuple[int, ...]]:
    """name -> trailing shape of every field of a record, padding left out."""
    return {n: dtype[n].shape for n in dtype.names if not n.startswith("_")}
