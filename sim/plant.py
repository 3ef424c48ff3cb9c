"""The plant: 6-DOF entry vehicle over a rotating Mars, 18 on/off jets with faults, and
the sensors it publishes to the FSW (docs/plant.md).

State x (12,) = [r_N (3) m, v_N (3) m/s, sigma_BN (3), omega_BN_B (3) rad/s], integrated
by the dynamics kernels of sim/dynamics.py; here the jets, their faults, the sensors and
the truth record, stepped together in numba kernels (flat float64 arrays).

Time is the integer step index k: t = k * dt_control, t_ns = k * dt_control_ns.
Jet commands are held over [t_k, t_k+1) (zero-order hold); scheduled faults apply at the
first step boundary with t >= t_s; the sensor frame for k+1 is sampled after the step.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from common import mrp
from common.frames import R1, R2, v_rel_N, wind_dcm
from common.model import Scenario
from interfaces import records
from interfaces.vocabulary import DEGRADED, FAILED_OFF, FAULT_HEALTH, N_JETS, NOMINAL, STUCK_ON
from sim.dynamics import (A_ACC_B, A_ALPHA, A_BANK, A_BETA, A_F_AERO_N, A_H, A_MACH, A_OMEGA_W_N, A_QBAR,
                          A_RHO, A_TAU_AERO_B, A_V, N_AUX, P_I, deriv, initial_translation, params_vector,
                          rk4, state_derivative)

STEP_OK, STEP_BAD_U, STEP_NON_FINITE = 0, 1, 2


@njit(cache=True)
def _step_kernel(x, u, gain, bias, T, Fj, has_force, tau_ext, p, n_sub, dt, thrust_N,
                 frac, tau_jets, F_B, tau_tot, ws, C, aux, book, dt_control):
    """One control period: produced thrust fractions from the (held) command and the
    fault state, jet torque T frac (+ force), RK4 over the period. Returns a STEP_* code."""
    for j in range(frac.shape[0]):
        if u[j] > 1:
            return STEP_BAD_U
    impulse = 0.0
    for j in range(frac.shape[0]):
        frac[j] = gain[j] * u[j] + bias[j]
        impulse += frac[j] * thrust_N[j]
    book[0] += impulse * dt_control
    for i in range(3):
        s = 0.0
        f = 0.0
        for j in range(frac.shape[0]):
            s += T[i, j] * frac[j]
            if has_force:
                f += Fj[i, j] * frac[j]
        tau_jets[i] = s
        F_B[i] = f
        tau_tot[i] = s + tau_ext[i]
    rk4(x, p, tau_tot, F_B, n_sub, dt, ws, C, aux)
    for j in range(12):
        if not math.isfinite(x[j]):
            return STEP_NON_FINITE
    return STEP_OK


@njit(cache=True)
def _sense(x, aux, frac, sig, gyro_bias, blocks_g, blocks_a, blocks_n, blocks_c, i, nav_noise,
           out_w, out_s, out_r, out_v, out_a, out_c):
    """Sample the sensor frame (docs/plant.md, sensors) from the state and unit-normal
    noise rows i. sig = [gyro, attitude, pos, vel, chamber] noise 1-sigma."""
    for j in range(3):
        out_w[j] = x[9 + j] + gyro_bias[j] + sig[0] * blocks_g[i, j]
    # attitude: small rotation d (MRP ~ theta/4) composed after sigma_BN: C_meas = C(d) C_BN
    d1, d2, d3 = 0.25 * sig[1] * blocks_a[i, 0], 0.25 * sig[1] * blocks_a[i, 1], 0.25 * sig[1] * blocks_a[i, 2]
    m1, m2, m3 = mrp.compose(d1, d2, d3, x[6], x[7], x[8])
    out_s[0], out_s[1], out_s[2] = mrp.shadow_switched(m1, m2, m3)
    for j in range(3):
        if nav_noise:
            out_r[j] = x[j] + sig[2] * blocks_n[i, j]
            out_v[j] = x[3 + j] + sig[3] * blocks_n[i, 3 + j]
        else:
            out_r[j] = x[j]
            out_v[j] = x[3 + j]
        out_a[j] = aux[A_ACC_B + j]
    for j in range(frac.shape[0]):
        out_c[j] = frac[j] + sig[4] * blocks_c[i, j]


# The SENSORS record as the kernels see it: [k, t_ns] int64, then the five 3-vectors
# (omega, sigma, r, v, accel) and the chamber pressures as one run of float64.
_S_F0 = records.SENSORS.fields["omega_BN_B"][1]
_S_NF = 15 + N_JETS
assert (records.SENSORS.fields["k"][1] == 0 and records.SENSORS.fields["t_ns"][1] == 8
        and all(records.SENSORS.fields[f][1] == _S_F0 + 24 * i
                for i, f in enumerate(("omega_BN_B", "sigma_BN", "r_N", "v_N", "accel_B")))
        and records.SENSORS.fields["chamber"][1] == _S_F0 + 120
        and records.SENSORS.itemsize == _S_F0 + 8 * _S_NF), "SENSORS layout changed: update sim/plant.py"


@njit(cache=True)
def _step_and_sense(x, u, gain, bias, T, Fj, has_force, tau_ext, p, n_sub, dt, thrust_N, frac, tau_jets, F_B,
                    tau_tot, ws, C, aux, book, dt_control, sig, gyro_bias, blocks_g, blocks_a, blocks_n, blocks_c,
                    i, nav_noise, sf, si, k_next, dt_ns):
    """_step_kernel, then (unless u was refused) _sense into the SENSORS floats sf with
    [k, t_ns] = [k_next, k_next dt_ns] into si: one call per control period."""
    st = _step_kernel(x, u, gain, bias, T, Fj, has_force, tau_ext, p, n_sub, dt, thrust_N, frac, tau_jets, F_B,
                      tau_tot, ws, C, aux, book, dt_control)
    if st == STEP_BAD_U:
        return st
    _sense(x, aux, frac, sig, gyro_bias, blocks_g, blocks_a, blocks_n, blocks_c, i, nav_noise,
           sf[0:3], sf[3:6], sf[6:9], sf[9:12], sf[12:15], sf[15:15 + frac.shape[0]])
    si[0] = k_next
    si[1] = k_next * dt_ns
    return st


# ---- the truth vector: the float part of interfaces.records.TRUTH, in its order ----
TRUTH_SCALARS = ("t_s", "h_m", "V_rel_mps", "gamma_rad", "psi_rad", "lat_rad", "lon_rad", "mach", "qbar_pa",
                 "rho_kgpm3", "alpha_rad", "beta_rad", "bank_rad", "decel_g", "propellant_kg")
TRUTH_VECTORS = (("sigma_BN", 3), ("omega_BN_B", 3), ("r_N", 3), ("v_N", 3), ("tau_jets_B", 3), ("tau_ext_B", 3),
                 ("tau_aero_B", 3), ("jet_thrust_frac", N_JETS), ("fault_eta", N_JETS))
T_SIGMA, T_OMEGA, T_R, T_V, T_TAU_JETS, T_TAU_EXT, T_TAU_AERO = 15, 18, 21, 24, 27, 30, 33
T_FRAC, T_ETA = 36, 36 + N_JETS
N_TRUTH_F = 36 + 2 * N_JETS


@njit(cache=True)
def _truth_kernel(x, aux, book, tau_jets, tau_ext, frac, fault_eta, fault_state, k, dt, dt_ns, om, mass, g0,
                  isp, out_f, out_i, out_s):
    """The truth at step k (docs/interfaces/index.md, sim/truth): floats into out_f (TRUTH_SCALARS
    then TRUTH_VECTORS), [k, t_ns] into out_i, the fault states into out_s. Scalar arithmetic,
    term for term (a NumPy evaluation may differ in the last bit of gamma and psi, where it
    sums the dot products in another order)."""
    rx, ry, rz = x[0], x[1], x[2]
    ux, uy, uz = x[3] + om * ry, x[4] - om * rx, x[5]          # v - Omega x r
    V = math.sqrt(ux * ux + uy * uy + uz * uz)
    rn = math.sqrt(rx * rx + ry * ry + rz * rz)
    upx, upy, upz = rx / rn, ry / rn, rz / rn                 # local axes (common/frames.local_axes)
    lam = math.atan2(ry, rx)
    ex, ey, ez = -math.sin(lam), math.cos(lam), 0.0
    nx, ny, nz = upy * ez - upz * ey, upz * ex - upx * ez, upx * ey - upy * ex
    t_s = k * dt
    c = (ux * upx + uy * upy + uz * upz) / V
    c = c if c < 1.0 else 1.0                                # Python max(-1, min(1, c)), NaN -> 1
    c = c if c > -1.0 else -1.0
    lon = lam - om * t_s
    fx, fy, fz = aux[A_F_AERO_N], aux[A_F_AERO_N + 1], aux[A_F_AERO_N + 2]
    out_f[0] = t_s
    out_f[1] = aux[A_H]
    out_f[2] = V
    out_f[3] = math.asin(c)
    out_f[4] = math.atan2(ux * ex + uy * ey + uz * ez, ux * nx + uy * ny + uz * nz)
    out_f[5] = math.asin(rz / rn)
    out_f[6] = lon - 2.0 * math.pi * math.floor((lon + math.pi) / (2.0 * math.pi))
    out_f[7] = aux[A_MACH]
    out_f[8] = aux[A_QBAR]
    out_f[9] = aux[A_RHO]
    out_f[10] = aux[A_ALPHA]
    out_f[11] = aux[A_BETA]
    out_f[12] = aux[A_BANK]
    out_f[13] = math.sqrt(fx * fx + fy * fy + fz * fz) / mass / g0
    out_f[14] = book[0] / (isp * g0)
    for j in range(3):
        out_f[T_SIGMA + j] = x[6 + j]
        out_f[T_OMEGA + j] = x[9 + j]
        out_f[T_R + j] = x[j]
        out_f[T_V + j] = x[3 + j]
        out_f[T_TAU_JETS + j] = tau_jets[j]
        out_f[T_TAU_EXT + j] = tau_ext[j]
        out_f[T_TAU_AERO + j] = aux[A_TAU_AERO_B + j]
    for j in range(frac.shape[0]):
        out_f[T_FRAC + j] = frac[j]
        out_f[T_ETA + j] = fault_eta[j]
        out_s[j] = fault_state[j]
    out_i[0] = k
    out_i[1] = k * dt_ns


def _truth_layout_ok() -> bool:
    """True when interfaces.records.TRUTH is [k, t_ns] int64, then the truth vector as
    contiguous float64, then fault_state int8: fill_truth then writes records in place."""
    f = records.TRUTH.fields
    try:
        off = 16
        ok = f["k"][0] == np.dtype("<i8") and f["k"][1] == 0 and f["t_ns"][0] == np.dtype("<i8") \
            and f["t_ns"][1] == 8
        for name in TRUTH_SCALARS:
            ok = ok and f[name][0] == np.dtype("<f8") and f[name][1] == off
            off += 8
        for name, n in TRUTH_VECTORS:
            ok = ok and f[name][0] == np.dtype(("<f8", (n,))) and f[name][1] == off
            off += 8 * n
        return bool(ok and off == 16 + 8 * N_TRUTH_F and f["fault_state"][0] == np.dtype(("i1", (N_JETS,)))
                    and f["fault_state"][1] == off)
    except KeyError:
        return False


_TRUTH_FAST = _truth_layout_ok()
_TRUTH_STATE_OFFSET = 16 + 8 * N_TRUTH_F


_SRC_GYRO, _SRC_ATT, _SRC_NAV, _SRC_CHAMBER = 0, 1, 2, 3   # one noise stream per source
_BLOCK = 4096


class _Noise:
    """Unit-normal noise drawn in blocks from one PCG64 stream per sensor source; a given
    seed reproduces every stream, and adding a source does not change the others."""

    def __init__(self, seed: int):
        def gen(src):
            return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(src,))))
        self.gens = [gen(s) for s in (_SRC_GYRO, _SRC_ATT, _SRC_NAV, _SRC_CHAMBER)]
        self.i = _BLOCK
        self.refill()

    def refill(self):
        self.g = self.gens[0].standard_normal((_BLOCK, 3))
        self.a = self.gens[1].standard_normal((_BLOCK, 3))
        self.n = self.gens[2].standard_normal((_BLOCK, 6))
        self.c = self.gens[3].standard_normal((_BLOCK, N_JETS))
        self.i = 0


class Plant:
    """The vehicle in its environment, stepped one control period at a time.

    Public state: k (step index), t_s, t_ns, sensors (0-d interfaces.records.SENSORS
    record, refilled in place), x (the state array: r_N, v_N, sigma_BN, omega_BN_B; read
    it, write it only through set_state), aux (derived outputs at t_k, indices A_*),
    fault_state (int8[18], NOMINAL/FAILED_OFF/STUCK_ON/DEGRADED), fault_eta (float[18]),
    inertia_truth_kgm2, p (truth parameter vector, indices P_*), propellant_kg, fault_log
    ((t_s, jet, kind) of every fault applied, scheduled or by call, in order).
    Methods: step(u, tau_ext_B=None), set_fault(jet, kind, eta), schedule_fault(t_s, jet,
    kind, eta), set_state(...), done(), truth(), fill_truth(rec=None).
    """

    def __init__(self, scenario: Scenario, seed: int | None = None):
        if seed is None:
            seed = scenario.seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        self.scenario = scenario
        self.seed = int(seed)
        veh = scenario.vehicle
        self.dt_control_s = scenario.dt_control_s
        self.dt_control_ns = int(round(scenario.dt_control_s * 1e9))
        self.n_sub = scenario.substeps
        self.dt_sub_s = scenario.dt_control_s / self.n_sub
        self.p = params_vector(scenario)
        self.inertia_truth_kgm2 = self.p[P_I:P_I + 9].reshape(3, 3).copy()
        self._T = np.ascontiguousarray(veh.torque_matrix_Nm, dtype=float)
        self._has_force = veh.jet_force_B_N is not None
        self._Fj = np.ascontiguousarray(veh.jet_force_B_N if self._has_force else np.zeros((3, N_JETS)), dtype=float)
        self._thrust = np.ascontiguousarray(veh.thrust_N, dtype=float)
        self._g0 = scenario.planet.g0_mps2
        self._isp = veh.isp_s

        # fault model: produced fraction = gain * u + bias
        self.fault_state = np.zeros(N_JETS, dtype=np.int8)
        self.fault_eta = np.ones(N_JETS)
        self._gain = np.ones(N_JETS)
        self._bias = np.zeros(N_JETS)
        self._schedule: list[tuple[int, int, str, float]] = []   # (k_apply, jet, kind, eta), sorted
        self.fault_log: list[tuple[float, int, str]] = []         # (t_s, jet, kind) of every fault applied
        self._next_fault = 0
        for f in scenario.faults:
            for j in f.jets:
                self._insert_fault(f.t_s, j, f.kind, f.eta if f.kind == "degraded" else 1.0)

        # work arrays for the kernels
        self.x = np.zeros(12)
        self.aux = np.zeros(N_AUX)
        self._ws = np.zeros((5, 12))
        self._C = np.zeros((3, 3))
        self._frac = np.zeros(N_JETS)
        self._tau_jets = np.zeros(3)
        self._F_B = np.zeros(3)
        self._tau_tot = np.zeros(3)
        self._tau_ext = np.zeros(3)
        self._zero3 = np.zeros(3)
        self._book = np.zeros(1)            # total impulse [N s]
        self._ti = np.zeros(2, np.int64)    # scratch [k, t_ns] for truth()
        self._status = STEP_OK

        sn = scenario.sensors
        self._sig = np.array([sn.gyro_noise_radps, sn.attitude_noise_rad, sn.nav_pos_noise_m,
                              sn.nav_vel_noise_mps, sn.chamber_noise])
        self._gyro_bias = np.asarray(sn.gyro_bias_radps, dtype=float).copy()
        self._nav_noise = bool(sn.nav_noise)
        self._noise = _Noise(self.seed)
        self.sensors = records.new(records.SENSORS)
        s = self.sensors
        self._out = (s["omega_BN_B"], s["sigma_BN"], s["r_N"], s["v_N"], s["accel_B"], s["chamber"])
        self._sf = np.ndarray((_S_NF,), np.float64, buffer=s, offset=_S_F0)   # views for the one-call step
        self._si = np.ndarray((3,), np.int64, buffer=s, offset=0)     # k, t_ns, u_k
        self._tau_ext_zero = True

        # initial state: trim attitude at the scenario's bank; omega = omega_WN so that
        # alpha, beta and bank stay put at t = 0
        r_N, v_N = initial_translation(scenario)
        self.x[0:3], self.x[3:6] = r_N, v_N
        C_WN = wind_dcm(r_N, v_rel_N(r_N, v_N, scenario.planet.omega_radps))
        C_BN = R2(veh.aero.alpha_trim_rad) @ R1(scenario.bank0_rad) @ C_WN
        self.x[6:9] = mrp.from_dcm(C_BN)
        _, aux = state_derivative(self.x, self.p)
        self.x[9:12] = C_BN @ aux[A_OMEGA_W_N:A_OMEGA_W_N + 3]
        # the parachute (scenario.deploy_by "fsw"): opened by the FSW's command inside the
        # vehicle's deploy box, else at the box's edge (docs/plant.md, deploy)
        self.deploy_box = veh.deploy_box if scenario.deploy_by == "fsw" else None
        self.deploy_commanded = False       # a deploy command held (the FSW's, latched)
        self.deploy_refused = 0             # checks with a command held outside the box
        self.deploy_edge = ""               # the box edge the plant deployed at, '' if none
        self._was_in_box = False
        self.k = 0
        self._apply_scheduled()
        self._refresh_aux()
        self._sample()

    # ---- time ----
    @property
    def t_s(self) -> float:
        return self.k * self.dt_control_s

    @property
    def t_ns(self) -> int:
        return self.k * self.dt_control_ns

    # ---- stepping ----
    def step(self, u, tau_ext_B=None, u_k: int | None = None) -> np.ndarray:
        """Integrate [t_k, t_k+1) with jet command u (18,) of 0/1 held, plus an optional
        ideal external torque tau_ext_B [N m] (open-loop and test use); return the sensor
        record for k+1 (the same object every step). ``u_k``: the step index of the command
        held (JETS.k; -1: none, jets held off), reported in the record as ``u_k`` so that the
        FSW judges its jets by the command actually in force; default k (the answer to
        frame k, as in lockstep and batch)."""
        if type(u) is not np.ndarray or u.dtype != np.uint8:
            u = _as_command(u)
        elif u.shape != (N_JETS,):
            raise ValueError(f"u must have shape ({N_JETS},), got {u.shape}")
        if tau_ext_B is None:
            tau = self._zero3
            if not self._tau_ext_zero:
                self._tau_ext[:] = 0.0
                self._tau_ext_zero = True
        else:
            tau = np.asarray(tau_ext_B, dtype=float)
            if tau.shape != (3,) or not np.all(np.isfinite(tau)):
                raise ValueError(f"tau_ext_B must be 3 finite numbers, got {tau_ext_B!r}")
            self._tau_ext[:] = tau
            self._tau_ext_zero = False
        nz = self._noise
        if nz.i >= _BLOCK:
            nz.refill()
        # the sensor frame for k+1 does not depend on a fault applied at k+1: sampled in the same call
        st = _step_and_sense(self.x, u, self._gain, self._bias, self._T, self._Fj, self._has_force, tau,
                             self.p, self.n_sub, self.dt_sub_s, self._thrust, self._frac, self._tau_jets,
                             self._F_B, self._tau_tot, self._ws, self._C, self.aux, self._book, self.dt_control_s,
                             self._sig, self._gyro_bias, nz.g, nz.a, nz.n, nz.c, nz.i, self._nav_noise,
                             self._sf, self._si, self.k + 1, self.dt_control_ns)
        if st == STEP_BAD_U:
            raise ValueError("u must hold only 0 or 1")
        self._si[2] = self.k if u_k is None else u_k
        nz.i += 1
        if st == STEP_NON_FINITE:
            self._status = STEP_NON_FINITE
        self.k += 1
        if self._next_fault < len(self._schedule) and self._schedule[self._next_fault][0] <= self.k:
            self._apply_scheduled()
        return self.sensors

    def _sample(self) -> None:
        nz = self._noise
        if nz.i >= _BLOCK:
            nz.refill()
        o = self._out
        _sense(self.x, self.aux, self._frac, self._sig, self._gyro_bias, nz.g, nz.a, nz.n, nz.c, nz.i,
               self._nav_noise, o[0], o[1], o[2], o[3], o[4], o[5])
        nz.i += 1
        s = self.sensors
        s["k"] = self.k
        s["t_ns"] = self.k * self.dt_control_ns
        s["u_k"] = -1                     # no command held before the first one

    def _refresh_aux(self) -> None:
        deriv(self.x, self.p, self._tau_tot, self._F_B, self._ws[0], self._C, self.aux, True)

    def set_state(self, r_N=None, v_N=None, sigma_BN=None, omega_BN_B=None) -> None:
        """Overwrite parts of the state (tests, Monte Carlo set-up); re-samples nothing."""
        for sl, val, name in ((slice(0, 3), r_N, "r_N"), (slice(3, 6), v_N, "v_N"),
                              (slice(6, 9), sigma_BN, "sigma_BN"), (slice(9, 12), omega_BN_B, "omega_BN_B")):
            if val is None:
                continue
            a = np.asarray(val, dtype=float)
            if a.shape != (3,) or not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be 3 finite numbers, got {val!r}")
            self.x[sl] = a
        self.x[6:9] = mrp.switch_shadow(self.x[6:9])
        self._refresh_aux()

    # ---- faults ----
    def set_fault(self, jet: int, kind: str, eta: float = 1.0) -> None:
        """Inject or remove a fault now (docs/plant.md, jet faults). jet 1..18, 0 = all;
        kind 'failed_off' | 'stuck_on' | 'degraded' (0 < eta < 1) | 'nominal' (no fault)."""
        _check_fault(jet, kind, eta)
        state = FAULT_HEALTH[kind]
        idx = range(N_JETS) if jet == 0 else (int(jet) - 1,)
        self.fault_log.extend((self.t_s, j + 1, kind) for j in idx)
        for j in idx:
            if state == FAILED_OFF:
                self.fault_state[j], self.fault_eta[j], self._gain[j], self._bias[j] = FAILED_OFF, 1.0, 0.0, 0.0
            elif state == STUCK_ON:
                self.fault_state[j], self.fault_eta[j], self._gain[j], self._bias[j] = STUCK_ON, 1.0, 0.0, 1.0
            elif state == DEGRADED:
                self.fault_state[j], self.fault_eta[j], self._gain[j], self._bias[j] = DEGRADED, eta, eta, 0.0
            else:
                self.fault_state[j], self.fault_eta[j], self._gain[j], self._bias[j] = NOMINAL, 1.0, 1.0, 0.0

    def schedule_fault(self, t_s: float, jet: int, kind: str, eta: float = 1.0) -> None:
        """Apply set_fault(jet, kind, eta) at the first step boundary with t >= t_s (at the
        next boundary if t_s is already past). Validated now: ValueError on bad input."""
        if isinstance(t_s, bool) or not isinstance(t_s, (int, float, np.integer, np.floating)) or not math.isfinite(t_s):
            raise ValueError(f"t_s must be a finite number, got {t_s!r}")
        _check_fault(jet, kind, eta)
        self._insert_fault(max(float(t_s), (self.k + 1) * self.dt_control_s), jet, kind, eta)

    def _insert_fault(self, t_s: float, jet: int, kind: str, eta: float) -> None:
        k_apply = max(0, math.ceil(t_s / self.dt_control_s - 1e-9))
        i = len(self._schedule)
        while i > self._next_fault and self._schedule[i - 1][0] > k_apply:   # stable: same k keeps order
            i -= 1
        self._schedule.insert(i, (k_apply, int(jet), kind, float(eta)))

    def _apply_scheduled(self) -> None:
        while self._next_fault < len(self._schedule) and self._schedule[self._next_fault][0] <= self.k:
            _, jet, kind, eta = self._schedule[self._next_fault]
            self.set_fault(jet, kind, eta)
            self._next_fault += 1

    # ---- the parachute ----
    def command_deploy(self, deploy) -> None:
        """The FSW's deploy command (JETS.deploy): 1 deploys at the next done() check inside
        the box (held until then), 0 is no command. ValueError for any other value (the
        SIL refuses such a command before it gets here)."""
        if isinstance(deploy, bool):
            deploy = int(deploy)
        if not isinstance(deploy, (int, np.integer)) or deploy not in (0, 1):
            raise ValueError(f"deploy must be 0 or 1, got {deploy!r}")
        if self.deploy_box is None and deploy:
            raise ValueError("this scenario's plant deploys at its end condition, not on command")
        self.deploy_commanded = self.deploy_commanded or bool(deploy)

    def _deploy_check(self) -> str:
        """'deploy' (commanded, inside the box), 'box_edge' (the box left or passed without a
        command), or ''."""
        a, box = self.aux, self.deploy_box
        inside = box.inside(a[A_MACH], a[A_QBAR], a[A_H])
        if self.deploy_commanded:
            if inside:
                return "deploy"
            self.deploy_refused += 1
        edge = box.passed(a[A_MACH], a[A_H])
        if not edge and self._was_in_box and not inside:
            edge = "qbar_max" if a[A_QBAR] > box.qbar_max_pa else "qbar_min" if a[A_QBAR] < box.qbar_min_pa \
                else "mach_max"
        self._was_in_box = inside
        if edge:
            self.deploy_edge = edge
            return "box_edge"
        return ""

    def deploy_report(self) -> dict:
        """How the parachute opened, for the run's summary: 'by' the FSW's command or at the
        box's 'edge' (which), and 'refused_outside_box', checks with a command held outside the
        box (held until inside). None values when this plant deploys at its end condition."""
        if self.deploy_box is None:
            return {"by": None, "edge": None, "refused_outside_box": 0}
        by = "box_edge" if self.deploy_edge else "command" if self.deploy_commanded else None
        return {"by": by, "edge": self.deploy_edge or None, "refused_outside_box": self.deploy_refused}

    # ---- outputs ----
    def done(self) -> tuple[bool, str]:
        """(finished, reason): 'mach' | 'speed' | 'deploy' | 'box_edge' | 'altitude' |
        'timeout' | 'non_finite' | ''."""
        if self._status == STEP_NON_FINITE:
            return True, "non_finite"
        a = self.aux
        if self.deploy_box is not None:
            why = self._deploy_check()
            if why:
                return True, why
        elif a[A_MACH] <= self.scenario.end_mach:
            return True, "mach"
        elif self.scenario.end_speed_mps is not None and a[A_V] <= self.scenario.end_speed_mps:
            return True, "speed"
        if a[A_H] <= self.scenario.end_altitude_m:
            return True, "altitude"
        if self.k * self.dt_control_s >= self.scenario.max_duration_s - 1e-9:
            return True, "timeout"
        return False, ""

    @property
    def propellant_kg(self) -> float:
        return float(self._book[0] / (self._isp * self._g0))

    def _truth_into(self, out_f: np.ndarray, out_i: np.ndarray, out_s: np.ndarray) -> None:
        _truth_kernel(self.x, self.aux, self._book, self._tau_jets, self._tau_ext, self._frac, self.fault_eta,
                      self.fault_state, self.k, self.dt_control_s, self.dt_control_ns,
                      self.scenario.planet.omega_radps, self.scenario.vehicle.mass_kg, self._g0, self._isp,
                      out_f, out_i, out_s)

    def truth(self) -> dict:
        """The full truth at t_k (docs/interfaces/index.md, sim/truth), as plain values (Python
        scalars; arrays are copies)."""
        f, s = np.empty(N_TRUTH_F), np.empty(N_JETS, np.int8)   # fresh: the arrays below are views of f
        self._truth_into(f, self._ti, s)
        v = f[:15].tolist()
        return {
            "k": self.k, "t_s": self.t_s, "t_ns": self.t_ns,
            "h_m": v[1], "V_rel_mps": v[2], "gamma_rad": v[3], "psi_rad": v[4], "lat_rad": v[5], "lon_rad": v[6],
            "mach": v[7], "qbar_pa": v[8], "rho_kgpm3": v[9],
            "alpha_rad": v[10], "beta_rad": v[11], "bank_rad": v[12],
            "sigma_BN": f[T_SIGMA:T_SIGMA + 3], "omega_BN_B": f[T_OMEGA:T_OMEGA + 3],
            "r_N": f[T_R:T_R + 3], "v_N": f[T_V:T_V + 3],
            "tau_jets_B": f[T_TAU_JETS:T_TAU_JETS + 3], "tau_ext_B": f[T_TAU_EXT:T_TAU_EXT + 3],
            "tau_aero_B": f[T_TAU_AERO:T_TAU_AERO + 3],
            "jet_thrust_frac": f[T_FRAC:T_FRAC + N_JETS],
            "decel_g": v[13],
            "fault_state": s, "fault_eta": f[T_ETA:T_ETA + N_JETS],
            "propellant_kg": v[14],
        }

    def fill_truth(self, rec: np.ndarray | None = None) -> np.ndarray:
        """The truth as an interfaces.records.TRUTH record (filled in place when given).
        A writeable 0-d TRUTH ndarray is written by one compiled call (no dict, no
        allocation): the batch and the SIL can record the truth every step through it."""
        if rec is None:
            rec = records.new(records.TRUTH)
        views = self.__dict__.get("_tviews")
        if views is None or views[0] is not rec:
            views = self._truth_views(rec)
        if views is None:
            for name, val in self.truth().items():
                rec[name] = val
        else:
            self._truth_into(views[1], views[2], views[3])
        return rec

    def _truth_views(self, rec):
        """(rec, floats, [k, t_ns], fault_state) views into rec's buffer, or None when rec is not
        a writeable 0-d TRUTH ndarray with the expected layout."""
        if not (_TRUTH_FAST and type(rec) is np.ndarray and rec.dtype == records.TRUTH and rec.shape == ()
                and rec.flags.writeable and rec.flags.c_contiguous):
            return None
        views = (rec, np.ndarray((N_TRUTH_F,), np.float64, buffer=rec, offset=16),
                 np.ndarray((2,), np.int64, buffer=rec, offset=0),
                 np.ndarray((N_JETS,), np.int8, buffer=rec, offset=_TRUTH_STATE_OFFSET))
        self._tviews = views
        return views


_check_fault = records.check_fault_request


def _as_command(u) -> np.ndarray:
    a = np.asarray(u)
    if a.shape != (N_JETS,):
        raise ValueError(f"u must have shape ({N_JETS},), got {a.shape}")
    if a.dtype == np.bool_:
        return a.view(np.uint8)
    if not np.all((a == 0) | (a == 1)):
        raise ValueError("u must hold only 0 or 1")
    return a.astype(np.uint8)
