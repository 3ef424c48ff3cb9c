"""Sensor-frame monitor (docs/fsw/index.md FDIR "Other monitors", docs/interfaces/index.md).

How to call it, per control period of the executive:
- ``check(t_s, frame)`` for each SENSORS record received; True = use it.
- ``tick(t_s, got_frame=False)`` for a period in which no frame arrived at all (the real-
  time executive; in lockstep every tick is a frame and ``tick`` is not needed).
Each rejected frame and each frameless ``tick`` is a period without fresh data; after
``fdir.stale_s`` of them in a row (in control periods, at least one) the monitor is STALE (``stale`` and
``jets_must_hold_off`` True, ERROR event); the next accepted frame recovers it (NOTICE).

Rejections (the whole frame; counted in ``counts`` under the reason):
- ``format``: not a SENSORS record;
- ``nonfinite``: a non-finite value in omega, sigma, r, v or accel;
- ``range``: |sigma| > 1 + sigma_tol, |omega| > omega_max, |r| below the surface by more than
  r_below_m or above it by more than alt_max_m, |v| > v_max, |accel| > accel_max, k < 0;
- ``duplicate`` (k equal to the last accepted) and ``out_of_order`` (k smaller).
Chamber pressures are per-jet sensors: a non-finite value or one outside
[chamber_lo, chamber_hi] is replaced by NaN in the frame, in place (FDIR then ignores
that jet's sample), counted under ``chamber_nonfinite`` / ``chamber_range`` per jet, and
does not reject the frame: one failed transducer must not cost the vehicle its attitude
control. Events are WARNING and rate-limited per reason (source "monitor").
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from common.events import EventLog
from interfaces.event_catalogue import EV, EventDef
from interfaces.records import SENSORS

from .params import Param, load_params, periods

MARS_RADIUS_M = 3396.2e3   # default only; pass the planet's radius from data/planets

REASONS = ("format", "nonfinite", "range", "duplicate", "out_of_order", "chamber_nonfinite", "chamber_range")
_VEC_FIELDS = ("omega_BN_B", "sigma_BN", "r_N", "v_N", "accel_B")

# The float part of a SENSORS record is one contiguous run of float64: the five 3-vectors
# in _VEC_FIELDS order, then the chamber pressures. check() views it without copying.
_F0 = SENSORS.fields["omega_BN_B"][1]
_K0 = SENSORS.fields["k"][1]
_N_CH = SENSORS.fields["chamber"][0].shape[0]
_N_F = 15 + _N_CH
assert all(SENSORS.fields[f][1] == _F0 + 24 * i for i, f in enumerate(_VEC_FIELDS))
assert SENSORS.fields["chamber"][1] == _F0 + 120 and SENSORS.itemsize == _F0 + 8 * _N_F
# ... and k, t_ns, u_k one run of int64 before it
assert all(SENSORS.fields[f][0] == np.dtype("<i8") and SENSORS.fields[f][1] == _K0 + 8 * i
           for i, f in enumerate(("k", "t_ns", "u_k"))) and _K0 % 8 == 0


@njit(cache=True)
def _frame_kernel(x, lims, n_vec, out):
    """x: the 15 vector floats then the chamber pressures; lims: (lo, hi) of |vector| per
    field, then (chamber_lo, chamber_hi). Returns 0 = accepted, 1 + i = vector i non-finite,
    101 + i = |vector i| out of range (|v| in out[0]). Bad chamber entries become NaN;
    out[1], out[2] = how many were non-finite / out of range, out[3], out[4] = first of each."""
    for i in range(n_vec):
        ss = 0.0
        for j in range(3):
            v = x[3 * i + j]
            if not math.isfinite(v):
                return 1 + i
            ss += v * v
        mag = math.sqrt(ss)
        if mag < lims[i, 0] or mag > lims[i, 1]:
            out[0] = mag
            return 101 + i
    lo, hi = lims[n_vec, 0], lims[n_vec, 1]
    out[1] = 0.0
    out[2] = 0.0
    out[3] = -1.0
    out[4] = -1.0
    for k in range(3 * n_vec, x.shape[0]):
        c = x[k]
        if not math.isfinite(c):
            if out[3] < 0:
                out[3] = k - 3 * n_vec
            out[1] += 1.0
            x[k] = np.nan
        elif c < lo or c > hi:
            if out[4] < 0:
                out[4] = k - 3 * n_vec
            out[2] += 1.0
            x[k] = np.nan
    return 0


# codes of ``frame_check``: a rejection is negative, an accepted frame 0 or the sum of what it
# calls for (the events are the Python caller's)
REJ_K, REJ_DUPLICATE, REJ_OUT_OF_ORDER = -1, -2, -3   # k < 0; k == last; k < last
REJ_VECTOR = -1000        # -1000 - frame kernel code: a vector non-finite or out of range
ACC_CHAMBER, ACC_RECOVER = 1, 2     # bad chamber entries to report; stale, now recovered
# the monitor's sequence state, one int64 array the kernel updates: the last accepted step
# index (-1: none yet), frames accepted, consecutive periods without fresh data
_SEQ_LAST, _SEQ_ACCEPTED, _SEQ_MISSED = 0, 1, 2


@njit(cache=True)
def frame_check(x, k, lims, out, seq, stale):
    """The frame check of one record (``x`` its floats, ``k`` its step index) as ``check``
    does it: the vector and chamber checks (``_frame_kernel``), then the sequence against
    ``seq``; an accepted frame updates ``seq``. Returns a REJ_* code (nothing updated; for
    REJ_VECTOR the frame kernel's code is added) or ACC_* flags (0: nothing to report)."""
    if k < 0:
        return REJ_K
    code = _frame_kernel(x, lims, 5, out)
    if code != 0:
        return REJ_VECTOR - code
    last = seq[_SEQ_LAST]
    if last >= 0 and k <= last:
        return REJ_DUPLICATE if k == last else REJ_OUT_OF_ORDER
    seq[_SEQ_LAST] = k
    seq[_SEQ_ACCEPTED] += 1
    seq[_SEQ_MISSED] = 0
    flags = ACC_CHAMBER if out[1] != 0.0 or out[2] != 0.0 else 0
    return flags + ACC_RECOVER if stale else flags


class SensorMonitor:
    PARAMS = [
        Param("fdir.stale_s", 1e-3, 20.0, "s", "no fresh frame this long (whole control periods, at least one) "
              "-> STALE"),
        Param("fdir.omega_max_radps", 0.01, 100.0, "rad/s", "largest credible |omega|"),
        Param("fdir.sigma_tol", 0.0, 1.0, "-", "|sigma| may exceed 1 by this much"),
        Param("fdir.r_below_m", 0.0, 1e6, "m", "reject |r| this far below the surface"),
        Param("fdir.alt_max_m", 1e3, 1e9, "m", "reject |r| this far above the surface"),
        Param("fdir.v_max_mps", 1.0, 1e6, "m/s", "largest credible |v|"),
        Param("fdir.accel_max_mps2", 1.0, 1e6, "m/s^2", "largest credible sensed |accel|"),
        Param("fdir.chamber_lo", -10.0, 0.0, "-", "lowest credible normalised chamber pressure"),
        Param("fdir.chamber_hi", 1.0, 10.0, "-", "highest credible normalised chamber pressure"),
    ]

    def __init__(self, events: EventLog, dt_s: float, params: dict[str, float] | None = None,
                 radius_m: float = MARS_RADIUS_M) -> None:
        if params is None:
            params = load_params(self.PARAMS)
        self._table = {q.name: q for q in self.PARAMS}
        self.p: dict[str, float] = {}
        for q in self.PARAMS:
            if q.name not in params:
                raise ValueError(f"{q.name}: missing")
            self.p[q.name] = q.check(params[q.name])
        if not (math.isfinite(dt_s) and dt_s > 0):
            raise ValueError(f"dt_s: must be finite and > 0, got {dt_s!r}")
        if not (math.isfinite(radius_m) and radius_m > 0):
            raise ValueError(f"radius_m: must be finite and > 0, got {radius_m!r}")
        self.events = events
        self.dt_s = float(dt_s)
        self.radius_m = float(radius_m)
        self._lims = np.zeros((6, 2))
        self._apply()
        self._out = np.zeros(5)
        self._r_x = np.zeros(_N_F)                          # the rehearsal's copy of a frame's floats
        self._r_seq = np.zeros(3, dtype=np.int64)           # ... and of the sequence state
        # (frame, its dtype, float view, view of k, t_ns, u_k) of the last frame
        self._fviews: tuple = (None, None, None, None)
        self.counts: dict[str, int] = {r: 0 for r in REASONS}
        self._seq = np.array([-1, 0, 0], dtype=np.int64)    # frame_check's sequence state
        self.stale = False

    # the sequence state as numbers (frame_check keeps it in ``_seq``)
    @property
    def last_k(self) -> int | None:
        """Step index of the last accepted frame (None: none yet, or a restarted source)."""
        k = int(self._seq[_SEQ_LAST])
        return None if k < 0 else k

    @property
    def accepted(self) -> int:
        return int(self._seq[_SEQ_ACCEPTED])

    @property
    def missed(self) -> int:
        """Consecutive periods without fresh data."""
        return int(self._seq[_SEQ_MISSED])

    def _apply(self) -> None:
        """Limits of the frame checks from the parameters (in place: the kernel reads them)."""
        p, R = self.p, self.radius_m
        self.stale_n = periods(p["fdir.stale_s"], self.dt_s)
        self._lims[:] = [[0.0, p["fdir.omega_max_radps"]], [0.0, 1.0 + p["fdir.sigma_tol"]],
                         [max(0.0, R - p["fdir.r_below_m"]), R + p["fdir.alt_max_m"]],
                         [0.0, p["fdir.v_max_mps"]], [0.0, p["fdir.accel_max_mps2"]],
                         [p["fdir.chamber_lo"], p["fdir.chamber_hi"]]]

    def set_param(self, name: str, value: float) -> float:
        """Owner's hook: a new limit, used from the next frame on; ValueError if not ours."""
        q = self._table.get(name)
        if q is None:
            raise ValueError(f"{name}: not a sensor-monitor parameter")
        self.p[name] = v = q.check(value)
        self._apply()
        return v

    @property
    def jets_must_hold_off(self) -> bool:
        return self.stale

    def restart_sequence(self) -> None:
        """A new sensor source (a restarted plant) counts its steps from 0 again: forget
        the last step index so its frames are not rejected as out of order."""
        self._seq[_SEQ_LAST] = -1

    def _reject(self, t_s: float, reason: str, event: EventDef, **args) -> bool:
        self.counts[reason] += 1
        self.events.emit(t_s, event, **args)
        self._no_fresh(t_s)
        return False

    def _no_fresh(self, t_s: float) -> None:
        self._seq[_SEQ_MISSED] += 1
        missed = int(self._seq[_SEQ_MISSED])
        if not self.stale and missed >= self.stale_n:
            self.stale = True
            self.events.emit(t_s, EV.SENSORS_STALE, periods=missed)

    def tick(self, t_s: float, got_frame: bool = False) -> None:
        """End of a control period; ``got_frame`` False = no frame arrived at all."""
        if not got_frame:
            self._no_fresh(t_s)

    def views(self, frame) -> tuple | None:
        """(float view, step-index view) of a SENSORS record, made once per record object;
        None when ``frame`` is not a writable, contiguous 0-d SENSORS record."""
        fv = self._fviews
        if frame is fv[0] and frame.dtype is fv[1] and frame.shape == () and frame.flags.writeable:
            return fv[2], fv[3]              # the same record as last time (a plant's sensors)
        if not isinstance(frame, np.ndarray) or frame.dtype != SENSORS or frame.shape != () \
                or not frame.flags.c_contiguous or not frame.flags.writeable:
            return None
        x = np.ndarray((_N_F,), dtype=np.float64, buffer=frame, offset=_F0)
        ki = np.ndarray((3,), dtype=np.int64, buffer=frame, offset=_K0)
        self._fviews = (frame, frame.dtype, x, ki)
        return x, ki

    def check(self, t_s: float, frame) -> bool:
        """Validate one SENSORS record; True = accepted (fresh and credible). Bad chamber
        entries are set to NaN in the record (see the module docstring)."""
        v = self.views(frame)
        if v is None:
            return self._reject(t_s, "format", EV.FRAME_FORMAT)
        k = int(v[1][0])
        # one pass over the floats: vectors finite and credible, bad chamber entries -> NaN
        return self.settle(t_s, frame_check(v[0], k, self._lims, self._out, self._seq, self.stale), k)

    def settle(self, t_s: float, code: int, k: int) -> bool:
        """What ``frame_check``'s ``code`` for the frame of step ``k`` calls for: the rejection
        counted and reported, or the accepted frame's reports; True = accepted."""
        if code == 0:
            return True
        if code == REJ_K:
            return self._reject(t_s, "range", EV.FRAME_RANGE, k=k)
        if code == REJ_DUPLICATE:
            return self._reject(t_s, "duplicate", EV.FRAME_DUPLICATE, k=k)
        if code == REJ_OUT_OF_ORDER:
            return self._reject(t_s, "out_of_order", EV.FRAME_OUT_OF_ORDER, k=k)
        if code < 0:
            code = REJ_VECTOR - code
            if code <= 5:
                return self._reject(t_s, "nonfinite", EV.FRAME_NONFINITE, vector=code - 1)
            return self._reject(t_s, "range", EV.FRAME_RANGE, vector=code - 101, value=self._out[0])
        if code & ACC_CHAMBER:
            self._report_chamber(t_s)
        if code & ACC_RECOVER:
            self.stale = False
            self.events.emit(t_s, EV.SENSORS_RECOVERED)
        return True

    def rehearsal_copy(self, x: np.ndarray) -> tuple:
        """The rehearsal's copies of a frame's floats ``x`` and of the sequence state, the
        last step index forgotten so that the copy of the last frame checks as a new one."""
        np.copyto(self._r_x, x)
        np.copyto(self._r_seq, self._seq)
        self._r_seq[_SEQ_LAST] = -1
        return self._r_x, self._r_seq

    def _report_chamber(self, t_s: float) -> None:
        n_nf, n_out = int(self._out[1]), int(self._out[2])
        self.counts["chamber_nonfinite"] += n_nf
        self.counts["chamber_range"] += n_out
        if n_nf:
            self.events.emit(t_s, EV.CHAMBER_NONFINITE, jet=int(self._out[3]) + 1)
        if n_out:
            self.events.emit(t_s, EV.CHAMBER_RANGE, jet=int(self._out[4]) + 1)
