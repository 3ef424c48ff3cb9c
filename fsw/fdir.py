"""FDIR: jet fault detection and isolation from chamber pressure, the isolation-to-
reconfiguration delay, ground overrides, and the analytic-redundancy torque residual
(docs/fsw/index.md "FDIR").

Jet monitor, per jet and per control period, from the command of the period that just
ended (u_k) and the chamber pressure measured over it (p_k, normalised, sensor noise
sigma = 0.02, docs/plant.md):

| commanded | measured                        | evidence for  |
|-----------|---------------------------------|---------------|
| on        | p < off_threshold               | failed off    |
| on        | degraded_lo <= p < degraded_hi  | degraded      |
| on        | p >= degraded_hi                | working (resets failed-off and degraded counts) |
| off       | p > on_threshold                | stuck on      |
| off       | p < off_threshold               | working (resets the stuck-on count) |

Any other sample (the gaps between the bands) is neutral: it neither counts nor resets.
A fault is declared after ``persist_n`` consecutive samples of evidence (``fdir.persist_s``
in control periods: 5 at 50 Hz, 20 at 200 Hz); a commanded-off
sample is neutral for failed-off/degraded (those faults show only when the jet fires) and
a commanded-on sample is neutral for stuck-on. eta_hat of a degraded jet is the mean of
its ``persist_n`` degraded samples. Declarations latch until ground clears them.
A jet latched DEGRADED keeps being watched for failed-off and stuck-on (escalation);
a jet latched FAILED_OFF or STUCK_ON is no longer watched.

False-alarm budget at the defaults (persist_s 0.1 = 5 samples at 50 Hz, degraded_hi 0.93,
sigma 0.02): a nominal firing reads below 0.93 with probability Phi(-3.5) = 2.3e-4, five in
a row 6.9e-19 per window (at 200 Hz twenty in a row: far less); failed-off and stuck-on thresholds are 40 and 25 sigma from the nominal levels.

Health seen by the allocator (``health_active``): an operator override wins immediately;
otherwise a detection is applied ``delay_s`` after it was declared (each detection keeps the
delay in force when it was declared; ``set_delay`` affects later detections).
``health_isolated`` is FDIR's own latched conclusion, applied or not.

Events (source "fdir"), texts <= 50 characters:
| code                | severity | example text                       |
|---------------------|----------|------------------------------------|
| jet_failed_off      | ERROR    | JET 17 FAILED_OFF                  |
| jet_stuck_on        | ERROR    | JET 5 STUCK_ON                     |
| jet_degraded        | WARNING  | JET 3 DEGRADED ETA 0.50            |
| fdir_reconfig       | NOTICE   | RECONFIG JET 17 FAILED_OFF         |
| fdir_override       | NOTICE   | GND MARK JET 3 DEGRADED ETA 0.50   |
| fdir_clear          | NOTICE   | GND CLEAR JET 17 / GND CLEAR ALL JETS |
| fdir_delay          | NOTICE   | FDIR DELAY 1.50 S                  |
| fdir_chamber_skip   | WARNING  | FDIR SKIPS NON-FINITE CHAMBER JET 5 (x3), rate-limited |
| unexplained_torque  | WARNING  | UNEXPLAINED TORQUE 250 NM, rate-limited |
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from common.events import EventLog
from interfaces.event_catalogue import EV
from interfaces.vocabulary import (DEGRADED, FAILED_OFF, HEALTH_NAMES, INHIBITED, MARK_KINDS, N_JETS, NOMINAL, STUCK_ON,
                                   refuse_state_word)

from .health import JetHealth
from .params import Param, periods

_ISOLATED = {FAILED_OFF: EV.JET_FAILED_OFF, STUCK_ON: EV.JET_STUCK_ON}     # a jet isolated: its event
_T_EPS_S = 1e-9          # time comparison slack for "delay elapsed" (float step times)

# Row indices of the per-jet counter array.
_C_FO, _C_ST, _C_DG = 0, 1, 2

JET_MONITOR_PARAMS = [
    Param("fdir.persist_s", 1e-3, 4.0, "s", "evidence this long (in consecutive per-period samples, at least one) "
          "declares a jet fault"),
    Param("fdir.on_threshold", 0.05, 0.95, "-", "commanded off: chamber above this = flow (stuck-on evidence)"),
    Param("fdir.off_threshold", 0.01, 0.9, "-", "below this = no flow (failed-off evidence when commanded on)"),
    Param("fdir.degraded_lo", 0.01, 0.99, "-", "commanded on: lower edge of the partial-pressure band"),
    Param("fdir.degraded_hi", 0.02, 1.0, "-", "commanded on: upper edge of the partial-pressure band"),
    Param("fdir.delay_s", 0.0, 60.0, "s", "isolation-to-reconfiguration delay (paper case 4: 1.5)"),
    Param("fdir.res_thr_Nm", 0.0, 1e5, "N*m", "residual threshold, absolute part"),
    Param("fdir.res_rel", 0.0, 10.0, "-", "residual threshold, part relative to |tau_cmd|+|tau_aero_est|"),
    Param("fdir.res_persist_s", 0.0, 60.0, "s", "residual above threshold this long -> unexplained torque"),
    Param("fdir.res_tau_s", 0.0, 10.0, "s", "residual low-pass time constant (0 = unfiltered)"),
    Param("fdir.mode", 0, 0, "", "detect: the jet monitor identifies faults; oracle: TEST MODE, the plant's "
          "fault log is the identification (paper's assumption), jet monitor off", ground_settable=False,
          choices=("detect", "oracle")),
]


@njit(cache=True)
def _jet_monitor(u, p, iso_state, cnt, sum_dg, thr, persist_n, new_kind, eta_new):
    """One sample per jet: update the evidence counters; write declarations to new_kind /
    eta_new (0 = none). Returns (number of declarations, number of non-finite samples)."""
    off_thr, on_thr, dg_lo, dg_hi = thr[0], thr[1], thr[2], thr[3]
    n_new = 0
    n_bad = 0
    for k in range(u.shape[0]):
        new_kind[k] = 0
        st = iso_state[k]
        if st == FAILED_OFF or st == STUCK_ON:
            continue
        x = p[k]
        if not math.isfinite(x):
            n_bad += 1
            new_kind[k] = -1          # marks the jet for the non-finite report
            continue
        if u[k] != 0:
            if x < off_thr:
                cnt[_C_FO, k] += 1
                cnt[_C_DG, k] = 0
                sum_dg[k] = 0.0
            elif x >= dg_hi:
                cnt[_C_FO, k] = 0
                cnt[_C_DG, k] = 0
                sum_dg[k] = 0.0
            elif x >= dg_lo:
                cnt[_C_FO, k] = 0
                if st == NOMINAL:
                    cnt[_C_DG, k] += 1
                    sum_dg[k] += x
        else:
            if x > on_thr:
                cnt[_C_ST, k] += 1
            elif x < off_thr:
                cnt[_C_ST, k] = 0
        kind = 0
        if cnt[_C_ST, k] >= persist_n:
            kind = STUCK_ON
            eta_new[k] = 1.0
        elif cnt[_C_FO, k] >= persist_n:
            kind = FAILED_OFF
            eta_new[k] = 0.0
        elif cnt[_C_DG, k] >= persist_n:
            kind = DEGRADED
            eta_new[k] = sum_dg[k] / cnt[_C_DG, k]
        if kind != 0:
            new_kind[k] = kind
            n_new += 1
            cnt[_C_FO, k] = 0
            cnt[_C_ST, k] = 0
            cnt[_C_DG, k] = 0
            sum_dg[k] = 0.0
    return n_new, n_bad


# flags of ``jet_step``: what its caller's Python (``Fdir.settle``) has to do
STEP_UNKNOWN, STEP_NONFINITE, STEP_DECLARED, STEP_DUE = 1, 2, 4, 8


@njit(cache=True)
def jet_step(u_k, sent, sent_k, zero_u, p, oracle, t_s, next_apply, iso_state, cnt, sum_dg, thr, persist,
             new_kind, eta_new):
    """``Fdir.update``'s per-period part with the command in force looked up: the answer to
    frame ``u_k`` in the ring (``sent`` rows, ``sent_k`` their frame indices), ``zero_u`` for
    -1; then the jet monitor (``_jet_monitor``, not in oracle mode) on the chamber pressures
    ``p`` (``persist``: its persistence, one int). Returns STEP_* flags: the command not known (no evidence), non-finite samples,
    declarations in ``new_kind``, a detection's reconfiguration due by ``t_s``; 0 = none."""
    flags = 0
    if u_k == -1:
        u = zero_u
    else:
        i = u_k % sent_k.shape[0]
        u = sent[i]
        if sent_k[i] != u_k:
            flags = STEP_UNKNOWN
    if flags == 0 and not oracle:
        n_new, n_bad = _jet_monitor(u, p, iso_state, cnt, sum_dg, thr, persist[0], new_kind, eta_new)
        if n_bad:
            flags += STEP_NONFINITE
        if n_new:
            flags += STEP_DECLARED
    if t_s + _T_EPS_S >= next_apply:
        flags += STEP_DUE
    return flags


