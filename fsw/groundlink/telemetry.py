"""Telemetry messages of the ground link, each built from the FlightSoftware's state
(what each one carries: interfaces/mavlink/README.md). Pure functions of their arguments;
scheduling and sending are link.py's.

What the control cycle computes (references, torques, estimates, the jet command, the
predicted deploy point) is read from its output record ``fsw.output`` (interfaces/records.py
FSW_STATE), as every other reader takes it. Mode, health, arming and the navigation state are
read from their owners: a ground command handled earlier in the same link tick changes them,
and what follows it must show the change.
"""
from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from common import frames, mrp
from interfaces.mavlink import dialect as mav
from interfaces.records import GUID_PREDICTION
from interfaces.vocabulary import INHIBITED, N_JETS, NOMINAL, Mode

STATUSTEXT_LEN = 50
_JET_BITS = 1 << np.arange(N_JETS, dtype=np.int64)


def ascii_text(text: str, n: int) -> bytes:
    return str(text).encode("ascii", "replace")[:n]


def local_ned_dcm(r_N: np.ndarray) -> np.ndarray:
    """C_LN: rows north, east, down at r_N (spherical planet, N3 = spin axis): the axes of
    common.frames.local_axes, the same arithmetic on floats and one array (its numpy
    temporaries and compiled cross product's dispatch are dear in a link tick with cold
    caches)."""
    x, y, z = float(r_N[0]), float(r_N[1]), float(r_N[2])
    r = math.sqrt(x ** 2 + y ** 2 + z ** 2)
    ux, uy, uz = x / r, y / r, z / r
    lam = math.atan2(y, x)
    ex, ey = -math.sin(lam), math.cos(lam)             # east; its third component is 0
    return np.array(((uy * 0.0 - uz * ey, uz * ex - ux * 0.0, ux * ey - uy * ex),
                     (ex, ey, 0.0), (-ux, -uy, -uz)))


