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
assert SENSORS.fields["k"][0] == np.dtype("<i8") and _K0 % 8 == 0


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
        self._r_x = np.zeros(_N_F)     # rehearse's copy of a frame's floats
        self._fviews: tuple = (None, None, None, None)   # (frame, its dtype, float view, k view) of the last frame
        self.counts: dict[str, int] = {r: 0 for r in REASONS}
        self.accepted = 0
        self.last_k: int | None = None
        self.missed = 0            # consecutive periods without fresh data
        self.stale = False

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
        self.last_k = None

    def _reject(self, t_s: float, reason: str, event: EventDef, **args) -> bool:
        self.counts[reason] += 1
        self.events.emit(t_s, event, **args)
        self._no_fresh(t_s)
        return False

    def _no_fresh(self, t_s: float) -> None:
        self.missed += 1
        if not self.stale and self.missed >= self.stale_n:
            self.stale = True
            self.events.emit(t_s, EV.SENSORS_STALE, periods=self.missed)

    def tick(self, t_s: float, got_frame: bool = False) -> None:
        """End of a control period; ``got_frame`` False = no frame arrived at all."""
        if not got_frame:
            self._no_fresh(t_s)

    def check(self, t_s: float, frame) -> bool:
        """Validate one SENSORS record; True = accepted (fresh and credible). Bad chamber
        entries are set to NaN in the record (see the module docstring)."""
        fv = self._fviews
        if frame is fv[0] and frame.dtype is fv[1] and frame.shape == () and frame.flags.writeable:
            x, k = fv[2], int(fv[3][0])          # the same record as last time (a plant's sensors)
        else:
            if not isinstance(frame, np.ndarray) or frame.dtype != SENSORS or frame.shape != () \
                    or not frame.flags.c_contiguous or not frame.flags.writeable:
                return self._reject(t_s, "format", EV.FRAME_FORMAT)
            x = np.ndarray((_N_F,), dtype=np.float64, buffer=frame, offset=_F0)
            ki = np.ndarray((1,), dtype=np.int64, buffer=frame, offset=_K0)
            self._fviews = (frame, frame.dtype, x, ki)
            k = int(ki[0])
        # one pass over the floats: vectors finite and credible, bad chamber entries -> NaN
        code = _frame_kernel(x, self._lims, 5, self._out) if k >= 0 else -1
        if code == -1:
            return self._reject(t_s, "range", EV.FRAME_RANGE, k=k)
        if 1 <= code <= 5:
            return self._reject(t_s, "nonfinite", EV.FRAME_NONFINITE, vector=code - 1)
        if code > 100:
            return self._reject(t_s, "range", EV.FRAME_RANGE, vector=code - 101, value=self._out[0])
        if self.last_k is not None and k <= self.last_k:
            if k == self.last_k:
                return self._reject(t_s, "duplicate", EV.FRAME_DUPLICATE, k=k)
            return self._reject(t_s, "out_of_order", EV.FRAME_OUT_OF_ORDER, k=k)
        if self._out[1] or self._out[2]:
            self._report_chamber(t_s)
        self.last_k = k
        self.accepted += 1
        self.missed = 0
        if self.stale:
            self.stale = False
            self.events.emit(t_s, EV.SENSORS_RECOVERED)
        return True

    def rehearse(self, frame) -> None:
        """Real time, just before a release: the frame check's kernel on a copy of the last
        checked frame's floats (``frame``, when it is that record) with this monitor's limits,
        so the next ``check`` finds its data warm. Changes nothing: the frame is not written
        (bad chamber entries become NaN in the copy), and ``_out`` is scratch that ``check``
        writes before it reads."""
        fv = self._fviews
        if frame is not fv[0] or fv[2] is None:
            return
        np.copyto(self._r_x, fv[2])
        _frame_kernel(self._r_x, self._lims, 5, self._out)

    def _report_chamber(self, t_s: float) -> None:
        n_nf, n_out = int(self._out[1]), int(self._out[2])
        self.counts["chamber_nonfinite"] += n_nf
        self.counts["chamber_range"] += n_out
        if n_nf:
            self.events.emit(t_s, EV.CHAMBER_NONFINITE, jet=int(self._out[3]) + 1)
        if n_out:
            self.events.emit(t_s, EV.CHAMBER_RANGE, jet=int(self._out[4]) + 1)