@njit(cache=True)
def _residual_step(w, w0, dt_s, tau_cmd, tau_aero, I, a, res_f):
    """r = I (w - w0)/dt + wm x I wm - tau_aero - tau_cmd with wm = (w + w0)/2; res_f += a (r - res_f).
    Returns |tau_cmd| + |tau_aero|, or -1.0 (nothing updated) if any input is non-finite."""
    for i in range(3):
        if not (math.isfinite(w[i]) and math.isfinite(w0[i]) and math.isfinite(tau_cmd[i])
                and math.isfinite(tau_aero[i])):
            return -1.0
        for j in range(3):
            if not math.isfinite(I[i, j]):
                return -1.0
    wm0 = 0.5 * (w[0] + w0[0])
    wm1 = 0.5 * (w[1] + w0[1])
    wm2 = 0.5 * (w[2] + w0[2])
    d0 = (w[0] - w0[0]) / dt_s
    d1 = (w[1] - w0[1]) / dt_s
    d2 = (w[2] - w0[2]) / dt_s
    h0 = I[0, 0] * wm0 + I[0, 1] * wm1 + I[0, 2] * wm2
    h1 = I[1, 0] * wm0 + I[1, 1] * wm1 + I[1, 2] * wm2
    h2 = I[2, 0] * wm0 + I[2, 1] * wm1 + I[2, 2] * wm2
    r0 = I[0, 0] * d0 + I[0, 1] * d1 + I[0, 2] * d2 + (wm1 * h2 - wm2 * h1) - tau_aero[0] - tau_cmd[0]
    r1 = I[1, 0] * d0 + I[1, 1] * d1 + I[1, 2] * d2 + (wm2 * h0 - wm0 * h2) - tau_aero[1] - tau_cmd[1]
    r2 = I[2, 0] * d0 + I[2, 1] * d1 + I[2, 2] * d2 + (wm0 * h1 - wm1 * h0) - tau_aero[2] - tau_cmd[2]
    res_f[0] += a * (r0 - res_f[0])
    res_f[1] += a * (r1 - res_f[1])
    res_f[2] += a * (r2 - res_f[2])
    return (math.sqrt(tau_cmd[0] ** 2 + tau_cmd[1] ** 2 + tau_cmd[2] ** 2)
            + math.sqrt(tau_aero[0] ** 2 + tau_aero[1] ** 2 + tau_aero[2] ** 2))