def euler321(C: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) [rad] of C = R1(roll) R2(pitch) R3(yaw)."""
    pitch = -math.asin(max(-1.0, min(1.0, float(C[0, 2]))))
    return math.atan2(C[1, 2], C[2, 2]), pitch, math.atan2(C[0, 1], C[0, 0])


def system_status(fsw) -> int:
    """MAV_STATE, first match wins: SAFE -> EMERGENCY; a jet not nominal or the allocation
    degraded -> CRITICAL; STANDBY -> STANDBY; otherwise ACTIVE."""
    mode = fsw.modes.mode
    if mode == Mode.SAFE:
        return mav.MAV_STATE_EMERGENCY
    if np.any(fsw.fdir.health_active.state != NOMINAL) or fsw.allocator.degraded:
        return mav.MAV_STATE_CRITICAL
    if mode == Mode.STANDBY:
        return mav.MAV_STATE_STANDBY
    return mav.MAV_STATE_ACTIVE


def heartbeat(fsw):
    base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mav.MAV_MODE_FLAG_SAFETY_ARMED if fsw.driver.armed else 0)
    return mav.MAVLink_heartbeat_message(mav.MAV_TYPE_GENERIC, mav.MAV_AUTOPILOT_GENERIC, base,
                                         int(fsw.modes.mode), system_status(fsw), 3)


def sys_status(fsw, loop_timing: dict[int, tuple], rejections: int, dropped: int = 0, refused_early: int = 0,
               unsigned_writes: int = 0, reads_limited: int = 0):
    """SYS_STATUS; the link's counters in the standard error fields (a stock ground station
    shows them): errors_comm every rejection, errors_count1 datagrams dropped on the full
    receive queue, errors_count2 datagrams refused before verification, errors_count3
    unsigned frames refused for their class (state-changing), errors_count4 read-only
    requests and answers over their sender's budget (each saturating)."""
    S = mav
    present = (S.MAV_SYS_STATUS_SENSOR_3D_GYRO | S.MAV_SYS_STATUS_SENSOR_3D_ACCEL
               | S.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION | S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
    enabled = present if fsw.driver.armed else present & ~S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    health = present
    if np.any(fsw.fdir.health_active.state != NOMINAL):
        health &= ~S.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    if getattr(fsw.monitor, "stale", False):
        health &= ~(S.MAV_SYS_STATUS_SENSOR_3D_GYRO | S.MAV_SYS_STATUS_SENSOR_3D_ACCEL)
    load = 0
    rg = loop_timing.get(0) or loop_timing.get(1)
    if rg is not None:
        load = int(round(min(1000.0, max(0.0, rg[3] * 1e-6 / fsw.dt_s * 1000.0))))
    return mav.MAVLink_sys_status_message(present, enabled, health, load, 0xFFFF, -1, -1, 0,
                                          min(rejections, 0xFFFF), min(dropped, 0xFFFF), min(refused_early, 0xFFFF),
                                          min(unsigned_writes, 0xFFFF), min(reads_limited, 0xFFFF))


def nav_valid(fsw) -> bool:
    """Navigation has a state to report (a frame was accepted)."""
    return fsw.k >= 0 and float(np.dot(fsw.nav.state.r_N, fsw.nav.state.r_N)) > 1.0


def attitude(fsw, ms: int, C_LN: np.ndarray, want: tuple[bool, bool, bool, bool, bool]) -> Iterator:
    """The attitude group relative to local NED (C_LN: ``local_ned_dcm`` at the vehicle):
    ATTITUDE, ATTITUDE_QUATERNION, ATTITUDE_TARGET, the NAMED_VALUE_FLOATs,
    ELLIPSLED_ENTRY_STATE (those ``want`` selects)."""
    nav, g, out = fsw.nav.state, fsw.guidance, fsw.output
    w = nav.omega_BN_B
    if want[0] or want[1]:
        C_BL = nav.C_BN @ C_LN.T
        if want[0]:
            roll, pitch, yaw = euler321(C_BL)
            yield mav.MAVLink_attitude_message(ms, roll, pitch, yaw, w[0], w[1], w[2])
        if want[1]:
            q = mrp.dcm_to_quat(C_BL)
            yield mav.MAVLink_attitude_quaternion_message(ms, q[0], q[1], q[2], q[3], w[0], w[1], w[2])
    if want[2]:
        q = mrp.dcm_to_quat(mrp.to_dcm(out["sigma_RN"]) @ C_LN.T)
        wr = g.omega_RN_R
        yield mav.MAVLink_attitude_target_message(
            ms, mav.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE, [float(x) for x in q], wr[0], wr[1], wr[2], 0.0)
    if want[3]:
        for name, value in (("bank_deg", math.degrees(nav.bank_rad)),
                            ("bref_deg", math.degrees(float(out["bank_ref_rad"]))),
                            ("berr_deg", math.degrees(float(out["bank_err_rad"]))), ("mach", nav.mach),
                            ("qbar_pa", nav.qbar_pa), ("alt_km", nav.h_m * 1e-3)):
            yield mav.MAVLink_named_value_float_message(ms, name.encode(), float(value))
        if fsw.entry is not None:          # guided: range to go and predicted miss, for stock stations
            tgt, veh, rtg = target_range(fsw)
            if rtg is not None:
                yield mav.MAVLink_named_value_float_message(ms, b"rtg_km", rtg * 1e-3)
                if out["guid_flags"] & GUID_PREDICTION:
                    miss = _angle(_unit(float(out["pred_lat_rad"]), float(out["pred_lon_rad"])),
                                  _unit(*tgt)) * fsw.scenario.planet.radius_m
                    yield mav.MAVLink_named_value_float_message(ms, b"miss_km", miss * 1e-3)
        if fsw.deploy is not None:         # the deploy command: 0 none, else its rule (records.DEPLOY_*)
            yield mav.MAVLink_named_value_float_message(ms, b"deploy", float(out["deploy"]))
    if want[4]:
        yield entry_state(fsw, ms, C_LN)


def lat_lon(fsw) -> tuple[float, float]:
    """(latitude, longitude) [rad] of the navigation position on the FSW's planet model, a
    sphere, where planetocentric and planetodetic latitude coincide; N and the planet-fixed
    frame coincide at t = 0, so longitude = atan2(y, x) - Omega t (as the plant reports it)."""
    r_N = fsw.nav.state.r_N
    r = math.sqrt(float(r_N[0] * r_N[0] + r_N[1] * r_N[1] + r_N[2] * r_N[2]))
    lat = math.asin(max(-1.0, min(1.0, float(r_N[2]) / r)))
    return lat, frames.wrap_pi(math.atan2(r_N[1], r_N[0]) - fsw.scenario.planet.omega_radps * fsw.t_s)


def entry_state(fsw, ms: int, C_LN: np.ndarray):
    nav = fsw.nav.state
    north, east, down = C_LN
    V = max(nav.V_rel_mps, 1e-9)
    gamma = math.asin(max(-1.0, min(1.0, -float(nav.vrel_N @ down) / V)))
    psi = math.atan2(float(nav.vrel_N @ east), float(nav.vrel_N @ north))
    lat, lon = lat_lon(fsw)
    return mav.MAVLink_ellipsled_entry_state_message(
        ms, nav.h_m, nav.V_rel_mps, gamma, psi, lat, lon, nav.mach, nav.qbar_pa, nav.alpha_rad,
        nav.beta_rad, nav.bank_rad, float(fsw.output["bank_ref_rad"]))


# ---------------------------------------------------------------- position group
# Standard messages a stock ground station draws its map, HUD and altitude tape from. The
# planet model is the FSW's own sphere (radius R): "altitude above the areoid" is the
# navigation altitude h = |r| - R, and with no terrain model the surface is that sphere,
# so the altitude relative to the ground (GLOBAL_POSITION_INT relative_alt, ALTITUDE
# altitude_relative) is h as well.
INT16_MAX = 0x7FFF
UINT16_MAX = 0xFFFF


def _sat_int(x: float, lo: int, hi: int) -> int:
    return lo if x <= lo else hi if x >= hi else int(round(x))


def heading_cdeg(yaw_rad: float) -> int:
    """Yaw [rad] as MAVLink's heading, centidegrees in [0, 35999]."""
    return int(round(math.degrees(yaw_rad) * 100.0)) % 36000


def position(fsw, ms: int, C_LN: np.ndarray, want: tuple[bool, bool, bool]) -> Iterator:
    """GLOBAL_POSITION_INT, VFR_HUD and ALTITUDE (those ``want`` selects) from the navigation
    state: position on the planet, planet-relative velocity in local NED, body yaw (3-2-1
    from local NED, as ATTITUDE). GLOBAL_POSITION_INT's int16 cm/s velocities saturate at
    +-327.67 m/s (entry speeds exceed it); VFR_HUD carries the speeds as floats."""
    nav = fsw.nav.state
    v_ned = C_LN @ nav.vrel_N
    C_BL = nav.C_BN @ C_LN.T
    yaw = math.atan2(C_BL[0, 1], C_BL[0, 0])           # euler321's yaw
    h = float(nav.h_m)
    if want[0]:
        lat, lon = lat_lon(fsw)
        yield mav.MAVLink_global_position_int_message(
            ms, int(round(math.degrees(lat) * 1e7)), int(round(math.degrees(lon) * 1e7)),
            _sat_int(h * 1e3, -0x80000000, 0x7FFFFFFF), _sat_int(h * 1e3, -0x80000000, 0x7FFFFFFF),
            _sat_int(v_ned[0] * 100.0, -INT16_MAX, INT16_MAX), _sat_int(v_ned[1] * 100.0, -INT16_MAX, INT16_MAX),
            _sat_int(v_ned[2] * 100.0, -INT16_MAX, INT16_MAX), heading_cdeg(yaw))
    if want[1]:
        ground = math.hypot(float(v_ned[0]), float(v_ned[1]))
        yield mav.MAVLink_vfr_hud_message(float(nav.V_rel_mps), ground, heading_cdeg(yaw) // 100, 0, h,
                                          -float(v_ned[2]))
    if want[2]:
        # no terrain model: terrain altitude unknown (< -1000 by the message's definition),
        # no clearance measurement (negative)
        yield mav.MAVLink_altitude_message(int(max(0.0, fsw.t_s) * 1e6), h, h, h, h, -1001.0, -1.0)


def planet_fixed(fsw, x_N: np.ndarray) -> np.ndarray:
    """x_N in the planet-fixed frame P (N and P coincide at t = 0; P turns at the planet's rate
    about N3, so longitude = atan2(y_P, x_P), as ``lat_lon``)."""
    th = fsw.scenario.planet.omega_radps * fsw.t_s
    c, s = math.cos(th), math.sin(th)
    return np.array([c * x_N[0] + s * x_N[1], -s * x_N[0] + c * x_N[1], x_N[2]])


def local_origin(fsw) -> tuple[np.ndarray, np.ndarray]:
    """(r0_P [m], C_L0P): the origin of LOCAL_POSITION_NED, the point of the FSW's sphere
    below the navigation position now, in P, and the north-east-down axes there (rows, in P).
    The link takes it once, at the first navigation fix."""
    r_P = planet_fixed(fsw, fsw.nav.state.r_N)
    r0_P = r_P * (fsw.scenario.planet.radius_m / float(np.linalg.norm(r_P)))
    return r0_P, local_ned_dcm(r0_P)


def local_position_ned(fsw, ms: int, origin: tuple[np.ndarray, np.ndarray]):
    """LOCAL_POSITION_NED in the planet-fixed north-east-down frame of ``origin``
    (``local_origin``): position of the vehicle relative to it, and the planet-relative
    velocity (its time derivative) in the same axes, as floats (no saturation). The origin's
    axes turn away from the vehicle's local NED by the angle flown around the planet."""
    r0_P, C_L0P = origin
    nav = fsw.nav.state
    x = C_L0P @ (planet_fixed(fsw, nav.r_N) - r0_P)
    v = C_L0P @ planet_fixed(fsw, nav.vrel_N)
    return mav.MAVLink_local_position_ned_message(ms, float(x[0]), float(x[1]), float(x[2]),
                                                  float(v[0]), float(v[1]), float(v[2]))


def gps_global_origin(fsw, origin: tuple[np.ndarray, np.ndarray]):
    """GPS_GLOBAL_ORIGIN: where ``origin`` is (latitude, longitude, altitude 0 on the sphere)."""
    r0_P = origin[0]
    lat = math.asin(max(-1.0, min(1.0, float(r0_P[2]) / float(np.linalg.norm(r0_P)))))
    lon = math.atan2(float(r0_P[1]), float(r0_P[0]))
    return mav.MAVLink_gps_global_origin_message(int(round(math.degrees(lat) * 1e7)),
                                                 int(round(math.degrees(lon) * 1e7)), 0,
                                                 int(max(0.0, fsw.t_s) * 1e6))


# ---------------------------------------------------------------- modes (standard modes protocol)
def current_mode(fsw):
    """CURRENT_MODE: the FSW's Mode as custom_mode; no MAVLink standard mode fits an entry
    vehicle's modes (NON_STANDARD); the intended mode is the one flown (no mode is refused
    silently: a refused mode command is answered DENIED)."""
    m = int(fsw.modes.mode)
    return mav.MAVLink_current_mode_message(mav.MAV_STANDARD_MODE_NON_STANDARD, m, m)


def available_modes(index: int = 0) -> list:
    """AVAILABLE_MODES: every Mode (``index`` 0) or the one of index 1..n, by name. Not
    selectable by a stock ground station: modes are set with ELLIPSLED_CMD_SET_MODE (signed)."""
    modes = list(Mode)
    pick = modes if index == 0 else modes[index - 1:index]
    return [mav.MAVLink_available_modes_message(len(modes), modes.index(m) + 1, mav.MAV_STANDARD_MODE_NON_STANDARD,
                                                int(m), mav.MAV_MODE_PROPERTY_NOT_USER_SELECTABLE,
                                                m.name.encode("ascii"), 0) for m in pick]


# ---------------------------------------------------------------- guidance
_RULES = {"corridor": mav.ELLIPSLED_REVERSAL_RULE_CORRIDOR, "final": mav.ELLIPSLED_REVERSAL_RULE_FINAL}


def _unit(lat: float, lon: float) -> tuple[float, float, float]:
    cl = math.cos(lat)
    return cl * math.cos(lon), cl * math.sin(lon), math.sin(lat)


def _cross(a, b) -> tuple[float, float, float]:
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def _dot(a, b) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _angle(a, b) -> float:
    """Great-circle angle between unit vectors (atan2 form: exact near 0)."""
    c = _cross(a, b)
    return math.atan2(math.sqrt(_dot(c, c)), _dot(a, b))


def deploy_errors(vehicle: tuple[float, float], target: tuple[float, float], point: tuple[float, float],
                  radius_m: float) -> tuple[float, float, float]:
    """(miss, downrange, crossrange) [m] of ``point`` (latitude, longitude [rad]) against
    ``target``, split along the great circle from ``vehicle`` to the target: downrange
    positive beyond the target, crossrange positive to the right of that path (the signs of
    summary.json's deploy figures). A vehicle on the target (no path) gives crossrange 0 and
    downrange = miss."""
    u, t, p = _unit(*vehicle), _unit(*target), _unit(*point)
    miss = _angle(p, t) * radius_m
    n = _cross(u, t)                       # normal of the path's plane (left of the path)
    nn = math.sqrt(_dot(n, n))
    if nn < 1e-12:
        return miss, miss, 0.0
    n = (n[0] / nn, n[1] / nn, n[2] / nn)
    along = _cross(n, u)                   # direction of travel at the vehicle
    off = max(-1.0, min(1.0, _dot(p, n)))
    s_p = math.atan2(_dot(p, along), _dot(p, u))       # p's foot on the path, from the vehicle
    s_t = _angle(u, t)
    return miss, (s_p - s_t) * radius_m, -math.asin(off) * radius_m


def _finite(*xs: float) -> bool:
    return all(math.isfinite(x) for x in xs)


def target_range(fsw) -> tuple:
    """(target (lat, lon), vehicle (lat, lon) [rad], great-circle range to go [m]) from the
    navigation position now; range None when there is no target or no finite position."""
    scn = fsw.scenario
    tgt = (scn.target_lat_rad, scn.target_lon_rad) if scn.target_lat_rad is not None else None
    veh = lat_lon(fsw) if nav_valid(fsw) else None
    if tgt is None or veh is None or not _finite(*tgt, *veh):
        return tgt, veh, None
    return tgt, veh, _angle(_unit(*veh), _unit(*tgt)) * scn.planet.radius_m


def guidance_status(fsw, ms: int):
    """ELLIPSLED_GUIDANCE_STATUS: mode, target and range to go (navigation now), the
    predictor-corrector's last answer (mode npc), reversals and the controllability LP's last
    answer. A group of fields goes out only when all its values are finite (its flag set);
    otherwise it is 0 with its flag clear: the ground never receives NaN or infinity."""
    scn, e, lp = fsw.scenario, fsw.entry, fsw.controllability
    R = scn.planet.radius_m
    flags = 0
    tgt, veh, rtg = target_range(fsw)
    tlat = tlon = 0.0
    if rtg is not None:
        flags |= mav.ELLIPSLED_GUIDANCE_FLAGS_TARGET
        tlat, tlon = tgt
    else:
        rtg = 0.0
    plat = plon = palt = miss = down = cross = tgo = b0 = bcmd = krho = 0.0
    sign = cycles = overruns = reversals = rule = 0
    t_rev = 0.0
    mode = mav.ELLIPSLED_GUIDANCE_MODE_PROFILE
    if e is not None:
        mode = mav.ELLIPSLED_GUIDANCE_MODE_NPC
        lat_f, lon_f = float(e.pred_impact[0]), float(e.pred_impact[1])
        if e.cycles > 0 and flags & mav.ELLIPSLED_GUIDANCE_FLAGS_TARGET and \
                _finite(lat_f, lon_f, e.pred_h_m, e.t_go_s, e.bank0_cmd):
            miss, down, cross = deploy_errors(veh, tgt, (lat_f, lon_f), R)
            if _finite(miss, down, cross):
                flags |= mav.ELLIPSLED_GUIDANCE_FLAGS_PREDICTION
                plat, plon, palt, tgo, b0 = lat_f, lon_f, e.pred_h_m, e.t_go_s, e.bank0_cmd
                if not abs(e.miss_m) <= e.params["npc.tol_m"]:              # solve_bank's criterion
                    flags |= mav.ELLIPSLED_GUIDANCE_FLAGS_NO_ROOT
                if e.t_go_s < e.params["npc.tgo_freeze_s"]:                # EntryGuidance holds phi_0
                    flags |= mav.ELLIPSLED_GUIDANCE_FLAGS_FROZEN
            else:
                miss = down = cross = 0.0
        lat_logic = e.lateral
        if lat_logic.final:
            flags |= mav.ELLIPSLED_GUIDANCE_FLAGS_FINAL_REVERSAL
        bcmd = e.bank_cmd if math.isfinite(e.bank_cmd) else 0.0
        krho = e.estimator.k_rho if math.isfinite(e.estimator.k_rho) else 0.0
        sign = 1 if lat_logic.sign > 0 else -1
        cycles, overruns, reversals = e.cycles, e.overruns, len(lat_logic.reversals)
        if reversals:
            t_rev = lat_logic.reversals[-1]
            rule = _RULES.get(lat_logic.rules[-1], mav.ELLIPSLED_REVERSAL_RULE_NONE)
    a_pos = a_neg = bias = trim = 0.0
    if lp is not None and _finite(lp.authority_pos_radps2, lp.authority_neg_radps2, lp.bias_Nm):
        flags |= mav.ELLIPSLED_GUIDANCE_FLAGS_LP
        a_pos, a_neg, bias = lp.authority_pos_radps2, lp.authority_neg_radps2, lp.bias_Nm
        if lp.controllable:
            flags |= mav.ELLIPSLED_GUIDANCE_FLAGS_CONTROLLABLE
        if math.isfinite(lp.trim_needed_deg):
            flags |= mav.ELLIPSLED_GUIDANCE_FLAGS_TRIM
            trim = math.radians(lp.trim_needed_deg)
    return mav.MAVLink_ellipsled_guidance_status_message(
        ms, mode, flags, tlat, tlon, rtg, plat, plon, palt, miss, down, cross, tgo, b0, bcmd, sign, krho,
        cycles & 0xFFFFFFFF, min(overruns, UINT16_MAX), min(reversals, UINT16_MAX),
        t_rev if math.isfinite(t_rev) else 0.0, rule, a_pos, a_neg, bias, trim)


def system_time(fsw, unix_s: float):
    """SYSTEM_TIME: the FSW host's Unix time and the FSW's mission time (the time_boot_ms
    of every other message)."""
    return mav.MAVLink_system_time_message(int(unix_s * 1e6), int(max(0.0, fsw.t_s) * 1000.0) & 0xFFFFFFFF)


def actuator_output_status(fsw):
    act = [0.0] * 32
    act[:N_JETS] = [float(x) for x in fsw.output["jets_cmd"]]
    return mav.MAVLink_actuator_output_status_message(int(fsw.t_s * 1e6), (1 << N_JETS) - 1, act)


def jet_status(fsw, ms: int, sensors):
    """Health per jet (an inhibited nominal jet shows INHIBITED), commanded and firing bits
    (firing: chamber pressure above fdir.on_threshold), eta, pulses, on-time."""
    h = fsw.fdir.health_active
    health = [int(s) for s in h.state]
    for i in range(N_JETS):
        if h.inhibited[i] and health[i] == NOMINAL:
            health[i] = INHIBITED
    cmd = int(np.dot(fsw.output["jets_cmd"].astype(np.int64) != 0, _JET_BITS))
    firing = 0
    if sensors is not None:
        on = np.asarray(sensors["chamber"]) > fsw.params["fdir.on_threshold"]
        firing = int(np.dot(on.astype(np.int64), _JET_BITS))
    return mav.MAVLink_ellipsled_jet_status_message(
        ms, cmd, firing, health, [float(x) for x in h.effective_eta()],
        [int(min(x, 0xFFFFFFFF)) for x in fsw.driver.pulses], [float(x) for x in fsw.driver.on_time_s])


def percentile99(a: np.ndarray) -> float:
    """``np.percentile(a, 99)`` (linear interpolation) of a non-empty array, found by
    partitioning around the two ranks it falls between instead of numpy's general quantile
    machinery, whose Python layers a link tick with cold caches pays dearly (docs/changelog.md,
    Benchmarks)."""
    k = 0.99 * (a.size - 1)
    lo = int(k)
    hi = min(lo + 1, a.size - 1)
    part = np.partition(a, (lo, hi))
    x0, x1, t = float(part[lo]), float(part[hi]), k - lo
    return x1 - (x1 - x0) * (1.0 - t) if t >= 0.5 else x0 + (x1 - x0) * t


def control_status(fsw, ms: int, alloc_ns: np.ndarray, alloc_degraded: int):
    """ELLIPSLED_CONTROL_STATUS; ``alloc_ns``: the allocator's recent solve times [ns]."""
    p99 = percentile99(alloc_ns) * 1e-3 if alloc_ns.size else 0.0
    out = fsw.output
    return mav.MAVLink_ellipsled_control_status_message(
        ms, [float(x) for x in out["u_cal_B"]], [float(x) for x in out["tau_alloc_B"]],
        [float(x) for x in out["theta_hat"]], int(fsw.cycles) & 0xFFFFFFFF, p99,
        alloc_degraded & 0xFFFFFFFF)


def loop_timing(ms: int, timing: dict[int, tuple]) -> Iterator:
    for rg, v in sorted(timing.items()):
        yield mav.MAVLink_ellipsled_loop_timing_message(ms, *v[:6], v[6] & 0xFFFFFFFF, rg & 0xFF)


def statustext(severity: int, text: str):
    return mav.MAVLink_statustext_message(int(severity), ascii_text(text, STATUSTEXT_LEN))