def _f64(x, shape) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"residual_check: expected shape {shape}, got {a.shape}")
    return a


def _check_params(params: dict, plist: list[Param]) -> dict[str, float]:
    out = {}
    for p in plist:
        if p.name not in params:
            raise ValueError(f"{p.name}: missing")
        out[p.name] = p.check(params[p.name])
    return out


class Fdir:
    """Jet fault detection/isolation, reconfiguration delay, ground overrides, residual check.

    ``update`` runs every control period (RG1); ``residual_check`` may run at any rate (its
    persistence is in seconds). ``health_active`` is mutated in place; ``health_version``
    increments on every change of it (from ``update``, ``override``, ``clear`` or
    ``set_inhibit``), so a consumer can tell that it must reconfigure.
    """

    # The jet monitor's and the residual's; the other fdir.* parameters are declared by the
    # sensor-frame monitor (fsw/monitors.py) and the failsafe list (fsw/modes.py).
    PARAMS: list[Param] = JET_MONITOR_PARAMS

    def __init__(self, params: dict[str, float], dt_s: float, events: EventLog, n_jets: int = N_JETS) -> None:
        if not (isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s: must be finite and > 0, got {dt_s!r}")
        if not (isinstance(n_jets, int) and n_jets > 0):
            raise ValueError(f"n_jets: must be a positive integer, got {n_jets!r}")
        self.dt_s = float(dt_s)
        self.events = events
        self.n = n_jets
        self.p = _check_params(params, JET_MONITOR_PARAMS)
        self._check_consistency(self.p)
        self._thr = np.zeros(4)
        self._persist = np.zeros(1, dtype=np.int64)
        self._load_thresholds()
        self.oracle = self.p["fdir.mode"] == "oracle"
        if self.oracle:
            events.emit(0.0, EV.FDIR_ORACLE)

        self.health_isolated = JetHealth(n_jets)
        self.health_active = JetHealth(n_jets)
        self.health_version = 0
        self.detections: list[dict] = []
        self.nonfinite_count = 0
        self.unknown_command_periods = 0     # periods whose command in force was not known (no evidence)

        n = n_jets
        self._cnt = np.zeros((3, n), dtype=np.int64)
        self._sum_dg = np.zeros(n)
        self._new_kind = np.zeros(n, dtype=np.int8)
        self._eta_new = np.zeros(n)
        # rehearse's scratch: the counters copied, the declarations discarded
        self._r_cnt = np.zeros((3, n), dtype=np.int64)
        self._r_sum_dg = np.zeros(n)
        self._r_kind = np.zeros(n, dtype=np.int8)
        self._r_eta = np.zeros(n)
        self._t_apply = np.full(n, np.inf)      # when the latched detection reaches health_active
        self._app_state = np.zeros(n, dtype=np.int8)   # detection state applied to health_active
        self._app_eta = np.ones(n)
        self._ovr_state = np.full(n, -1, dtype=np.int8)   # -1 = no override
        self._ovr_eta = np.ones(n)
        self._next_apply = math.inf
        self._u8 = np.zeros(n, dtype=np.uint8)

        # residual check state
        self._res_f = np.zeros(3)
        self._tau_ref_f = 0.0
        self._res_above_s = 0.0
        self.residual_norm_Nm = 0.0
        self.residual_limit_Nm = 0.0       # what |r_f| was last compared with
        self.residual_alarm = False

    # ------------------------------------------------------------------ parameters
    @staticmethod
    def _check_consistency(p: dict) -> None:
        off, on = p["fdir.off_threshold"], p["fdir.on_threshold"]
        lo, hi = p["fdir.degraded_lo"], p["fdir.degraded_hi"]
        if not off <= lo:
            raise ValueError(f"fdir.degraded_lo: must be >= fdir.off_threshold ({off:g}), got {lo:g}")
        if not lo < hi:
            raise ValueError(f"fdir.degraded_hi: must be > fdir.degraded_lo ({lo:g}), got {hi:g}")
        if not off < on:
            raise ValueError(f"fdir.on_threshold: must be > fdir.off_threshold ({off:g}), got {on:g}")

    def _load_thresholds(self) -> None:
        p = self.p
        # in place: the compiled callers hold the array
        self._thr[:] = (p["fdir.off_threshold"], p["fdir.on_threshold"], p["fdir.degraded_lo"], p["fdir.degraded_hi"])
        self._persist[0] = periods(p["fdir.persist_s"], self.dt_s)
        self.delay_s = p["fdir.delay_s"]

    def set_param(self, name: str, value: float) -> float:
        """Owner's hook: one of the jet monitor's or residual's parameters (validated,
        consistent with the others), used from the next sample on; ValueError leaves
        everything unchanged."""
        plist = {q.name: q for q in self.PARAMS}
        if name not in plist:
            raise ValueError(f"{name}: not a jet-monitor or residual parameter")
        v = plist[name].check(value)
        trial = dict(self.p)
        trial[name] = v
        self._check_consistency(trial)
        self.p = trial
        self._load_thresholds()
        return v

    def set_delay(self, delay_s: float, t_s: float | None = None) -> None:
        """Isolation-to-reconfiguration delay for detections declared from now on."""
        v = self.set_param("fdir.delay_s", delay_s)
        if t_s is not None:
            self.events.emit(t_s, EV.FDIR_DELAY, delay_s=v)

    # ------------------------------------------------------------------ jet monitor
    def update(self, t_s: float, u_cmd_prev: np.ndarray | None, chamber: np.ndarray) -> bool:
        """One control period: ``u_cmd_prev`` is the command in force over the period that
        just ended (None: not known -- the plant held a command this FSW no longer has --
        then the period is no evidence either way), ``chamber`` the normalised chamber
        pressure measured over it. Non-finite chamber samples are ignored for their jet (and
        reported, rate-limited). Returns True when ``health_active`` changed during this call."""
        if u_cmd_prev is None:
            return self.settle(t_s, STEP_UNKNOWN)
        if u_cmd_prev.shape != (self.n,) or chamber.shape != (self.n,):
            raise ValueError(f"fdir.update: u_cmd_prev and chamber must have shape ({self.n},), "
                             f"got {u_cmd_prev.shape} and {chamber.shape}")
        u = u_cmd_prev
        if u.dtype != np.uint8:
            np.greater(u, 0.5, out=self._u8, casting="unsafe")
            u = self._u8
        if chamber.dtype != np.float64:
            chamber = chamber.astype(np.float64)
        if self.oracle:       # identification comes from identified() alone
            return self.settle(t_s, 0)
        n_new, n_bad = _jet_monitor(u, chamber, self.health_isolated.state, self._cnt, self._sum_dg,
                                    self._thr, self._persist[0], self._new_kind, self._eta_new)
        return self.settle(t_s, (STEP_NONFINITE if n_bad else 0) + (STEP_DECLARED if n_new else 0))

    def settle(self, t_s: float, flags: int) -> bool:
        """What the jet monitor's period calls for (``jet_step``'s STEP_* ``flags``): the
        unknown command counted, non-finite samples reported, declarations made, and the
        reconfigurations due applied. Returns True when ``health_active`` changed."""
        if flags & STEP_UNKNOWN:
            self.unknown_command_periods += 1
        if flags & STEP_NONFINITE:
            self._report_nonfinite(t_s, int(np.count_nonzero(self._new_kind == -1)))
        if flags & STEP_DECLARED:
            self._declare(t_s)
        if t_s + _T_EPS_S >= self._next_apply:
            return self._apply_due(t_s)
        return False

    def step_arrays(self, scratch: bool = False) -> tuple:
        """The arrays ``jet_step`` works on after ``next_apply``, in its order; the parameters
        are refilled in place, so the tuple stays valid. ``scratch``: the rehearsal's, whose
        counters ``rehearsal_copy`` refreshes and whose declarations nothing reads."""
        if scratch:
            return (self.health_isolated.state, self._r_cnt, self._r_sum_dg, self._thr, self._persist,
                    self._r_kind, self._r_eta)
        return (self.health_isolated.state, self._cnt, self._sum_dg, self._thr, self._persist,
                self._new_kind, self._eta_new)

    def rehearsal_copy(self) -> None:
        """The counters copied to the rehearsal's scratch (``step_arrays(scratch=True)``)."""
        np.copyto(self._r_cnt, self._cnt)
        np.copyto(self._r_sum_dg, self._sum_dg)

    def identified(self, t_s: float, jet: int, kind: str, eta: float = 1.0) -> None:
        """Oracle mode (a test mode): the fault of ``jet`` is known as of ``t_s`` (the time the
        plant applied it), declared as the jet monitor would and applied ``delay_s`` later.
        kind: failed_off | stuck_on | degraded (0 < eta < 1) | nominal (a removed fault)."""
        if not self.oracle:
            raise ValueError("fdir.identified: only in fdir.mode = oracle")
        jet = self._check_jet(jet)
        state = MARK_KINDS.get(kind, INHIBITED)
        if state == NOMINAL:
            self.health_isolated.set(jet, NOMINAL)
            self._t_apply[jet - 1] = t_s + self.delay_s
            self._next_apply = min(self._next_apply, t_s + self.delay_s)
            return
        if state == INHIBITED:
            raise ValueError(f"kind: {refuse_state_word(kind, (k for k, c in MARK_KINDS.items() if c != INHIBITED))}")
        self._new_kind[:] = 0
        self._new_kind[jet - 1] = state
        self._eta_new[jet - 1] = float(eta) if kind == "degraded" else (0.0 if kind == "failed_off" else 1.0)
        self._declare(t_s)

    def _report_nonfinite(self, t_s: float, n_bad: int) -> None:
        self.nonfinite_count += n_bad
        first = int(np.flatnonzero(self._new_kind == -1)[0]) + 1
        self.events.emit(t_s, EV.FDIR_CHAMBER_SKIP, jet=first, count=n_bad)

    def _declare(self, t_s: float) -> None:
        for k in np.flatnonzero(self._new_kind > 0):
            kind = int(self._new_kind[k])
            eta = float(self._eta_new[k])
            self.health_isolated.set(k + 1, kind, eta)
            t_apply = t_s + self.delay_s
            self._t_apply[k] = t_apply
            self._next_apply = min(self._next_apply, t_apply)
            name = HEALTH_NAMES[kind]
            self.detections.append({"jet": int(k + 1), "kind": name, "t_s": float(t_s), "eta_hat": eta,
                                    "t_apply_s": float(t_apply)})
            if kind == DEGRADED:
                self.events.emit(t_s, EV.JET_DEGRADED, jet=k + 1, eta=eta)
            else:
                self.events.emit(t_s, _ISOLATED[kind], jet=k + 1)

    def _apply_due(self, t_s: float) -> bool:
        due = self._t_apply <= t_s + _T_EPS_S
        self._t_apply[due] = np.inf
        self._next_apply = float(np.min(self._t_apply))
        changed = False
        for k in np.flatnonzero(due):
            st = int(self.health_isolated.state[k])
            self._app_state[k] = st
            self._app_eta[k] = self.health_isolated.eta[k]
            eta = {"eta": self.health_isolated.eta[k]} if st == DEGRADED else {}
            self.events.emit(t_s, EV.FDIR_RECONFIG, jet=k + 1, health=st, override=self._ovr_state[k] >= 0, **eta)
        if due.any():
            changed = self._refresh_active()
        return changed

    @property
    def reconfig_pending(self) -> bool:
        """A detection waits for its reconfiguration delay: the allocator still plans with
        jets FDIR knows do not deliver what it models."""
        return self._next_apply < np.inf

    def _refresh_active(self) -> bool:
        """Recompute health_active from overrides and applied detections; True if it changed."""
        act = self.health_active
        before = act.key()
        for k in range(self.n):
            if self._ovr_state[k] >= 0:
                act.set(k + 1, int(self._ovr_state[k]), float(self._ovr_eta[k]))
            else:
                act.set(k + 1, int(self._app_state[k]), float(self._app_eta[k]))
        changed = act.key() != before
        if changed:
            self.health_version += 1
        return changed

    # ------------------------------------------------------------------ ground commands
    def _check_jet(self, jet, allow_all: bool = False) -> int:
        if isinstance(jet, bool) or not isinstance(jet, (int, np.integer)):
            raise ValueError(f"jet: must be an integer, got {jet!r}")
        lo = 0 if allow_all else 1
        if not lo <= int(jet) <= self.n:
            raise ValueError(f"jet: must be in {lo}..{self.n}, got {jet}")
        return int(jet)

    def override(self, t_s: float, jet: int, kind: str, eta: float = 1.0) -> None:
        """Operator marking, applied to health_active immediately and held until ``clear``:
        'failed_off' | 'stuck_on' | 'degraded' (0 < eta < 1) | 'nominal' (use the jet as
        nominal whatever FDIR concludes; FDIR keeps monitoring and reporting)."""
        jet = self._check_jet(jet)
        state = MARK_KINDS.get(kind, INHIBITED)
        if state == INHIBITED:          # the inhibit mask is set_inhibit's, not a health state
            raise ValueError(f"kind: {refuse_state_word(kind, (k for k, c in MARK_KINDS.items() if c != INHIBITED))}")
        if state == DEGRADED:
            if isinstance(eta, bool) or not isinstance(eta, (int, float, np.floating)) \
                    or not math.isfinite(eta) or not 0.0 < eta < 1.0:
                raise ValueError(f"eta: must be in (0, 1) for degraded, got {eta!r}")
        self._ovr_state[jet - 1] = state
        self._ovr_eta[jet - 1] = float(eta) if state == DEGRADED else 1.0
        self.events.emit(t_s, EV.FDIR_OVERRIDE, jet=jet, health=state, **({"eta": eta} if state == DEGRADED else {}))
        self._refresh_active()

    def clear(self, t_s: float, jet: int) -> None:
        """Ground: clear the latch, any pending reconfiguration and any override of ``jet``
        (0 = all jets); the jet returns to nominal in health_active immediately."""
        jet = self._check_jet(jet, allow_all=True)
        idx = range(self.n) if jet == 0 else [jet - 1]
        for k in idx:
            self.health_isolated.set(k + 1, NOMINAL)
            self._cnt[:, k] = 0
            self._sum_dg[k] = 0.0
            self._t_apply[k] = np.inf
            self._app_state[k] = NOMINAL
            self._app_eta[k] = 1.0
            self._ovr_state[k] = -1
            self._ovr_eta[k] = 1.0
        self._next_apply = float(np.min(self._t_apply))
        self.events.emit(t_s, EV.FDIR_CLEAR, jets=jet)
        self._refresh_active()

    def set_inhibit(self, t_s: float, jet: int, on: bool) -> None:
        """Mirror of the ground inhibit mask into health_active (the allocator must not plan
        with an inhibited jet); jet 0 = all. The jet driver enforces the mask itself."""
        jet = self._check_jet(jet, allow_all=True)
        before = self.health_active.key()
        if jet == 0:
            self.health_active.inhibited[:] = bool(on)
            self.health_isolated.inhibited[:] = bool(on)
        else:
            self.health_active.inhibited[jet - 1] = bool(on)
            self.health_isolated.inhibited[jet - 1] = bool(on)
        if self.health_active.key() != before:
            self.health_version += 1

    # ------------------------------------------------------------------ analytic redundancy
    def residual_check(self, t_s: float, omega_B: np.ndarray, omega_prev_B: np.ndarray, dt_s: float,
                       tau_cmd_B: np.ndarray, tau_aero_est_B: np.ndarray, I_hat: np.ndarray) -> float:
        """Angular-acceleration residual r = I_hat w_dot + w x I_hat w - tau_aero_est - tau_cmd
        (docs/fsw/index.md FDIR), with w_dot = (w - w_prev)/dt (the mean over the interval, which
        matches jets held over it) and w at the interval midpoint. ``tau_cmd_B`` is the (mean) torque
        the jets were commanded to give over that interval. r is low-passed (res_tau_s); when
        |r_f| > res_thr_Nm + res_rel (|tau_cmd| + |tau_aero_est|) (low-passed too) for
        res_persist_s, an "unexplained torque" WARNING is raised (rate-limited) and
        ``residual_alarm`` set. Returns |r_f| [N*m]. Non-finite inputs skip the sample."""
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s: must be finite and > 0, got {dt_s!r}")
        tau_f = self.p["fdir.res_tau_s"]
        a = 1.0 if tau_f <= 0 else min(1.0, dt_s / tau_f)
        tau_ref = _residual_step(_f64(omega_B, (3,)), _f64(omega_prev_B, (3,)), float(dt_s), _f64(tau_cmd_B, (3,)),
                                 _f64(tau_aero_est_B, (3,)), _f64(I_hat, (3, 3)), a, self._res_f)
        if tau_ref < 0:
            return self.residual_norm_Nm
        self._tau_ref_f += a * (tau_ref - self._tau_ref_f)
        rf = self._res_f
        norm = math.sqrt(rf[0] * rf[0] + rf[1] * rf[1] + rf[2] * rf[2])
        self.residual_norm_Nm = norm
        limit = self.p["fdir.res_thr_Nm"] + self.p["fdir.res_rel"] * self._tau_ref_f
        self.residual_limit_Nm = limit
        if norm > limit:
            self._res_above_s += dt_s
            if self._res_above_s >= self.p["fdir.res_persist_s"] - _T_EPS_S:
                self.residual_alarm = True
                self.events.emit(t_s, EV.UNEXPLAINED_TORQUE, torque_Nm=norm)
        else:
            self._res_above_s = 0.0
            self.residual_alarm = False
        return norm
